"""Reading a range log from a stream (``-``: standard input).

The stream is copied to a temporary file first (removed on every exit, signals
included, as the interpreter unwinds), so every format reads from it as from a file:
the format is told from the content, and memory stays bounded by the reader, not by
the stream.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from typing import IO, Any

from occtool.errors import InputError


def read_log_stream(stream: IO[bytes] | None = None, *, name: str = "standard input", **options: Any) -> Any:
    """Read a range log from ``stream`` (default: standard input, as bytes).

    ``options`` are those of :func:`occtool.io.read_log`. The log's ``source`` is ``name``.

    Raises
    ------
    InputError
        If the stream is empty or its content is no supported format.
    """
    from occtool.io import read_log

    source = stream if stream is not None else sys.stdin.buffer
    fd, temporary = tempfile.mkstemp(prefix="occtool-stdin-", suffix=".log")
    try:
        with os.fdopen(fd, "wb") as handle:
            shutil.copyfileobj(source, handle, 1 << 20)
        if os.path.getsize(temporary) == 0:
            raise InputError(f"{name} is empty")
        try:
            log = read_log(temporary, **options)
        except InputError as exc:
            raise InputError(str(exc).replace(temporary, name)) from None
        log.source = name
        for number, position in enumerate(log.positions):
            if position.source == temporary:
                object.__setattr__(log.positions[number], "source", name)
        return log
    finally:
        try:
            os.unlink(temporary)
        except FileNotFoundError:
            pass


__all__ = ["read_log_stream"]
