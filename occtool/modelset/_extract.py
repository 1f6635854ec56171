"""Extracting model sets: the navigation map of every position (see :mod:`occtool.modelset`)."""

from __future__ import annotations

import logging
import os
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from occtool.errors import InputError
from occtool.modelset._common import (
    Failure,
    ProgressCallback,
    ProgressEvent,
    SetSummary,
    _terminate_as_interrupt,
    find_model_sets,
    log,
    read_set_state,
)

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

    from occtool.formats.model import read_navigable
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
        Keywords of :func:`occtool.formats.geojson.write_navigation` (``sequence``,
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
    from occtool.formats.geojson import write_navigation, write_navigation_set
    from occtool.modelset._index import read_model_set

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
            log.warning("%s: the model set is incomplete (an interrupted fit; resume it with skip_existing=True)",
                        folder)
    to_folder = per_position if per_position is not None else (
        out is not None and (str(out).endswith(("/", os.sep)) or Path(out).is_dir()))
    if len(sets) > 1 and not to_folder:
        raise InputError("several model sets need an output folder (out ending in '/')")
    if len({f.resolve() for f in folders}) != len(folders):
        raise InputError("the same model set is given twice")
    written = dict(geojson or {})
    targets: list[Path] = []
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
                        raise FileExistsError(f"{candidate} exists already (pass overwrite=True to replace it)")
        for target in targets:
            if target.exists() and not target.is_dir():
                raise InputError(f"{target} exists and is not a folder")
        for target in targets:
            target.mkdir(parents=True, exist_ok=True)
    elif not overwrite and out not in (None, "-") and Path(out).exists():
        raise FileExistsError(f"{out} exists already (pass overwrite=True to replace it)")
    poses: dict[tuple[int, int], Any] = {}
    if world:
        for number, (folder, entries) in enumerate(sets):
            for entry in entries:
                if entry.get("pose") is None:
                    raise InputError(
                        f"{folder / 'index.json'}: position {entry['position']} has no pose for world=True")
                try:
                    poses[number, entry["position"]] = Pose.from_dict(entry["pose"])
                except (TypeError, ValueError):
                    raise InputError(
                        f"{folder / 'index.json'}: position {entry['position']}'s pose is not numbers") from None

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
                write_navigation(nav, targets[number] / f"nav_{position:04d}.geojson", **written)
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


