"""Write a file completely or not at all."""

from __future__ import annotations

import contextlib
import errno
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

#: Characters of the target's name kept in its temporary file's name (``.NAME.XXXXXXXX.tmp``).
TEMP_PREFIX_CHARS = 32


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
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name[:TEMP_PREFIX_CHARS]}.", suffix=".tmp", dir=directory)
    try:
        # mkstemp makes the file private (0600); give the result the mode a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_name, 0o666 & ~umask)
        with os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": "\n"})) as handle:  # type: ignore[call-overload]
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp_name, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp_name)
        raise
