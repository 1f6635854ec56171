"""The library ``occtool map``: a log or a model set in, every output of its map written.

:func:`map_log` reads a log (registering its scans when it needs it), fits its keyframes,
fuses them, builds the map of the run and writes it (:func:`occtool.fuse.write_run_map`,
and ``poses.csv`` when the poses were registered, the files moved into place as one set);
:func:`map_model_set` does the same from the models of ``occtool fit LOG -o DIR/``. Both
return a :class:`MapResult`; the command line only parses its options, calls one of them
and reports.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from occtool.executor import make_executor
from occtool.features import RangeLog
from occtool.fuse._build import FuseReport, fuse_log, fuse_model_set
from occtool.fuse._combine import DEFAULT_COMBINATION
from occtool.fuse._keyframes import KEYFRAME_NEW_SHARE
from occtool.fuse._log3d import is_3d_log, map_log_3d, sensor_positions
from occtool.fuse._memory import check_map_memory
from occtool.fuse._outputs import _write_run_map, check_outputs
from occtool.fuse._refit import build_world_map
from occtool.fuse._run import RunMap, map_of_run, place_navigation
from occtool.limits import DEFAULT_MEMORY_LIMIT, release_free_memory

#: The kinds of world map :func:`map_log` writes.
WORLD_KINDS = ("auto", "2d", "3d")


@dataclass
class MapResult:
    """What :func:`map_log` or :func:`map_model_set` made and wrote."""

    #: The map of the run (fused map, world map, raster, navigation region, points).
    run: RunMap
    #: The files written, ``world.occmap`` first.
    written: list[Path]
    #: What ``summary.json`` holds.
    summary: dict[str, Any]
    #: The fitted (or read) models, one per position of the fused map.
    models: list[Any] = field(default_factory=list)
    #: :func:`fuse_log`'s report (``None`` for a model set).
    report: FuseReport | None = None
    #: The registration's report (``None`` when the log's own poses were kept).
    registration: Any | None = None


def _write(run: RunMap, output: str | os.PathLike[str], extra: dict[str, Any], registration: Any, *,
           overwrite: bool, simplify: float | None, precision: int | None, mcap: bool, georeference: Any | None,
           nav2_mode: str) -> tuple[list[Path], dict[str, Any]]:
    from occtool.register import trajectory, write_map_poses

    run.trajectory = trajectory(registration)
    if registration is not None:
        extra["registration"] = registration.to_dict()

    def poses_csv(staging: Path) -> list[Path]:
        # In the set: written beside the others and moved into place with them.
        poses = write_map_poses(registration, staging)
        return [poses] if poses is not None else []

    return _write_run_map(run, output, overwrite=overwrite, simplify=simplify, precision=precision, mcap=mcap,
                          georeference=georeference, extra_summary=extra, nav2_mode=nav2_mode, also=poses_csv)


def _existing_folder(output: str | os.PathLike[str]) -> Path:
    """The output folder, or its nearest existing parent: where a lean run keeps its large
    raster's cells while it writes its files (an unnamed file, on the disk the map goes to)."""
    folder = Path(output).absolute()
    while not folder.is_dir() and folder != folder.parent:
        folder = folder.parent
    return folder


def map_log(source: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | RangeLog,
            output: str | os.PathLike[str], *,
            estimator: Any | None = None, read_options: Mapping[str, Any] | None = None,
            register: bool | None = None, registration: Any | None = None,
            combination: str = DEFAULT_COMBINATION, threshold: float = 0.6,
            keyframe_share: float = KEYFRAME_NEW_SHARE, resolution: float = 0.05, max_range: float = 1.5,
            nav2_mode: str = "trinary", simplify: float | None = None, precision: int | None = None,
            georeference: Any | None = None, mcap: bool = True, overwrite: bool = True,
            progress: Callable[[int, int], None] | None = None, heights_from_data: bool = False,
            world: str = "auto", world_resolution: float | None = None, seed: int = 0,
            memory_limit: int | float | str | None = DEFAULT_MEMORY_LIMIT, jobs: int | None = 1,
            scheduler: Any = None, lean: bool = False) -> MapResult:
    """Map a log: what ``occtool map LOG -o OUTPUT`` does.

    Parameters
    ----------
    source
        A log file or folder (read with :func:`occtool.io.read_log` and ``read_options``;
        a folder of scans with ``read_options={"poses": ...}``), several point-cloud files
        (a list, read as one scan sequence: each file a scan, registered without poses), or a
        :class:`~occtool.features.RangeLog` read already (mapped on its own poses).
    output
        The folder the map is written into (created if missing): ``world.occmap``, the
        Nav2 map, ``map.mcap``, the GeoJSON layers, ``summary.json``, and ``poses.csv``
        when the poses were registered (:func:`occtool.fuse.write_run_map`).
    estimator
        The unfitted :class:`~occtool.fit.OccupancyRegressor` every keyframe is fitted with
        (default: one with its defaults); its robot is the map's.
    read_options
        Keywords of :func:`occtool.io.read_log` (``no_return_range``, ``format``, ...).
    register, registration
        Register the scans (``True``), keep the log's poses (``False``) or register when the
        log has no poses or only odometry (``None``); ``registration`` is the
        :class:`occtool.register.RegistrationSettings` (default: its defaults).
    combination, threshold, keyframe_share
        As for :func:`occtool.fuse.fuse_log`; ``threshold`` also cuts the navigation maps.
    resolution, max_range
        The raster's cell size and each position's navigation polygon's radius, metres.
    nav2_mode, simplify, precision, georeference, mcap, overwrite
        As for :func:`occtool.fuse.write_run_map`. The run's 2D raster keeps its float32
        occupancy (``probability``) only for a ``"scale"`` map.
    progress
        Called with ``(done, total)`` as the keyframes are fitted.
    heights_from_data
        No sensor or body height was given: the data's sets them (:func:`occtool.fuse.fuse_log`).
    world
        The world map's kind: ``"2d"`` (:class:`occtool.fuse.WorldMap`, the body band's
        walls, ``world.occmap`` version 4), ``"3d"`` (:class:`occtool.fuse.WorldMap3D`:
        surfaces and crossed free space in x, y, z, version 6; the Nav2 map its body band
        over the ground per tile) or ``"auto"``: 3D when the log's returns spread above and
        below the sensor (:func:`occtool.fuse.is_3d_log`: a depth camera, a 3D lidar).
    world_resolution
        The 3D map's cell size, metres; ``None``: chosen on an inner split of the log's own
        positions (:func:`occtool.fuse.choose_resolution`, seeded by ``seed``).
    memory_limit
        Refuse a run estimated (from the log, before any fit) to need more memory than this:
        bytes, or a size such as ``"8G"``; ``None``: no limit (:func:`occtool.fuse.check_map_memory`).
    jobs, scheduler
        Where the expensive per-position and per-tile work runs (the keyframes' fits, the
        navigation maps, the 2D raster's bands of rows): ``jobs`` local processes (1: this
        process; ``None``: the cores), or the Dask cluster at ``scheduler`` (an address such
        as ``"tcp://host:8786"`` or a ``distributed.Client``; the ``dask`` extra, occtool on
        the workers): :func:`occtool.executor.make_executor`. The files are the same, byte
        for byte, wherever it ran.
    lean
        Hold only what the files need, each part no longer than the map needs it: a log
        read here (for a 2D map) is used up as it is fitted (:func:`fuse_log`'s
        ``consume``), the models go once their navigation maps are placed, before the world
        map is built (:attr:`MapResult.models` is then empty), every position's sightings
        once the world map is built (the report's :attr:`~FuseReport.sightings` is
        ``None``), the placed navigation maps keep no per-height slices and their
        polygons wait in an unnamed temporary file in the output folder
        (:class:`occtool.fuse._outlines.SpilledNavigation`), and a large 2D
        raster's cells wait in an unnamed temporary file in the output folder (or its
        nearest existing parent) while the files are written (:class:`occtool.raster.SpilledCells`;
        :attr:`MapResult.run`'s raster reads them from there). The files are
        the same; a large run's memory is less (the command line maps lean).

    Raises
    ------
    InputError
        A log that cannot be read, placed or fitted, or outputs that cannot be written;
        ``FileExistsError`` for an existing output without ``overwrite``. Checked before
        any work where it can be.
    """
    from occtool.errors import InputError

    if world not in WORLD_KINDS:
        raise InputError(f"world must be one of {', '.join(WORLD_KINDS)}, got {world!r}")
    if world_resolution is not None and not (0.01 <= world_resolution <= 10.0):
        raise InputError(f"world_resolution must lie in [0.01, 10] metres, got {world_resolution}")
    check_outputs(output, nav2_mode=nav2_mode, overwrite=overwrite)
    if estimator is None:
        from occtool.fit import OccupancyRegressor

        estimator = OccupancyRegressor()
    report_of_registration = None
    if isinstance(source, RangeLog):
        if register:
            raise InputError("register=True needs the log's file (its scans are read one by one)")
        log, name = source, source.source or "log"
    else:
        from occtool.register import RegistrationSettings, read_map_log

        log, report_of_registration = read_map_log(source, read_options, register=register,
                                                   settings=registration or RegistrationSettings())
        name = str(source) if isinstance(source, (str, os.PathLike)) else log.source
        # The reader's parsed lines and scans, gone once grouped into positions (campus x2:
        # 100 MB read, 53 MB of it the positions).
        release_free_memory()
    three_d = world == "3d" or (world == "auto" and is_3d_log(log))
    check_map_memory(log, memory_limit=memory_limit, resolution=resolution, nav2_mode=nav2_mode, world3d=three_d,
                     spill=lean)
    with make_executor(jobs, scheduler) as executor:  # an unreachable scheduler is refused before any fit
        # A log read here is used up as it is fitted when mapped lean (a 3D map reads it again).
        fused, models, report = fuse_log(log, estimator, combination=combination, threshold=threshold,
                                         keyframe_share=keyframe_share, progress=progress,
                                         heights_from_data=heights_from_data, executor=executor,
                                         consume=lean and not three_d and not isinstance(source, RangeLog))
        positions = list(zip(report.fitted, fused.poses, fused.stamps))
        navigation = {"max_range": max_range, "threshold": threshold}
        placed, navigation_seconds = None, None
        if lean:
            # The navigation maps first, so that the models go before the world map is built.
            placed, navigation_seconds = place_navigation(models, positions, navigation=navigation,
                                                          executor=executor, release_models=True,
                                                          spill=_existing_folder(output))
        world3d, world2d, sensors = None, None, None
        started = time.perf_counter()
        if three_d:
            world3d = map_log_3d(log, world_resolution, to_map=log.to_log_frame, seed=seed)
            sensors = sensor_positions(log)
        if not isinstance(source, RangeLog):
            # Read here and fused: the features of every scan are of no more use (a large run's
            # raster needs the memory they held).
            del log
        # The scans' features and the models, gone: their pages of the C heap back to the
        # system before the world map is built (campus x2: 183 -> 140 MB after the fits).
        release_free_memory()
        if not three_d:
            world2d = build_world_map(fused, sightings=report.sightings)
            if lean:
                report.sightings = None  # every position's returns: the world map holds what the files need
        seconds = time.perf_counter() - started
        # The raster keeps its float32 occupancy only for a scale map, the one file drawn from
        # it: four bytes a cell a trinary map would hold for nothing.
        run = map_of_run(fused, models, positions, resolution=resolution, navigation=navigation,
                         sightings=report.sightings, world3d=world3d, sensor_positions=sensors, executor=executor,
                         occupancy=nav2_mode == "scale", world=world2d, release_models=lean, placed=placed,
                         spill=_existing_folder(output) if lean else None)
    run.seconds["world_map"] = seconds
    if navigation_seconds is not None:
        run.seconds["navigation"] = navigation_seconds
    extra = {"source": name, "fitted_here": True, "fit_seconds": round(report.fit_seconds, 3),
             "skipped_positions": [index for index, _ in report.skipped],
             "keyframe_share": keyframe_share, "not_keyframes": len(report.not_keyframes)}
    written, summary = _write(run, output, extra, report_of_registration, overwrite=overwrite, simplify=simplify,
                              precision=precision, mcap=mcap, georeference=georeference, nav2_mode=nav2_mode)
    return MapResult(run, written, summary, models, report, report_of_registration)


def map_model_set(models: str | os.PathLike[str], output: str | os.PathLike[str], *,
                  combination: str = DEFAULT_COMBINATION, threshold: float = 0.6, resolution: float = 0.05,
                  max_range: float = 1.5, robot_overrides: Mapping[str, float] | None = None,
                  nav2_mode: str = "trinary",
                  simplify: float | None = None, precision: int | None = None, georeference: Any | None = None,
                  mcap: bool = True, overwrite: bool = True, jobs: int | None = 1, scheduler: Any = None) -> MapResult:
    """Map a model set: what ``occtool map MODELS/ -o OUTPUT`` does.

    ``models`` is a set written by ``occtool fit LOG -o DIR/`` (``DIR`` or
    ``DIR/index.json``), fused by :func:`occtool.fuse.fuse_model_set`; the other
    keywords are :func:`map_log`'s. Its models are fitted already: their fit settings
    are the ones they were fitted with, and so is their robot but for ``robot_overrides``,
    :class:`~occtool.robot.Robot` fields (``radius``, ``sensor_height``, ``body_height``,
    ``ground_clearance``) that replace the fitted robot's in the navigation maps (the
    navigation region, obstacles and frontiers; the fused and world maps keep the band the
    models were fitted for). ``jobs`` and ``scheduler`` draw the navigation maps and the
    raster there, as for :func:`map_log`.
    """
    check_outputs(output, nav2_mode=nav2_mode, overwrite=overwrite)
    fused, fitted, positions = fuse_model_set(models, combination=combination, threshold=threshold)
    with make_executor(jobs, scheduler) as executor:
        run = map_of_run(fused, fitted, positions, resolution=resolution,
                         navigation={"max_range": max_range, "threshold": threshold},
                         robot_overrides=robot_overrides, executor=executor,
                         occupancy=nav2_mode == "scale")
    extra: dict[str, Any] = {"source": str(models), "fitted_here": False}
    written, summary = _write(run, output, extra, None, overwrite=overwrite, simplify=simplify, precision=precision,
                              mcap=mcap, georeference=georeference, nav2_mode=nav2_mode)
    return MapResult(run, written, summary, fitted)


__all__ = ["WORLD_KINDS", "MapResult", "map_log", "map_model_set"]
