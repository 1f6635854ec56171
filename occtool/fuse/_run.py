"""The map of a run: a fused map, its world map and raster, the navigation region, obstacles and frontiers.

:func:`map_of_run` turns fitted local models and their poses into :class:`RunMap`: the
fused map refitted as one :class:`occtool.fuse.WorldMap` (saved as ``world.occmap``)
and drawn as the Nav2 raster. :mod:`occtool.fuse._outputs` writes it where robots and
people look.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Pose
from occtool.fuse._map import FusedMap
from occtool.fuse._refit import build_world_map
from occtool.fuse._sightings import RunReturns
from occtool.fuse._world import WorldMap
from occtool.raster import FREE, UNKNOWN, Raster
from occtool.robot import Robot

FloatArray = NDArray[np.float64]
#: How far past an exploration point the raster is walked for unknown space, metres.
FRONTIER_LOOKAHEAD = 1.0


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
    world: WorldMap
    raster: Raster
    placed: list[PlacedMap]
    navigation: Any
    obstacles: FloatArray
    frontiers: FloatArray
    seconds: dict[str, float] = field(default_factory=dict)
    #: ``(stamp, pose)`` of every scan when the poses were registered (occtool.register): ``/tf`` in map.mcap.
    trajectory: list[tuple[float | None, Pose]] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        counts = self.raster.counts()
        grid_bytes = 4 * self.raster.cells.size
        return {
            "positions": len(self.fused),
            "combination": self.fused.combination,
            "threshold": self.fused.threshold,
            "fused_map_bytes": self.fused.nbytes,
            "world_map": {"bytes": self.world.nbytes, "segments": len(self.world),
                          "one_byte_grid_bytes_0.1m": self.world.grid_bytes(0.1)},
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


def _frontiers(raster: Raster, placed: list[PlacedMap], lookahead: float) -> FloatArray:
    """Exploration points past which no position saw: walking on from each, away from the
    position that found it, the fused raster turns unknown before it turns occupied
    (within ``lookahead`` metres)."""
    points, outward = [], []
    for item in placed:
        pts = np.asarray(item.nav.exploration_points, dtype=np.float64).reshape(-1, 2)
        if len(pts):
            direction = pts - np.array([item.pose.x, item.pose.y])
            direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
            points.append(pts)
            outward.append(direction)
    if not points:
        return np.zeros((0, 2))
    pts, direction = np.concatenate(points), np.concatenate(outward)
    steps = np.arange(1, max(2, int(np.ceil(lookahead / raster.resolution))) + 1) * raster.resolution
    walk = pts[:, None, :] + steps[None, :, None] * direction[:, None, :]
    row, col, inside = raster.cell_of(walk.reshape(-1, 2))
    cells = np.where(inside, raster.cells[row, col], UNKNOWN).reshape(len(pts), len(steps))
    # Off the raster is unexplored; an unknown cell the run observed (a wall's uncertain edge) is not.
    unexplored = np.where(inside, raster.unexplored(row, col), True).reshape(len(pts), len(steps))
    not_free = cells != FREE
    first = np.argmax(not_free, axis=1)
    reached = not_free.any(axis=1)
    return pts[reached & unexplored[np.arange(len(pts)), first]]


def map_of_run(fused: FusedMap, models: list[Any], positions: list[tuple[int, Pose, float | None]], *,
               resolution: float = 0.05, navigation: dict[str, Any] | None = None,
               lookahead: float = FRONTIER_LOOKAHEAD, sightings: RunReturns | None = None,
               robot_overrides: Mapping[str, float] | None = None) -> RunMap:
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
    robot_overrides
        :class:`~occtool.robot.Robot` fields (``radius``, ``sensor_height``, ...) that
        replace those of each model's own robot (or ``navigation``'s) in its navigation map.
    """
    from occtool.navigation import NavigationWarning

    if len(models) != len(positions):
        raise InputError(f"{len(models)} models but {len(positions)} positions")
    unknown = sorted(set(robot_overrides or {}) - {f.name for f in fields(Robot)})
    if unknown:
        raise InputError(f"robot_overrides: no robot field {', '.join(unknown)}")
    seconds = {}
    started = time.perf_counter()
    world = build_world_map(fused, sightings=sightings)
    seconds["world_map"] = time.perf_counter() - started
    started = time.perf_counter()
    raster = world.rasterise(resolution)
    seconds["raster"] = time.perf_counter() - started
    started = time.perf_counter()
    placed = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NavigationWarning)
        for model, (index, pose, stamp) in zip(models, positions):
            options = dict(navigation or {})
            if robot_overrides:
                options["robot"] = replace(options.get("robot", model.robot_), **robot_overrides)
            nav = model.navigation_map(**options).in_world(pose)
            placed.append(PlacedMap(index, pose, stamp, nav))
    seconds["navigation"] = time.perf_counter() - started
    started = time.perf_counter()
    region = shapely.union_all([p.nav.polygon for p in placed if not p.nav.polygon.is_empty])
    obstacles = np.concatenate([np.asarray(p.nav.obstacle_points, dtype=np.float64).reshape(-1, 2)
                                for p in placed]) if placed else np.zeros((0, 2))
    frontiers = _frontiers(raster, placed, lookahead)
    seconds["union_frontiers"] = time.perf_counter() - started
    return RunMap(fused, world, raster, placed, region, obstacles, frontiers, seconds)


__all__ = ["FRONTIER_LOOKAHEAD", "PlacedMap", "RunMap", "map_of_run"]
