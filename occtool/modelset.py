"""Model sets: one model per robot position of one or more logs, fitted and extracted in parallel.

A model set is a folder holding ``model_NNNN.json`` (one per position, ``NNNN`` the
position's index) and ``index.json`` (the ``occtool-model-set`` format) listing each
position's file, pose, stamp, feature count and the digest of its features.

- :func:`fit_model_set` fits every position of one or more logs. One log writes its set
  into the folder itself; several write one sub-folder each, named after the log's file
  without its format and compression suffixes (``intel-corrected.log.gz`` ->
  ``DIR/intel-corrected/``).
- :func:`extract_model_set` extracts the navigation map of every position of one or more
  sets (a folder of sub-folder sets counts as all of them).
- The positions run on an :mod:`occtool.executor` (``jobs`` local processes, or a Dask
  cluster at ``scheduler``). A model's bytes do not depend on where it was fitted: the
  run details (seconds, date, host, ...) are kept apart in its ``run`` object.

Partial results. ``index.json`` is rewritten (atomically) as positions finish, at most
about once a second, with ``"complete": false`` until every position was tried; it then
says ``"complete": true``. A position that fails (bad data, a worker killed) is listed
under ``"failed"`` with its reason and the others are written. An interrupted run
(Ctrl-C, SIGTERM) writes the index of what is finished, still marked incomplete, and
leaves no temporary file. With ``skip_existing`` a later run reuses every model whose
input digest (``training.features_sha256``) and settings digest (``run.settings_sha256``)
match, so a killed run resumes where it stopped.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import signal
import stat
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from occtool.errors import InputError

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


# --- settings and reuse -------------------------------------------------------------------

def settings_digest(estimator: Any) -> str:
    """sha256 of everything besides the features that decides a model's bytes: the fit
    parameters, sensor model, robot and occtool's version."""
    from occtool import __version__
    from occtool.robot import Robot
    from occtool.sensor import SensorModel

    params = {k: v for k, v in estimator.get_params().items() if k not in ("progress", "sensor", "robot")}
    sensor = estimator.sensor if estimator.sensor is not None else SensorModel()
    robot = estimator.robot if estimator.robot is not None else Robot()
    content = {
        "fit": params,
        "sensor": sensor.to_dict(),
        "robot": {k: float(getattr(robot, k)) for k in ("radius", "sensor_height", "body_height", "ground_clearance")},
        "occtool": __version__,
    }
    return hashlib.sha256(json.dumps(content, sort_keys=True, default=repr).encode()).hexdigest()


def _reusable(target: Path, digest: str, settings: str) -> bool:
    """Whether ``target`` is a readable model of these features fitted with these settings."""
    from occtool.io.model import load_model

    try:
        if not stat.S_ISREG(os.stat(target).st_mode):
            return False
        model = load_model(target)
    except (OSError, ValueError):
        return False
    return model.features_digest_ == digest and model.run_.get("settings_sha256") == settings


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
        from occtool.io.model import save_model_set_index

        entries = [self.entries[k] for k in sorted(self.entries)]
        failed = [{"position": k, "reason": v} for k, v in sorted(self.failed.items(), key=lambda kv: (kv[0] is None, kv[0] or 0))]
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


# --- fitting ------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Failed:
    """A position's failure inside a chunk (an exception may not survive pickling)."""

    reason: str


def _reason(exc: BaseException) -> str:
    return str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"


def _fit_chunk(params: dict[str, Any], chunk: list[Any]) -> list[Any]:
    """Fit a few positions (runs in a worker). For each: the model file's text (its run
    object a placeholder), a few facts for the log, the seconds and the host; or a
    :class:`_Failed`."""
    import platform

    from occtool.fit import OccupancyRegressor
    from occtool.io.model import RUN_PLACEHOLDER, model_text

    out: list[Any] = []
    for features in chunk:
        start = time.perf_counter()
        try:
            model = OccupancyRegressor(**params).fit(features)
        except (InputError, ValueError, ArithmeticError, MemoryError) as exc:
            out.append(_Failed(_reason(exc)))
            continue
        seconds = time.perf_counter() - start
        facts = {"features": model.n_features_, "rmse": model.rmse_}
        out.append((model_text(model, run=RUN_PLACEHOLDER), facts, seconds, platform.node()))
    return out


#: A task holds consecutive positions up to this many features (or CHUNK_POSITIONS
#: positions): small positions travel together, so a cluster's per-task cost is shared.
CHUNK_FEATURES = 20_000
CHUNK_POSITIONS = 16


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


def _read_source(source: Any, read_options: dict[str, Any]) -> Any:
    from occtool.features import RangeLog

    if isinstance(source, RangeLog):
        return source
    if str(source) == "-":
        from occtool.io.stream import read_log_stream

        return read_log_stream(**read_options)
    from occtool.io import read_log

    return read_log(source, **read_options)


def fit_model_set(
    logs: Any,
    folder: str | os.PathLike[str],
    *,
    estimator: Any = None,
    read_options: dict[str, Any] | None = None,
    positions: Sequence[int] | None = None,
    jobs: int | None = None,
    scheduler: Any = None,
    skip_existing: bool = False,
    overwrite: bool = True,
    progress: ProgressCallback | None = None,
    command: str | None = None,
) -> SetSummary:
    """Fit one model per robot position of one or more logs and write them as model sets.

    Parameters
    ----------
    logs
        A log (a path, ``"-"`` for standard input, or a :class:`~occtool.features.RangeLog`)
        or a list of them. Several logs give one sub-folder each (:func:`log_set_name`).
    folder
        The set's folder; created if missing.
    estimator
        An unfitted :class:`~occtool.fit.OccupancyRegressor` whose parameters every
        position is fitted with (default: the defaults).
    read_options
        Keyword arguments of :func:`occtool.io.read_log` (``topics``, ``group_by``, ...).
    positions
        Position indices to fit (default: all).
    jobs, scheduler
        ``jobs`` local processes (default: the cores), or a Dask scheduler address or
        ``distributed.Client``; see :func:`occtool.executor.make_executor`.
    skip_existing
        Reuse a model file whose features digest and settings digest match.
    overwrite
        If false, refuse (before any work) when a set folder already holds an index or a model.
    progress
        Called with a :class:`ProgressEvent` after every log read and position done.
    command
        The command line, recorded in each model's ``run`` object.

    Returns
    -------
    SetSummary
        Positions, fitted, reused, failures (with reasons) and time. Failures do not raise:
        the caller decides (the CLI exits non-zero).

    Raises
    ------
    InputError
        For invalid settings, a set folder that exists as a file, two logs of the same
        name, or (a single log) a log that cannot be read. An unreadable log among
        several is a failure of that log and the others go on.
    KeyboardInterrupt
        After writing the finished part (Ctrl-C, or SIGTERM when not handled elsewhere).
    """
    from occtool import __version__
    from occtool.executor import check_jobs, make_executor
    from occtool.fit import OccupancyRegressor, features_digest
    from occtool.io.model import save_model_text, with_run

    start = time.perf_counter()
    sources = list(logs) if isinstance(logs, (list, tuple)) else [logs]
    if not sources:
        raise InputError("no logs to fit")
    if scheduler is None:
        check_jobs(jobs)
    template = estimator if estimator is not None else OccupancyRegressor()
    params = {k: v for k, v in template.get_params().items() if k != "progress"}
    OccupancyRegressor(**params)._validate()
    settings = settings_digest(template)
    read_options = dict(read_options or {})
    root = Path(folder)
    if len(sources) == 1:
        folders = [root]
    else:
        names = [log_set_name(s) for s in sources]
        seen: dict[str, Any] = {}
        for name, source in zip(names, sources):
            if name in seen:
                raise InputError(f"two logs would share the sub-folder {root / name}: {seen[name]} and {source}")
            seen[name] = source
        folders = [root / name for name in names]
    for target in folders:
        if target.exists() and not target.is_dir():
            raise InputError(f"{target} exists and is not a folder")
        if not overwrite and not skip_existing and target.is_dir():
            existing = [p for p in (target / "index.json", *sorted(target.glob("model_*.json"))) if p.exists()]
            if existing:
                raise FileExistsError(f"{existing[0]} exists already (pass --overwrite to replace it)")

    summary = SetSummary(folders=folders)
    writers: list[_IndexWriter] = []
    outstanding: dict[int, int] = {}
    state = {"logs_read": 0}

    def notify(status: str, source: str = "", position: int | None = None) -> None:
        if progress is not None:
            progress(ProgressEvent(summary.done + summary.reused + len(summary.failures), summary.positions,
                                   state["logs_read"], len(sources), status, source, position))

    def tasks() -> Iterator[Any]:
        for number, (source, target) in enumerate(zip(sources, folders)):
            name = str(getattr(source, "source", source)) or f"log {number}"
            writer = _IndexWriter(target, name)
            writers.append(writer)
            try:
                range_log = _read_source(source, read_options)
                chosen = list(range_log.positions)
                if positions is not None:
                    chosen = [range_log.single(p) for p in positions]
                elif not chosen:
                    range_log.single(None)  # the "no range data" error
            except (InputError, OSError) as exc:
                if len(sources) == 1:
                    writers.pop()  # nothing of this set is written
                    raise
                reason = str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"
                summary.failures.append(Failure(name, None, reason))
                writer.fail(None, reason)
                writer.all_submitted = True
                target.mkdir(parents=True, exist_ok=True)
                state["logs_read"] += 1
                notify("failed", name)
                continue
            for note in range_log.notes:
                log.warning("%s: %s", Path(name).name, note)
            state["logs_read"] += 1
            target.mkdir(parents=True, exist_ok=True)
            summary.positions += len(chosen)
            outstanding[number] = len(chosen)
            notify("read", name)
            chunk: list[tuple[dict[str, Any], Any]] = []
            for item in chosen:
                digest = features_digest(item.features)
                model_file = f"model_{item.index:04d}.json"
                entry = {"position": item.index, "file": model_file,
                         "pose": item.pose.to_dict() if item.pose is not None else None,
                         "stamp": item.stamp, "features": len(item.features), "features_sha256": digest}
                if skip_existing and _reusable(target / model_file, digest, settings):
                    writer.add(entry)
                    summary.reused += 1
                    outstanding[number] -= 1
                    notify("reused", name, item.index)
                    continue
                chunk.append((entry, item.features))
                if len(chunk) >= CHUNK_POSITIONS or sum(len(f) for _, f in chunk) >= CHUNK_FEATURES:
                    yield (number, [e for e, _ in chunk]), _fit_chunk, (params, [f for _, f in chunk])
                    chunk = []
            if chunk:
                yield (number, [e for e, _ in chunk]), _fit_chunk, (params, [f for _, f in chunk])
                chunk = []
            writer.all_submitted = True
            del range_log, chosen

    executor = make_executor(jobs, scheduler)
    summary.executor = executor.description
    interrupted = True
    try:
        with _terminate_as_interrupt(), executor:
            for (number, entries), outcomes in executor.run_unordered(tasks()):
                writer = writers[number]
                if isinstance(outcomes, BaseException):  # the whole chunk: a worker died, a cluster error
                    outcomes = [_Failed(_reason(outcomes))] * len(entries)
                for entry, outcome in zip(entries, outcomes):
                    outstanding[number] -= 1
                    if isinstance(outcome, _Failed):
                        summary.failures.append(Failure(writer.source, entry["position"], outcome.reason))
                        writer.fail(entry["position"], outcome.reason)
                        log.warning("%s, position %d: %s", Path(writer.source).name, entry["position"],
                                    outcome.reason)
                        notify("failed", writer.source, entry["position"])
                        continue
                    text, facts, seconds, host = outcome
                    run = {
                        "seconds": round(seconds, 3),
                        "date": time.strftime("%Y-%m-%dT%H:%M:%S+00:00", time.gmtime()),
                        "occtool_version": __version__,
                        "python": _python_version(),
                        "host": host,
                        "executor": executor.description,
                        "command": command or "occtool.modelset.fit_model_set",
                        "input": writer.source,
                        "position": entry["position"],
                        "settings_sha256": settings,
                    }
                    save_model_text(with_run(text, run), writer.folder / entry["file"])
                    writer.add(entry)
                    summary.done += 1
                    log.info("%s, position %d: %d features, RMSE %.4f, %.2f s", Path(writer.source).name,
                             entry["position"], facts["features"], facts["rmse"], seconds)
                    notify("fitted", writer.source, entry["position"])
                writer.write(complete=writer.all_submitted and outstanding[number] == 0)
        interrupted = False
    finally:
        for writer, number in zip(writers, range(len(writers))):
            finished = not interrupted and writer.all_submitted and outstanding.get(number, 0) == 0
            with contextlib.suppress(OSError):
                writer.write(complete=finished, force=True)
    summary.seconds = time.perf_counter() - start
    return summary


def _python_version() -> str:
    import platform

    return platform.python_version()


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


# --- extraction ---------------------------------------------------------------------------

def navigation_map_of_file(
    path: str | os.PathLike[str],
    *,
    robot: Any = None,
    robot_overrides: dict[str, float] | None = None,
    straight_line: bool = True,
    bounds: bool = True,
    **options: Any,
) -> tuple[Any, list[tuple[int, str]]]:
    """The navigation map of a model or inverse file, and messages ``(level, text)`` about it.

    Parameters
    ----------
    robot
        The robot for a file that records none.
    robot_overrides
        :class:`~occtool.robot.Robot` fields (``radius``, ``sensor_height``, ...) that
        replace those of the robot the model was fitted for.
    straight_line, bounds
        As for :func:`~occtool.navigation.navigation_map`; ``bounds=False`` cuts at the
        given heights only (the paper's plain extraction).
    options
        Further keywords of :func:`~occtool.navigation.navigation_map` (``threshold``,
        ``heights``, ``max_range``, ...).
    """
    import warnings

    from occtool.io.model import read_navigable
    from occtool.navigation import NavigationWarning, navigation_map

    navigable = read_navigable(path)
    settings = dict(options)
    if navigable.robot is not None:
        settings["robot"] = replace(navigable.robot, **(robot_overrides or {}))
    elif robot is not None:
        settings["robot"] = robot
    messages: list[tuple[int, str]] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", NavigationWarning)
        nav = navigation_map(navigable.inverse_range, straight_line=straight_line,
                             **navigable.navigation_options(bounds=bounds), **settings)
    for warning in caught:
        messages.append((logging.WARNING, f"{path}: {warning.message}"))
    if nav.margin > 0:
        text = (f"{path}: cut at {len(nav.slice_heights)} heights, threshold {nav.threshold:.3g} lowered by "
                f"{nav.margin:.3g} to {nav.effective_threshold:.3g} so the map holds between them")
        messages.append((logging.INFO, text))
    text = (f"{path}: navigation polygon {nav.polygon.area:.3g} m2, {len(nav.obstacle_points)} obstacle and "
            f"{len(nav.exploration_points)} exploration points")
    messages.append((logging.INFO, text))
    return nav, messages


def _extract_task(path: Path, options: dict[str, Any]) -> tuple[Any, list[tuple[int, str]]]:
    return navigation_map_of_file(path, **options)


def extract_model_set(
    model_sets: Any,
    out: str | os.PathLike[str] | None = None,
    *,
    per_position: bool | None = None,
    world: bool = False,
    jobs: int | None = None,
    scheduler: Any = None,
    overwrite: bool = True,
    progress: ProgressCallback | None = None,
    geojson: dict[str, Any] | None = None,
    **navigation: Any,
) -> SetSummary:
    """Extract the navigation map of every position of one or more model sets.

    Parameters
    ----------
    model_sets
        A set (its folder or ``index.json``; a folder of sets counts as each of them) or a
        list of them.
    out
        ``None``/``"-"`` (standard output) or a file: one GeoJSON collection with each map
        tagged by its ``position`` (one set only). A folder (``per_position``, or a path
        ending in ``/`` or an existing folder): ``nav_NNNN.geojson`` per position, in a
        sub-folder per set when there are several. Folders are created.
    world
        Move each map into the world frame by its position's pose.
    jobs, scheduler
        As for :func:`fit_model_set`.
    geojson
        Keywords of :func:`occtool.io.geojson.write_navigation` (``sequence``,
        ``precision``, ``indent``, ``include_slices``).
    navigation
        Keywords of :func:`navigation_map_of_file` (``robot``, ``robot_overrides``,
        ``straight_line``, ``bounds``, ``threshold``, ``heights``, ...).

    Returns
    -------
    SetSummary
        A failing position is reported there and the others are written.
    """
    from occtool.executor import check_jobs, make_executor
    from occtool.features import Pose
    from occtool.io.geojson import write_navigation, write_navigation_set
    from occtool.io.model import read_model_set

    start = time.perf_counter()
    given = list(model_sets) if isinstance(model_sets, (list, tuple)) else [model_sets]
    paths = [found for item in given for found in find_model_sets(item)]
    if scheduler is None:
        check_jobs(jobs)
    sets = [read_model_set(str(p)) for p in paths]
    folders = [folder for folder, _ in sets]
    for folder in folders:
        state = read_set_state(folder)
        if state["complete"] is False:
            log.warning("%s: the model set is incomplete (an interrupted fit; resume it with --skip-existing)", folder)
    to_folder = per_position if per_position is not None else (
        out is not None and (str(out).endswith(("/", os.sep)) or Path(out).is_dir()))
    if len(sets) > 1 and not to_folder:
        raise InputError("several model sets need an output folder (out ending in '/')")
    if len({f.resolve() for f in folders}) != len(folders):
        raise InputError("the same model set is given twice")
    written = dict(geojson or {})
    targets: list[Path | None] = []
    if to_folder:
        root = Path(out)  # type: ignore[arg-type]
        names = [f.name for f in folders]
        if len(sets) > 1 and len(set(names)) != len(names):
            raise InputError(f"model sets of the same folder name would share an output folder: {names}")
        targets = [root / name for name in names] if len(sets) > 1 else [root]
        if not overwrite:
            for target, (_, entries) in zip(targets, sets):
                for entry in entries:
                    candidate = target / f"nav_{entry['position']:04d}.geojson"
                    if candidate.exists():
                        raise FileExistsError(f"{candidate} exists already (pass --overwrite to replace it)")
        for target in targets:
            if target.exists() and not target.is_dir():
                raise InputError(f"{target} exists and is not a folder")
        for target in targets:
            target.mkdir(parents=True, exist_ok=True)
    elif not overwrite and out not in (None, "-") and Path(out).exists():  # type: ignore[arg-type]
        raise FileExistsError(f"{out} exists already (pass --overwrite to replace it)")
    poses: dict[tuple[int, int], Any] = {}
    if world:
        for number, (folder, entries) in enumerate(sets):
            for entry in entries:
                if entry.get("pose") is None:
                    raise InputError(f"{folder / 'index.json'}: position {entry['position']} has no pose for world=True")
                try:
                    poses[number, entry["position"]] = Pose.from_dict(entry["pose"])
                except (TypeError, ValueError):
                    raise InputError(f"{folder / 'index.json'}: position {entry['position']}'s pose is not numbers") from None

    summary = SetSummary(folders=folders, positions=sum(len(e) for _, e in sets))
    maps: list[tuple[int, Any]] = []

    def notify(status: str, source: str, position: int | None) -> None:
        if progress is not None:
            progress(ProgressEvent(summary.done + len(summary.failures), summary.positions, len(sets), len(sets),
                                   status, source, position))

    tasks = (((number, entry["position"]), _extract_task, (folder / entry["file"], navigation))
             for number, (folder, entries) in enumerate(sets) for entry in entries)
    executor = make_executor(jobs, scheduler)
    summary.executor = executor.description
    with _terminate_as_interrupt(), executor:
        for (number, position), outcome in executor.run_unordered(tasks):
            source = str(folders[number])
            if isinstance(outcome, BaseException):
                reason = str(outcome) if isinstance(outcome, (InputError, ValueError)) else \
                    f"{type(outcome).__name__}: {outcome}"
                summary.failures.append(Failure(source, position, reason))
                log.warning("%s, position %d: %s", source, position, reason)
                notify("failed", source, position)
                continue
            nav, messages = outcome
            for level, text in messages:
                log.log(level, "%s", text)
            if world:
                nav = nav.in_world(poses[number, position])
            if to_folder:
                write_navigation(nav, targets[number] / f"nav_{position:04d}.geojson", **written)  # type: ignore[operator]
            else:
                maps.append((position, nav))
            summary.done += 1
            notify("extracted", source, position)
    if not to_folder:
        maps.sort(key=lambda item: item[0])
        if maps:
            write_navigation_set(maps, out if out is not None else "-", **written)
    summary.seconds = time.perf_counter() - start
    return summary


__all__ = [
    "Failure", "ProgressEvent", "SetSummary", "extract_model_set", "find_model_sets", "fit_model_set",
    "log_set_name", "navigation_map_of_file", "read_set_state", "settings_digest",
]
