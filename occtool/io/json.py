"""Reading a JSON document with one-line errors that name the file.

The one JSON reader of occtool's report-like files (comparison reports, benchmark
results, scene truths); model files keep their own format checks in
:mod:`occtool.io.model`.
"""

from __future__ import annotations

import json
import os
from typing import Any

from occtool.errors import ModelFormatError, OcctoolError


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
    try:
        with open(path, encoding="utf-8") as handle:
            text = handle.read()
    except UnicodeDecodeError:
        raise error(f"{os.fspath(path)}: not a text (UTF-8) file") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{os.fspath(path)}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
