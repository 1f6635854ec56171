"""What fitting and extracting model sets share: progress events, summaries, the
index writer, finding sets, and SIGTERM handled as Ctrl-C."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

log = logging.getLogger("occtool.modelset")

#: Suffixes dropped from a log's file name to name its sub-folder.
LOG_SUFFIXES = (".gz", ".bz2", ".log", ".csv", ".mcap", ".bag", ".db3", ".dat", ".xyz", ".pcd", ".ply", ".txt")
#: Seconds between two rewrites of a running set's index.json.
INDEX_INTERVAL = 1.0


# --- progress and summaries -------------------------------------------------------------

@dataclass(frozen=True)
class ProgressEvent:
    """Passed to a ``progress`` callback after every position (and every log read).

    ``total`` grows as logs are read; it is final once ``logs_read == logs_total``.
    ``status`` is ``"read"`` (a log was read), ``"fitted"``/``"extracted"``, ``"reused"``
    or ``"failed"``.
    """

    done: int
    total: int
    logs_read: int
    logs_total: int
    status: str
    source: str = ""
    position: int | None = None


@dataclass(frozen=True)
class Failure:
    """A position (or a whole log, ``position`` None) that could not be done, and why."""

    source: str
    position: int | None
    reason: str


@dataclass
class SetSummary:
    """What a run over model sets did."""

    folders: list[Path] = field(default_factory=list)
    positions: int = 0
    done: int = 0
    reused: int = 0
    failures: list[Failure] = field(default_factory=list)
    seconds: float = 0.0
    executor: str = ""

    def describe(self, verb: str = "fitted") -> str:
        """One line for the user: counts, failures, time."""
        text = f"{self.positions} position(s): {self.done} {verb}"
        if self.reused:
            text += f", {self.reused} reused"
        if self.failures:
            text += f", {len(self.failures)} failed"
        return f"{text} in {self.seconds:.1f} s on {self.executor}"


ProgressCallback = Callable[[ProgressEvent], None]


# --- the index of a set -------------------------------------------------------------------

class _IndexWriter:
    """The entries of one set as they finish, written to ``index.json`` atomically."""

    def __init__(self, folder: Path, source: str) -> None:
        self.folder = folder
        self.source = source
        self.entries: dict[int, dict[str, Any]] = {}
        self.failed: dict[int | None, str] = {}
        self.all_submitted = False
        self.last_write = 0.0
        self.dirty = False

    def add(self, entry: dict[str, Any]) -> None:
        self.entries[entry["position"]] = entry
        self.failed.pop(entry["position"], None)
        self.dirty = True

    def fail(self, position: int | None, reason: str) -> None:
        self.failed[position] = reason
        self.dirty = True

    def write(self, *, complete: bool, force: bool = False) -> None:
        now = time.monotonic()
        if not force and (not self.dirty or now - self.last_write < INDEX_INTERVAL):
            return
        from occtool.modelset._index import save_model_set_index

        entries = [self.entries[k] for k in sorted(self.entries)]
        failed = [{"position": k, "reason": v}
                  for k, v in sorted(self.failed.items(), key=lambda kv: (kv[0] is None, kv[0] or 0))]
        save_model_set_index(self.folder, entries, source=self.source, complete=complete, failed=failed)
        self.last_write = now
        self.dirty = False


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM stops the run as Ctrl-C does (the finished part is indexed, temp files go),
    when this is the main thread and nobody else handles SIGTERM."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGTERM)
    if previous is not signal.SIG_DFL:
        yield
        return

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt("terminated")

    signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def log_set_name(source: Any) -> str:
    """The sub-folder name of a log in a multi-log set: its file name without the format
    and compression suffixes."""
    name = Path(str(getattr(source, "source", source))).name
    while True:
        stem, suffix = os.path.splitext(name)
        if suffix.lower() in LOG_SUFFIXES and stem:
            name = stem
        else:
            return name or "log"


# --- reading sets -------------------------------------------------------------------------

def find_model_sets(path: str | os.PathLike[str]) -> list[Path]:
    """The model sets at ``path``: a set's folder or its ``index.json`` gives that set; a
    folder without an index gives every sub-folder that holds one (``fit A B -o DIR/``)."""
    target = Path(path)
    if target.is_dir() and not (target / "index.json").exists():
        found = sorted(p for p in target.iterdir() if p.is_dir() and (p / "index.json").is_file())
        if found:
            return found
    return [target]


def read_set_state(folder: str | os.PathLike[str]) -> dict[str, Any]:
    """``complete`` (``None`` for an index older than the flag) and ``failed`` of a set's index."""
    index = Path(folder) / "index.json" if Path(folder).is_dir() else Path(folder)
    try:
        data = json.loads(index.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {"complete": None, "failed": []}
    if not isinstance(data, dict):
        return {"complete": None, "failed": []}
    failed = data.get("failed") if isinstance(data.get("failed"), list) else []
    complete = data.get("complete")
    return {"complete": complete if isinstance(complete, bool) else None, "failed": failed}


