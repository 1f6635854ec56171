"""Fitting model sets: one model per position of one or more logs (see :mod:`occtool.modelset`)."""

from __future__ import annotations

import contextlib
import os
import stat
import time
from collections import Counter
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from occtool.errors import InputError
from occtool.executor import Failed, tasks_of_fits
from occtool.modelset._common import (
    Failure,
    ProgressCallback,
    ProgressEvent,
    SetSummary,
    _IndexWriter,
    _terminate_as_interrupt,
    log,
    log_set_name,
)
from occtool.modelset._settings import _GeometrySurvey, estimator_for_log, settings_digest  # noqa: F401 - estimator_for_log re-exported

# --- settings and reuse -------------------------------------------------------------------

def _reusable(target: Path, digest: str, settings: str) -> bool:
    """Whether ``target`` is a readable model of these features fitted with these settings."""
    from occtool.formats.model import load_model

    try:
        if not stat.S_ISREG(os.stat(target).st_mode):
            return False
        model = load_model(target)
    except (OSError, ValueError):
        return False
    return model.features_digest_ == digest and model.run_.get("settings_sha256") == settings


# --- fitting ------------------------------------------------------------------------------

def _reason(exc: BaseException) -> str:
    return str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"


def _fit_chunk(params: dict[str, Any], chunk: list[Any]) -> list[Any]:
    """Fit a few positions (runs in a worker). For each: the model file's text (its run
    object a placeholder), a few facts for the log, the seconds and the host; or a
    :class:`Failed`."""
    import platform

    from occtool.fit import OccupancyRegressor
    from occtool.formats.model import RUN_PLACEHOLDER, model_text
    from occtool.observation import observe

    out: list[Any] = []
    for features in chunk:
        start = time.perf_counter()
        try:
            model = OccupancyRegressor(**params).fit(features)
        except (InputError, ValueError, ArithmeticError, MemoryError) as exc:
            out.append(Failed(_reason(exc)))
            continue
        seconds = time.perf_counter() - start
        facts = {"features": model.n_features_, "rmse": model.rmse_}
        # What the position observed goes into its file: a map of the set needs its free rays
        # and returns, and the file keeps no features (occtool.fuse.Observation).
        text = model_text(model, run=RUN_PLACEHOLDER, observed=observe(model, features))
        out.append((text, facts, seconds, platform.node()))
    return out




def _open_source(source: Any, read_options: dict[str, Any]) -> Any:
    """The positions of a log as an iterable that can be read twice: a
    :class:`~occtool.io.position_stream.PositionStream` for a file (read one position at a
    time), the positions of a :class:`~occtool.features.RangeLog` as they are, and standard
    input read whole (it is copied to a temporary file that is gone after reading)."""
    from occtool.features import RangeLog

    if str(source) == "-" and not isinstance(source, RangeLog):
        from occtool.io.stream import read_log_stream

        source = read_log_stream(**read_options)
    if isinstance(source, RangeLog):
        return _HeldLog(source)
    from occtool.io import iter_positions

    return iter_positions(source, **read_options)


class _HeldLog:
    """A log already in memory, with the interface of a position stream."""

    def __init__(self, range_log: Any) -> None:
        self.source = range_log.source
        self.notes = range_log.notes
        self.positions = range_log.positions

    def __iter__(self) -> Iterator[Any]:
        return iter(self.positions)


def _chosen(stream: Any, positions: Sequence[int] | None) -> Iterator[Any]:
    """The positions to fit, as the stream yields them (all), or those asked for in the
    order asked (only those are held)."""
    if positions is None:
        yield from stream
        return
    wanted = set(positions)
    held = {k: item for k, item in enumerate(stream) if k in wanted}  # as RangeLog.single numbers them
    for index in positions:
        yield held[index]


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
    planar_defaults: bool = False,
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
    planar_defaults
        Fit a log of planar scans with a planar scanner's robot (:func:`estimator_for_log`);
        every log's geometry findings are logged either way.

    Notes
    -----
    Memory does not grow with a log's length: a log file is read twice through
    :func:`occtool.io.iter_positions`, one position at a time. The first pass checks every
    line or message (a bad one is an error before any model is written), counts the
    positions (for the progress bar and ``positions``) and surveys their geometry for
    :func:`estimator_for_log`; the second pass hands positions to the executor in chunks,
    at most its window of chunks in flight, and each model is written as it comes back.
    Standard input (``"-"``) and a :class:`~occtool.features.RangeLog` are held whole; with
    ``positions``, only the chosen positions are held.

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
    from occtool._version import __version__
    from occtool.executor import check_jobs, make_executor
    from occtool.features import log_notes
    from occtool.fit import OccupancyRegressor, features_digest
    from occtool.formats.model import save_model_text, with_run
    from occtool.observation import returns_per_degree
    from occtool.robot import Robot

    start = time.perf_counter()
    sources = list(logs) if isinstance(logs, (list, tuple)) else [logs]
    if not sources:
        raise InputError("no logs to fit")
    if scheduler is None:
        check_jobs(jobs)
    template = estimator if estimator is not None else OccupancyRegressor()
    OccupancyRegressor(**template.get_params(deep=False))._validate()
    log_settings: dict[int, str] = {}
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
                raise FileExistsError(f"{existing[0]} exists already (pass overwrite=True to replace it)")

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
                # The first pass reads the whole log (checking every line, so a bad one is an
                # error before any model is written), counts its positions and surveys their
                # geometry, holding one position at a time; the second pass fits.
                stream = _open_source(source, read_options)
                survey = _GeometrySurvey(template, planar_defaults)
                wanted = Counter(positions) if positions is not None else None
                total = 0
                for total, item in enumerate(stream, start=1):  # noqa: B007 - the count is used below
                    for _ in range(1 if wanted is None else wanted[total - 1]):
                        survey.add(item)  # the positions to fit, as estimator_for_log sees them
                if positions is not None:
                    for index in positions:
                        if not 0 <= index < total:
                            raise InputError(f"position {index} is out of range (the log has {total})")
                elif not total:
                    raise InputError(f"{stream.source or 'the log'} holds no range data")
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
            log_notes(log, Path(name).name, stream.notes)
            log_template = survey.result()
            params = log_template.get_params(deep=False)
            settings = log_settings[number] = settings_digest(log_template)
            state["logs_read"] += 1
            target.mkdir(parents=True, exist_ok=True)
            count = len(positions) if positions is not None else survey.count
            summary.positions += count
            outstanding[number] = count
            notify("read", name)
            robot = params.get("robot") or Robot()
            to_fit = []  # this log's positions that need a fit, a task's worth at a time
            for item in _chosen(stream, positions):
                digest = features_digest(item.features)
                model_file = f"model_{item.index:04d}.json"
                # How dense its returns are: a map of the set tells a scanning laser by it
                # (occtool.fuse.fuse_model_set), where a model file keeps no features.
                density = returns_per_degree(item.features, robot, params.get("level"))
                entry = {"position": item.index, "file": model_file,
                         "pose": item.pose.to_dict() if item.pose is not None else None,
                         "stamp": item.stamp, "features": len(item.features), "features_sha256": digest,
                         "returns_per_degree": round(density, 3)}
                if skip_existing and _reusable(target / model_file, digest, settings):
                    writer.add(entry)
                    summary.reused += 1
                    outstanding[number] -= 1
                    notify("reused", name, item.index)
                    continue
                to_fit.append((entry, item.features))
                # All but the last group of tasks_of_fits's rule are whole tasks already.
                *tasks_ready, to_fit = tasks_of_fits(to_fit, lambda pair: len(pair[1]))
                for task in tasks_ready:
                    yield (number, [e for e, _ in task]), _fit_chunk, (params, [f for _, f in task])
            if to_fit:
                yield (number, [e for e, _ in to_fit]), _fit_chunk, (params, [f for _, f in to_fit])
            writer.all_submitted = True
            del stream, survey

    executor = make_executor(jobs, scheduler)
    summary.executor = executor.description
    interrupted = True
    try:
        with _terminate_as_interrupt(), executor:
            for (number, entries), outcomes in executor.run_unordered(tasks()):
                writer = writers[number]
                if isinstance(outcomes, BaseException):  # the whole chunk: a worker died, a cluster error
                    outcomes = [Failed(_reason(outcomes))] * len(entries)
                for entry, outcome in zip(entries, outcomes):
                    outstanding[number] -= 1
                    if isinstance(outcome, Failed):
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
                        "settings_sha256": log_settings[number],
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


