"""Write a file completely or not at all."""

from __future__ import annotations

import contextlib
import errno
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import IO

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
