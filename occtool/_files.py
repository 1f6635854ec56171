"""Occtool's files on disk: outputs written completely or not at all, inputs opened
whatever their compression with the decompressed size bounded.

:func:`atomic_write` writes through a temporary file renamed into place on success.
:func:`open_input` tells compression by the file's first bytes (gzip ``1f 8b``, bzip2 ``BZh``), not its
name, so a gzip file saved as ``scan.csv`` is read as the text it holds. A compressed
file may expand without limit (a few megabytes of zeros become gigabytes); readers
stop at :data:`occtool.limits.MAX_DECOMPRESSED_BYTES` with an :class:`~occtool.errors.InputError`
instead of filling the memory. Text is UTF-8; a byte-order mark is skipped.
:func:`read_at` reads a run's own temporary files (its spilled raster and outlines).
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import signal
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from occtool import limits
from occtool.errors import InputError


def read_at(descriptor: int, into: bytearray, offset: int, what: str) -> bytearray:
    """Fill ``into`` from the file ``descriptor`` at ``offset`` with ``os.preadv`` (never
    mapped: what was read is not held in the process), as many reads as it takes (one
    returns at most about 2 GB); an :class:`OSError` naming ``what`` when the file ends first."""
    done = 0
    while done < len(into):
        got = os.preadv(descriptor, [memoryview(into)[done:]], offset + done)
        if got <= 0:
            raise OSError(f"{what} ended {len(into) - done} bytes early")
        done += got
    return into


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM held back (delivered when the block ends) where the platform can
    (POSIX, the main thread): a few renames that must not stop half way, or a call into a
    library that holds locks its own clean-up needs (a process pool's)."""
    held = {signal.SIGINT, signal.SIGTERM}
    can = hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held) if can else None
    try:
        yield
    finally:
        if previous is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)


#: Characters of the target's name kept in its temporary file's name (``.NAME.XXXXXXXX.tmp``).
TEMP_PREFIX_CHARS = 32
#: Random names tried for a temporary file before giving up.
TEMP_ATTEMPTS = 100


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w", *, overwrite: bool = True) -> Iterator[IO]:
    """Open ``path`` for writing through a temporary file renamed into place on success.

    If the body raises (a ``BaseException`` too: Ctrl-C, or SIGTERM turned into one by
    :func:`occtool.cli.main.main`), the temporary file is removed and ``path`` is left
    untouched, so an output file is either complete or absent. ``"-"`` writes to standard output.

    Parameters
    ----------
    path
        Destination file, or ``"-"`` for standard output.
    mode
        ``"w"`` for text (UTF-8) or ``"wb"`` for bytes.
    overwrite
        If false and ``path`` exists, raise :class:`FileExistsError`.
    """
    if str(path) == "-":
        if sys.stdout is None:  # started with standard output closed (`>&-`)
            raise OSError(errno.EBADF, "standard output is closed: name an output file with -o")
        stream = sys.stdout.buffer if "b" in mode else sys.stdout
        yield stream
        stream.flush()
        return
    target = Path(path)
    if not overwrite and target.exists():
        raise FileExistsError(f"{target} exists already (pass overwrite=True to replace it)")
    if target.is_dir():
        raise IsADirectoryError(errno.EISDIR, "Is a directory (name an output file)", str(target))
    if target.exists() and not target.is_file():
        # A device or pipe (/dev/null, /dev/stdout, a FIFO): write into it, never replace it.
        # (mypy: ``mode`` is a runtime string, text or binary, so no overload of open() matches.)
        with open(target, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": "\n"})) as handle:  # type: ignore[call-overload]
            yield handle
        return
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise FileNotFoundError(f"output folder {directory} does not exist")
    # A short prefix: the temporary name must fit NAME_MAX (255) when the target's does.
    prefix = f".{target.name[:TEMP_PREFIX_CHARS]}."
    tmp_name: str | None = None
    try:
        # The name is chosen before the file is made, inside this try: a Ctrl-C or SIGTERM
        # arriving just after the file exists (between mkstemp's return and a try, as a
        # loaded machine showed once) still finds its name and removes it.
        for _ in range(TEMP_ATTEMPTS):
            # os.urandom is what secrets.token_hex reads (whose import, with random and hmac, is
            # a few ms of every fresh command that writes a file).
            tmp_name = str(directory / f"{prefix}{os.urandom(4).hex()}.tmp")
            try:
                fd = os.open(tmp_name, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
                break
            except FileExistsError:
                tmp_name = None  # someone else's: never ours to remove
        else:
            raise FileExistsError(errno.EEXIST, "no free temporary file name", str(directory))
        # Made private (0600) while written; give the result the mode a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_name, 0o666 & ~umask)
        with os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": "\n"})) as handle:  # type: ignore[call-overload]
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp_name, target)
    except BaseException:
        if tmp_name is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp_name)
        raise


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
