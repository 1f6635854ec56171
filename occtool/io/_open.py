"""Open an input file whatever its compression, with the decompressed size bounded.

Compression is told by the file's first bytes (gzip ``1f 8b``, bzip2 ``BZh``), not its
name, so a gzip file saved as ``scan.csv`` is read as the text it holds. A compressed
file may expand without limit (a few megabytes of zeros become gigabytes); readers
stop at :data:`occtool.limits.MAX_DECOMPRESSED_BYTES` with an :class:`~occtool.errors.InputError`
instead of filling the memory. Text is UTF-8; a byte-order mark is skipped.
"""

from __future__ import annotations

import io
import os
from typing import IO

from occtool import limits
from occtool.errors import InputError

GZIP_MAGIC = b"\x1f\x8b"
BZIP2_MAGIC = b"BZh"


def compression_of(path: str | os.PathLike[str]) -> str | None:
    """``"gzip"``, ``"bzip2"`` or ``None``, from the file's first bytes."""
    with open(path, "rb") as handle:
        start = handle.read(3)
    if start[:2] == GZIP_MAGIC:
        return "gzip"
    if start == BZIP2_MAGIC:
        return "bzip2"
    return None


class _Bounded(io.RawIOBase):
    """A read-only stream that raises InputError past ``limit`` bytes of ``inner``."""

    def __init__(self, inner: IO[bytes], name: str, limit: int) -> None:
        self.inner = inner
        self.name_for_errors = name
        self.limit = limit
        self.count = 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: bytearray | memoryview) -> int:  # type: ignore[override]
        data = self.inner.read(len(buffer))
        self.count += len(data)
        if self.count > self.limit:
            raise InputError(
                f"{self.name_for_errors} expands to more than {self.limit:,} bytes when decompressed "
                "(a decompression bomb, or a log too large to read whole): decompress and split it first"
            )
        buffer[: len(data)] = data
        return len(data)

    def close(self) -> None:
        self.inner.close()
        super().close()


def open_input(path: str | os.PathLike[str], mode: str = "r", *,
               limit: int | None = None) -> IO:
    """Open ``path`` for reading as text (``"r"``) or bytes (``"rb"``), decompressed.

    Raises
    ------
    InputError
        While reading, when a compressed file expands past ``limit`` bytes (by default
        :data:`occtool.limits.MAX_DECOMPRESSED_BYTES`).
    """
    name = str(path)
    limit = limits.MAX_DECOMPRESSED_BYTES if limit is None else limit
    kind = compression_of(path)
    if kind is None:
        if "b" in mode:
            return open(name, "rb")
        return open(name, encoding="utf-8-sig", errors="replace", newline=None)
    # Imported for a compressed file only: gzip and bz2 are a few ms of every fresh fit of a plain log.
    if kind == "gzip":
        import gzip

        inner: IO[bytes] = gzip.open(name, "rb")  # type: ignore[assignment]  # noqa: SIM115 (returned open)
    else:
        import bz2

        inner = bz2.open(name, "rb")  # noqa: SIM115 (returned open)
    stream = io.BufferedReader(_Bounded(inner, name, limit))
    if "b" in mode:
        return stream
    return io.TextIOWrapper(stream, encoding="utf-8-sig", errors="replace", newline=None)
