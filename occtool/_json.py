"""JSON from users: integers and nesting bounded, one-line errors that name the file.

The one JSON reader of occtool's report-like files (comparison reports, benchmark
results, scene truths); model files and navigation maps parse with :func:`loads` and keep
their own format checks (:mod:`occtool.formats.model`, :mod:`occtool.formats.geojson`).
``json.loads`` turns a 400-digit integer into a Python int that overflows every float
conversion later, and a document nested a thousand deep into a RecursionError; here both
are :class:`json.JSONDecodeError`, which every reader reports in one line.
"""

from __future__ import annotations

import json
import os
import re
from typing import Any

from occtool.errors import ModelFormatError, OcctoolError


def read_text(path: str | os.PathLike[str], *, error: type[OcctoolError] = ModelFormatError) -> str:
    """A user's text file, whole: ``error`` (one line naming the file) when it is not UTF-8."""
    try:
        with open(path, encoding="utf-8") as handle:
            return handle.read()
    except UnicodeDecodeError:
        raise error(f"{os.fspath(path)}: not a text (UTF-8) file") from None


def read_json(path: str | os.PathLike[str], *, error: type[OcctoolError] = ModelFormatError) -> Any:
    """The JSON document in a file.

    Parameters
    ----------
    path
        The file, UTF-8 text.
    error
        The exception raised for a file that is not UTF-8 or not JSON
        (:class:`~occtool.errors.ModelFormatError` unless the caller reads input data).

    Raises
    ------
    OcctoolError
        ``error``, one line naming the file and, for bad JSON, the line and the problem.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "report.json"
    >>> _ = path.write_text('{"models": ')
    >>> read_json(path)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    occtool.errors.ModelFormatError: .../report.json: not valid JSON (line 1: Expecting value)
    """
    text = read_text(path, error=error)
    try:
        return loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{os.fspath(path)}: not valid JSON (line {exc.lineno}: {exc.msg})") from None


#: Longest integer literal accepted: counts, versions and seeds have at most 19 digits.
MAX_INTEGER_DIGITS = 20


def _parse_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_INTEGER_DIGITS:
        # JSONDecodeError needs a document and position; the caller adds the file name.
        raise json.JSONDecodeError(f"an integer of {digits} digits ({text[:12]}...) is too long to be a value", text, 0)
    return int(text)


#: Longest number literal :func:`loads` takes when asked to bound them (``repr`` of a
#: float is at most 24 characters).
MAX_NUMBER_LENGTH = 64
_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')


def _parse_float(text: str) -> float:
    if len(text) > MAX_NUMBER_LENGTH:
        raise json.JSONDecodeError(f"a number of {len(text)} characters ({text[:12]}...) is too long to be a value",
                                   text, 0)
    return float(text)


_BRACKETS = b"[]{}"
_NOT_BRACKETS = bytes(b for b in range(256) if b not in _BRACKETS)


def _depth(text: str) -> int:
    """How deep ``text``'s arrays and objects nest (strings blanked first), without
    recursing: the brackets alone (``bytes.translate``), counted by numpy."""
    import numpy as np

    brackets = _STRING.sub('""', text).encode("utf-8", "replace").translate(None, _NOT_BRACKETS)
    code = np.frombuffer(brackets, dtype=np.uint8)
    step = np.where((code == ord("[")) | (code == ord("{")), 1, -1)
    return int(np.cumsum(step).max(initial=0))


#: Deepest nesting of arrays and objects :func:`loads` parses (occtool's files nest a few
#: levels; a GeoJSON polygon five). Deeper is refused before parsing, whatever the depth
#: of the interpreter's stack at the call (the parser's own limit moved with it: the library
#: and the command line told a summary nested 950 deep apart).
MAX_JSON_DEPTH = 256


def loads(text: str, *, max_depth: int | None = None, bounded_numbers: bool = False) -> Any:
    """``json.loads`` with integers of at most :data:`MAX_INTEGER_DIGITS` digits and at most
    :data:`MAX_JSON_DEPTH` levels of nesting; both failures are :class:`json.JSONDecodeError`.

    ``max_depth``: arrays and objects nested deeper are refused before parsing with their
    depth (a file format that knows its depth says so); ``bounded_numbers``: number literals longer
    than :data:`MAX_NUMBER_LENGTH` characters and ``NaN`` / ``Infinity`` are refused too.

    >>> loads('[[[1]]]', max_depth=2)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    json.decoder.JSONDecodeError: nested 3 deep, more than 2: line 1 column 1 (char 0)
    """
    if max_depth is not None or text.count("[") + text.count("{") > MAX_JSON_DEPTH:
        depth = _depth(text)
        if max_depth is not None and depth > max_depth:
            raise json.JSONDecodeError(f"nested {depth} deep, more than {max_depth}", text, 0)
        if depth > MAX_JSON_DEPTH:
            raise json.JSONDecodeError("nested too deeply", text, 0)
    hooks: dict[str, Any] = {}
    if bounded_numbers:
        hooks = {"parse_float": _parse_float, "parse_constant": _refuse_constant}
    try:
        return json.loads(text, parse_int=_parse_int, **hooks)
    except RecursionError:
        raise json.JSONDecodeError("nested too deeply", text, 0) from None


def _refuse_constant(name: str) -> Any:
    raise json.JSONDecodeError(f"{name} is not a JSON number", name, 0)
