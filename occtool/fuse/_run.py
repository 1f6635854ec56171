"""The map of a run: a fused map, its world map and raster, the navigation region, obstacles and frontiers.

:func:`map_of_run` turns fitted local models and their poses into :class:`RunMap`: the
fused map refitted as one :class:`occtool.fuse.WorldMap` (saved as ``world.occmap``)
and drawn as the Nav2 raster. :mod:`occtool.fuse._outputs` writes it where robots and
people look.
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.executor import in_order
from occtool.features import Pose
from occtool.fuse._frontiers import frontier_points, frontiers_in_strips
from occtool.fuse._map import FusedMap
from occtool.fuse._outlines import SpilledNavigation, SpilledOutlines, placed_outlines
from occtool.fuse._refit import build_world_map
from occtool.fuse._sightings import RunReturns
from occtool.fuse._union import union_in_groups
from occtool.fuse._world import WorldMap
from occtool.limits import release_free_memory
from occtool.raster import FREE, UNKNOWN, Raster
from occtool.robot import Robot

FloatArray = NDArray[np.float64]
#: Shortest frontier kept, metres of boundary: explore_lite's ``min_frontier_size`` default,
#: about a robot's width (a shorter gap is one the robot could not drive through to look).
FRONTIER_MIN_LENGTH = 0.5


@dataclass
class PlacedMap:
    """One position's navigation map in the world frame, with its pose and time."""

    position: int
    pose: Pose
    stamp: float | None
    nav: Any


@dataclass
class RunMap:
    """Everything ``occtool map`` writes, in the world (``map``) frame."""

    fused: FusedMap
    #: The world map: 2D (:class:`WorldMap`) or, for a 3D log, :class:`~occtool.fuse.WorldMap3D`.
    world: WorldMap | Any
    raster: Raster
    placed: list[PlacedMap]
    navigation: Any
    obstacles: FloatArray
    frontiers: FloatArray
    seconds: dict[str, float] = field(default_factory=dict)
    #: ``(stamp, pose)`` of every scan when the poses were registered (occtool.register): ``/tf`` in map.mcap.
    trajectory: list[tuple[float | None, Pose]] = field(default_factory=list)

    def _world_summary(self) -> dict[str, Any]:
        if isinstance(self.world, WorldMap):
            return {"kind": "2d", "bytes": self.world.nbytes, "segments": len(self.world),
                    "one_byte_grid_bytes_0.1m": self.world.grid_bytes(0.1)}
        return {"kind": "3d", "bytes": self.world.nbytes, "patches": len(self.world),
                "resolution": self.world.resolution, "free_cells": self.world.free_cells,
                "one_byte_grid_bytes_0.1m": self.world.grid_bytes(0.1), "resolution_choice": self.world.choice}

    def summary(self) -> dict[str, Any]:
        counts = self.raster.counts()
        grid_bytes = 4 * self.raster.cells.size
        return {
            "positions": len(self.fused),
            "combination": self.fused.combination,
            "threshold": self.fused.threshold,
            "fused_map_bytes": self.fused.nbytes,
            "world_map": self._world_summary(),
            "grid_float32_bytes_same_extent": grid_bytes,
            "raster": {"resolution": self.raster.resolution, "origin": list(self.raster.origin),
                       "rows": self.raster.shape[0], "columns": self.raster.shape[1], "cells": counts},
            "navigation_area_m2": float(self.navigation.area),
            "obstacle_points": len(self.obstacles),
            "frontier_points": len(self.frontiers),
            "seconds": {k: round(v, 3) for k, v in self.seconds.items()},
            "frame": "map",
            "path": [[round(p.pose.x, 3), round(p.pose.y, 3)] for p in self.placed],
        }


def frontiers_of(raster: Raster, min_length: float = FRONTIER_MIN_LENGTH) -> FloatArray:
    """Exploration points: where free space the run observed meets space nothing observed.

    A frontier cell is a free cell with an unexplored 4-neighbour (an unknown cell outside
    :attr:`Raster.explored`, or the raster's edge): the unknown rims round walls were
    observed and are no frontier. Frontier cells that touch (8-connected) form a frontier;
    one shorter than ``min_length`` metres (its cell count times the resolution) is
    dropped, and each other gives one point, its cell nearest the frontier's centroid,
    so the point lies on the boundary itself (as explore_lite's frontier search does).
    Points are ordered by frontier size, largest first, then by position.
    """
    from scipy import ndimage

    unexplored = raster.cells == UNKNOWN
    if raster.explored is not None:
        unexplored &= ~raster.explored
    beyond = np.pad(unexplored, 1, constant_values=True)
    touches = beyond[:-2, 1:-1] | beyond[2:, 1:-1] | beyond[1:-1, :-2] | beyond[1:-1, 2:]
    labels, count = ndimage.label((raster.cells == FREE) & touches, structure=np.ones((3, 3), dtype=bool))
    if count == 0:
        return np.zeros((0, 2))
    rows, cols = np.nonzero(labels)
    return frontier_points(raster, rows, cols, labels[rows, cols] - 1, count, min_length)


#: Navigation maps placed by one task (about 25 ms each).
NAVIGATION_CHUNK = 32


def _placed_navigation(models: list[Any], options: list[dict[str, Any]], poses: list[Pose]) -> list[Any]:
    """Each model's navigation map with its options, placed at its pose in the world (runs
    in this process or on a worker)."""
    from occtool.navigation import NavigationWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NavigationWarning)
        return [model.navigation_map(**option).in_world(pose) for model, option, pose in zip(models, options, poses)]


def map_of_run(fused: FusedMap, models: list[Any], positions: list[tuple[int, Pose, float | None]], *,
               resolution: float = 0.05, navigation: dict[str, Any] | None = None,
               frontier_min_length: float = FRONTIER_MIN_LENGTH, sightings: RunReturns | None = None,
               robot_overrides: Mapping[str, float] | None = None, world3d: Any | None = None,
               sensor_positions: Any | None = None, executor: Any = None,
               occupancy: bool | None = None, world: WorldMap | None = None,
               release_models: bool = False, placed: list[PlacedMap] | None = None,
               spill: str | os.PathLike[str] | None = None) -> RunMap:
    """Rasterise ``fused`` and place each model's navigation map in the world.

    Parameters
    ----------
    fused
        The fused map of ``models``.
    models
        The fitted regressors, one per entry of ``positions``.
    positions
        ``(position index, pose, stamp)`` of each model.
    resolution
        Raster cell size, metres.
    navigation
        Keywords of :meth:`occtool.fit.OccupancyRegressor.navigation_map` (``max_range``,
        ``threshold``, ``robot``...).
    sightings
        What every position of the run saw (:attr:`occtool.fuse.FuseReport.sightings`), for
        the world map's walls; ``None``: the fused map's own positions.
    frontier_min_length
        Shortest frontier kept, metres (:func:`frontiers_of`).
    robot_overrides
        :class:`~occtool.robot.Robot` fields (``radius``, ``sensor_height``, ...) that
        replace those of each model's own robot (or ``navigation``'s) in its navigation map.
    world3d, sensor_positions
        A :class:`~occtool.fuse.WorldMap3D` of the run: the world map instead of one refitted
        from ``fused``, and the raster its body band over the ground per tile
        (:func:`occtool.fuse._projection.project_band`, for the first model's robot), the
        ground implied by ``sensor_positions`` ``(N, 3)``, every position's sensor in the
        3D map's frame.
    executor
        An :class:`occtool.executor.Executor` (local processes, a Dask cluster) that draws
        the 2D raster's bands of rows and the navigation maps, a few at a time; ``None``:
        this process. The map is the same, byte for byte, wherever they ran.
    occupancy
        Keep the 2D raster's float32 occupancy (a ``scale`` Nav2 map needs it); ``None``: for
        a raster of at most :data:`occtool.fuse._world.OCCUPANCY_CELLS` cells (:meth:`WorldMap.rasterise`).
    world
        The 2D world map of the run, built already (:func:`occtool.fuse.build_world_map` of
        ``fused`` and ``sightings``, which are then not used); ``None``: built here.
    release_models
        Clear ``models`` (the list given) once their navigation maps are placed, and keep
        those maps without their per-height slices (no file holds them): what a large run
        holds a position while its raster is drawn and its files written
        (:func:`occtool.fuse.map_log` with ``lean``). The map is the same.
    placed
        The models' navigation maps placed already (:func:`place_navigation`; ``models``
        are then not used and may be empty); ``None``: placed here.
    spill
        A folder where a large 2D raster's cells are kept in an unnamed temporary file
        instead of memory (:class:`occtool.raster.SpilledCells`, read back a strip of rows
        at a time as the files are written); ``None``: in memory.
    """
    if placed is None and len(models) != len(positions):
        raise InputError(f"{len(models)} models but {len(positions)} positions")
    unknown = sorted(set(robot_overrides or {}) - {f.name for f in fields(Robot)})
    if unknown:
        raise InputError(f"robot_overrides: no robot field {', '.join(unknown)}")
    seconds: dict[str, float] = {}
    started = time.perf_counter()
    if world3d is None:
        the_world: WorldMap | Any = build_world_map(fused, sightings=sightings) if world is None else world
        seconds["world_map"] = time.perf_counter() - started
    else:
        the_world = world3d
        # The models' robot (the fused map's: the one they were fitted for, when they are gone already).
        robot = (navigation or {}).get("robot") or (models[0].robot_ if models else fused.robot)
        robot = replace(robot, **(robot_overrides or {}))
    # The navigation maps first: the models (a large run's largest share per position) may
    # then go before the raster is drawn.
    if placed is None:
        placed, seconds["navigation"] = place_navigation(models, positions, navigation=navigation,
                                                         robot_overrides=robot_overrides, executor=executor,
                                                         release_models=release_models)
    else:
        seconds["navigation"] = 0.0
    started = time.perf_counter()
    if world3d is None:
        raster = the_world.rasterise(resolution, executor=executor, occupancy=occupancy, spill=spill)
    else:
        from occtool.fuse._projection import project_band

        raster = project_band(world3d, sensor_positions if sensor_positions is not None else np.zeros((0, 3)),
                              sensor_height=robot.sensor_height, body_height=robot.body_height,
                              ground_clearance=robot.ground_clearance, radius=robot.radius, resolution=resolution)
    # In the order the stages ran before the navigation maps moved ahead (summary.json's seconds).
    seconds = {**{key: seconds[key] for key in ("world_map",) if key in seconds},
               "raster": time.perf_counter() - started, "navigation": seconds["navigation"]}
    started = time.perf_counter()
    # A group of overlapping polygons at a time: campus x10's in one union took 600 MB more.
    outlines, bounds = placed_outlines([p.nav for p in placed])
    region = union_in_groups(outlines, bounds=bounds)
    del outlines
    obstacles = np.concatenate([np.asarray(p.nav.obstacle_points, dtype=np.float64).reshape(-1, 2)
                                for p in placed]) if placed else np.zeros((0, 2))
    release_free_memory()  # the world map's and the raster's temporaries, back to the system
    frontiers = frontiers_in_strips(raster, frontier_min_length)
    seconds["union_frontiers"] = time.perf_counter() - started
    return RunMap(fused, the_world, raster, placed, region, obstacles, frontiers, seconds)


def place_navigation(models: list[Any], positions: list[tuple[int, Pose, float | None]], *,
                     navigation: dict[str, Any] | None = None, robot_overrides: Mapping[str, float] | None = None,
                     executor: Any = None, release_models: bool = False,
                     spill: str | os.PathLike[str] | None = None) -> tuple[list[PlacedMap], float]:
    """Each model's navigation map placed at its position, as :func:`map_of_run` places them
    (its keywords), and the seconds it took. ``spill``: a folder where the maps' polygons
    wait in an unnamed temporary file (:class:`occtool.fuse._outlines.SpilledNavigation`,
    read back as they are drawn and unioned) instead of memory; ``None``: in memory."""
    started = time.perf_counter()
    outlines = SpilledOutlines(spill) if spill is not None else None
    options = []
    for model in models:
        option = dict(navigation or {})
        if release_models:
            # No file holds a placed map's per-height slices: not cut at all (0.3 ms a campus keyframe).
            option["slices"] = False
        if robot_overrides:
            option["robot"] = replace(option.get("robot", model.robot_), **robot_overrides)
        options.append(option)
    chunks = in_order(executor, "placing the navigation maps", _placed_navigation,
                      ((models[k:k + NAVIGATION_CHUNK], options[k:k + NAVIGATION_CHUNK],
                        [pose for _, pose, _ in positions[k:k + NAVIGATION_CHUNK]])
                       for k in range(0, len(models), NAVIGATION_CHUNK)))
    placed = []
    for chunk, at in zip(chunks, range(0, len(models), NAVIGATION_CHUNK)):
        for (index, pose, stamp), nav in zip(positions[at:at + NAVIGATION_CHUNK], chunk):
            placed.append(PlacedMap(index, pose, stamp, nav if outlines is None else SpilledNavigation(nav, outlines)))
        del chunk
    if release_models:
        models.clear()
    return placed, time.perf_counter() - started


__all__ = ["FRONTIER_MIN_LENGTH", "PlacedMap", "RunMap", "frontiers_of", "map_of_run", "place_navigation"]
