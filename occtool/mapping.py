"""The map of a run: a fused map, its world map and raster, the navigation region, obstacles and frontiers.

:func:`map_of_run` turns fitted local models and their poses into :class:`RunMap`: the
fused map refitted as one :class:`occtool.fuse.WorldMap` (saved as ``world.occmap``)
and drawn as the Nav2 raster. The writers put it where robots and people look: the
world map, a Nav2 map (:mod:`occtool.formats.nav2`), an
MCAP that Foxglove draws with its standard schemas (:mod:`occtool.formats.foxglove`),
GeoJSON layers with one geometry type each, and a JSON summary (:func:`write_run_map`).
"""

from __future__ import annotations

import json
import math
import os
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray

from occtool._files import atomic_write
from occtool.errors import InputError
from occtool.features import Pose
from occtool.fuse import FusedMap, Raster, RunReturns, WorldMap

FloatArray = NDArray[np.float64]
#: How far past an exploration point the raster is walked for unknown space, metres.
FRONTIER_LOOKAHEAD = 1.0
LAYERS = ("navigation", "obstacles", "frontiers")


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
    from occtool.fuse import FREE, UNKNOWN

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
               lookahead: float = FRONTIER_LOOKAHEAD, sightings: RunReturns | None = None) -> RunMap:
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
    """
    from occtool.navigation import NavigationWarning

    if len(models) != len(positions):
        raise InputError(f"{len(models)} models but {len(positions)} positions")
    from occtool.fuse import build_world_map

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
            nav = model.navigation_map(**(navigation or {})).in_world(pose)
            placed.append(PlacedMap(index, pose, stamp, nav))
    seconds["navigation"] = time.perf_counter() - started
    started = time.perf_counter()
    region = shapely.union_all([p.nav.polygon for p in placed if not p.nav.polygon.is_empty])
    obstacles = np.concatenate([np.asarray(p.nav.obstacle_points, dtype=np.float64).reshape(-1, 2)
                                for p in placed]) if placed else np.zeros((0, 2))
    frontiers = _frontiers(raster, placed, lookahead)
    seconds["union_frontiers"] = time.perf_counter() - started
    return RunMap(fused, world, raster, placed, region, obstacles, frontiers, seconds)


# ---------------------------------------------------------------------- GeoJSON
def _polygons(geometry: Any) -> list[Any]:
    if geometry is None or geometry.is_empty:
        return []
    if geometry.geom_type == "Polygon":
        return [geometry]
    return [g for g in getattr(geometry, "geoms", []) if g.geom_type == "Polygon" and not g.is_empty]


def layer_collections(run: RunMap, *, simplify: float | None = None, precision: int | None = None,
                      georeference: Any | None = None) -> dict[str, dict[str, Any]]:
    """The three GeoJSON layers, one geometry type each: ``navigation`` (Polygon),
    ``obstacles`` and ``frontiers`` (Point), metric x, y in the ``map`` frame, or WGS84
    longitude/latitude (RFC 7946) with a :class:`occtool.formats.wgs84.Georeference`.
    ``simplify`` is in metres either way."""
    region = run.navigation
    if simplify is not None:
        if not (math.isfinite(simplify) and simplify >= 0):
            raise InputError(f"simplify tolerance must be a number of metres >= 0, got {simplify}")
        region = shapely.simplify(region, simplify, preserve_topology=True)
    polygons = [shapely.orient_polygons(p) if hasattr(shapely, "orient_polygons") else p for p in _polygons(region)]
    obstacles, frontiers = run.obstacles, run.frontiers
    properties: dict[str, Any] = {"frame": "map", "units": "m",
                                  "crs_note": "metric x, y in the map frame, not longitude/latitude"}
    if georeference is not None:
        polygons = [shapely.transform(p, georeference.to_lonlat) for p in polygons]
        obstacles, frontiers = georeference.to_lonlat(obstacles), georeference.to_lonlat(frontiers)
        properties = {"frame": "WGS84", "units": "degrees",
                      "origin": {"lat": georeference.lat, "lon": georeference.lon, "heading": georeference.heading}}
    if precision is not None:
        polygons = [shapely.set_precision(p, 10.0 ** -precision) for p in polygons]

    def rounded(values: FloatArray) -> list[list[float]]:
        out = np.asarray(values, dtype=np.float64).reshape(-1, 2)
        return (np.round(out, precision) if precision is not None else out).tolist()

    return {
        "navigation": {"type": "FeatureCollection", "properties": {**properties, "kind": "navigation"},
                       "features": [{"type": "Feature", "properties": {"kind": "navigation"},
                                     "geometry": shapely.geometry.mapping(p)} for p in polygons]},
        "obstacles": {"type": "FeatureCollection", "properties": {**properties, "kind": "obstacle"},
                      "features": [{"type": "Feature", "properties": {"kind": "obstacle"},
                                    "geometry": {"type": "Point", "coordinates": xy}}
                                   for xy in rounded(obstacles)]},
        "frontiers": {"type": "FeatureCollection", "properties": {**properties, "kind": "frontier"},
                      "features": [{"type": "Feature", "properties": {"kind": "frontier"},
                                    "geometry": {"type": "Point", "coordinates": xy}}
                                   for xy in rounded(frontiers)]},
    }


#: The Nav2 map's modes (map_server's): three values, or the fused occupancy graded.
NAV2_MODES = ("trinary", "scale")


def output_paths(folder: str | os.PathLike[str], nav2_mode: str = "trinary") -> list[Path]:
    folder = Path(folder)
    image = "map.png" if nav2_mode == "scale" else "map.pgm"
    return [folder / name for name in ("world.occmap", "map.yaml", image, "map.mcap", "navigation.geojson",
                                       "obstacles.geojson", "frontiers.geojson", "summary.json")]


def write_run_map(run: RunMap, folder: str | os.PathLike[str], *, overwrite: bool = True,
                  simplify: float | None = None, precision: int | None = None, mcap: bool = True,
                  georeference: Any | None = None, extra_summary: dict[str, Any] | None = None,
                  nav2_mode: str = "trinary") -> list[Path]:
    """Write the world map (``world.occmap``), the Nav2 map, the Foxglove MCAP, the GeoJSON
    layers and ``summary.json`` into ``folder`` (created if missing). Every file is written
    completely or not at all, and everything is computed before the first file is written.

    ``nav2_mode``: ``"trinary"`` writes ``map.pgm`` (free / occupied / unknown), ``"scale"``
    ``map.png`` with the fused occupancy graded (needs Pillow)."""
    from occtool.formats.nav2 import _pillow, write_nav2, write_nav2_scale
    from occtool.formats.occmap import encode

    if nav2_mode not in NAV2_MODES:
        raise InputError(f"nav2_mode must be one of {', '.join(NAV2_MODES)}, got {nav2_mode!r}")
    if nav2_mode == "scale":
        _pillow("nav2_mode='scale' (a PNG map)")  # reported before any file is written
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder} exists and is not a folder")
    if not overwrite:
        for path in output_paths(folder, nav2_mode):
            if path.exists():
                raise FileExistsError(f"{path} exists already (pass overwrite=True to replace it)")
    layers = layer_collections(run, simplify=simplify, precision=precision, georeference=georeference)
    world_bytes = encode(run.world)
    summary = {**run.summary(), **(extra_summary or {})}
    summary["world_map"]["file_bytes"] = len(world_bytes)
    mcap_bytes = None
    if mcap:
        from occtool.formats.foxglove import run_map_mcap_bytes

        mcap_bytes = run_map_mcap_bytes(run)
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_write(folder / "world.occmap", "wb", overwrite=overwrite) as handle:
        handle.write(world_bytes)
    written = [folder / "world.occmap"]
    if nav2_mode == "scale":
        written += list(write_nav2_scale(run.raster.graded(), run.raster.resolution, run.raster.origin,
                                         folder / "map.yaml", overwrite=overwrite))
    else:
        written += list(write_nav2(run.raster.cells, run.raster.resolution, run.raster.origin, folder / "map.yaml",
                                  overwrite=overwrite))
    if mcap_bytes is not None:
        with atomic_write(folder / "map.mcap", "wb", overwrite=overwrite) as handle:
            handle.write(mcap_bytes)
        written.append(folder / "map.mcap")
    for name, collection in layers.items():
        with atomic_write(folder / f"{name}.geojson", "w", overwrite=overwrite) as handle:
            json.dump(collection, handle, separators=(",", ":"))
            handle.write("\n")
        written.append(folder / f"{name}.geojson")
    with atomic_write(folder / "summary.json", "w", overwrite=overwrite) as handle:
        json.dump(summary, handle, indent=1)
        handle.write("\n")
    written.append(folder / "summary.json")
    return written


__all__ = ["LAYERS", "NAV2_MODES", "PlacedMap", "RunMap", "layer_collections", "map_of_run", "output_paths",
           "write_run_map"]
