"""The picture of a run's map (``occtool plot map``): the fused raster, the path, frontiers, walls.

Reads a folder written by ``occtool map`` (``map.yaml`` by map_server's rules,
``summary.json`` for the path, ``frontiers.geojson``, ``world.occmap`` for the walls);
drawing needs the ``plot`` extra. Every file is checked before it is used (sizes, finite
coordinates in range), and a refusal is one :class:`~occtool.errors.InputError` line naming
the file.

A map can hold far more cells than the picture has pixels (the MIT corridor's: ~100 M).
The raster is read reduced to the axes' pixel count (a PGM a strip of rows at a time), keeping
each block's darkest cell, so a one-cell wall stays black and memory stays that of the
picture, not of the map.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool._json import read_json
from occtool.errors import InputError
from occtool.limits import DEFAULT_MEMORY_LIMIT
from occtool.plot._canvas import new_figure

DEFAULT_MAP_SIZE = (8.0, 8.0)
#: Largest summary.json or frontiers.geojson read: the JSON parser needs several times the
#: text's size, and a run's path of a million positions is ~30 MB.
MAX_SIDECAR_BYTES = 128 * 1024 * 1024
#: Share of the figure the map's axes cover at least (matplotlib's default subplot box is
#: 0.775 x 0.77; the constrained layout gives more), for the pixels the raster is reduced to.
_AXES_SHARE = 0.75


def _sidecar(path: Path) -> Any:
    """The JSON document in one of the folder's files, its size bounded."""
    size = path.stat().st_size
    if size > MAX_SIDECAR_BYTES:
        raise InputError(f"{path}: {size:,} bytes, over the {MAX_SIDECAR_BYTES:,} read from a map folder's JSON")
    return read_json(path, error=InputError)


def _points(values: Any, path: Path, what: str) -> NDArray[np.float64]:
    """``values`` as ``(N, 2)`` finite floats within the map's coordinate range, else one line naming ``path``."""
    from occtool.formats.nav2 import MAX_MAP_COORDINATE

    # Checked value by value: numpy would read "1" or true as numbers, and a ragged list as objects.
    ok = isinstance(values, list) and all(
        isinstance(point, list) and len(point) == 2
        and all(type(v) in (int, float) and math.isfinite(v) and abs(v) <= MAX_MAP_COORDINATE for v in point)
        for point in values)
    if not ok:
        raise InputError(f"{path}: {what} must be [x, y] pairs of finite numbers within {MAX_MAP_COORDINATE:g} m "
                         f"(as `occtool map` writes it)")
    return np.array(values, dtype=np.float64).reshape(-1, 2)


def _frontier_coordinates(document: Any, path: Path) -> Any:
    """The frontier points of a map-frame collection; ``[]`` for one in another frame."""
    if not isinstance(document, dict) or not isinstance(document.get("features"), list):
        raise InputError(f"{path}: not a GeoJSON FeatureCollection (as `occtool map` writes it)")
    properties = document.get("properties")
    if not isinstance(properties, dict) or properties.get("frame") != "map":
        return []  # longitude/latitude frontiers (--origin) are not drawn over metric cells
    geometries = [feature.get("geometry") if isinstance(feature, dict) else None for feature in document["features"]]
    if not all(isinstance(g, dict) and g.get("type") == "Point" for g in geometries):
        raise InputError(f"{path}: every frontier must be a GeoJSON Point feature")
    return [g.get("coordinates") for g in geometries]  # type: ignore[union-attr]


def _map_yaml(folder: Path) -> Path:
    if not (folder / "map.yaml").is_file():
        raise InputError(f"{folder}: no map.yaml (write the folder with `occtool map LOG -o {folder}/`)")
    return folder / "map.yaml"


def read_map_folder(folder: str | Path, *, decimate: int = 1,
                    memory_limit: int | float | str | None = DEFAULT_MEMORY_LIMIT) -> tuple[Any, list[list[float]],
                                                                                           np.ndarray]:
    """The Nav2 map (read ``decimate`` times coarser, within ``memory_limit``:
    :func:`occtool.formats.nav2.read_nav2`), the path and the frontier points of an
    ``occtool map`` folder."""
    from occtool.formats.nav2 import read_nav2

    folder = Path(folder)
    nav2 = read_nav2(_map_yaml(folder), decimate=decimate, memory_limit=memory_limit)
    path: list[list[float]] = []
    frontiers = np.zeros((0, 2))
    summary_path, frontiers_path = folder / "summary.json", folder / "frontiers.geojson"
    if summary_path.is_file():
        summary = _sidecar(summary_path)
        if not isinstance(summary, dict):
            raise InputError(f"{summary_path}: not a JSON object (as `occtool map` writes it)")
        if summary.get("path") is not None:
            path = _points(summary["path"], summary_path, "path").tolist()
    if frontiers_path.is_file():
        frontiers = _points(_frontier_coordinates(_sidecar(frontiers_path), frontiers_path), frontiers_path,
                            "each frontier's coordinates")
    return nav2, path, frontiers


def decimate(cells: NDArray[np.int8], factor: int) -> NDArray[np.int8]:
    """Each ``factor`` x ``factor`` block of ``cells`` as its largest value: the one home of
    that rule is :func:`occtool.formats.nav2.decimate_cells` (:func:`map_figure` reads a
    map so reduced)."""
    from occtool.formats.nav2 import decimate_cells

    return decimate_cells(cells, factor)


#: A wall's colour is ``(1, 1 - trust, 1 - trust) * _WALL_SHADE``: dark red at trust 1,
#: pale red at 0, linear between (so a two-colour map is its exact key).
_WALL_SHADE = np.array([0.85, 0.6, 0.6, 1.0])


def _patch_traces(world: Any) -> tuple[list[Any], Any]:
    """A 3D map's upright patches (walls, furniture sides: a normal within 60 degrees of
    horizontal) as their horizontal traces, centre plus and minus their half-width along
    the level direction in their plane, and their trusts."""
    g = world.geometry
    upright = np.abs(g.normals[:, 2]) < 0.5
    normals = g.normals[upright]
    level = np.column_stack([-normals[:, 1], normals[:, 0], np.zeros(len(normals))])
    level /= np.maximum(np.linalg.norm(level, axis=1, keepdims=True), 1e-12)
    half = (np.abs(np.sum(g.u[upright] * level, axis=1)) * g.extents[upright, 0]
            + np.abs(np.sum(g.v[upright] * level, axis=1)) * g.extents[upright, 1])
    centres = g.centres[upright, :2]
    offset = level[:, :2] * half[:, None]
    return list(np.stack([centres - offset, centres + offset], axis=1)), g.trust[upright]


def _trust_key(figure: Any, axes: Any) -> None:
    """The colour bar naming what a wall's colour means: its trust, 0 to 1."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LinearSegmentedColormap, Normalize

    colours = np.array([[1.0, 1.0, 1.0, 1.0], [1.0, 0.0, 0.0, 1.0]]) * _WALL_SHADE
    scale = ScalarMappable(Normalize(0.0, 1.0), LinearSegmentedColormap.from_list("wall trust", colours))
    bar = figure.colorbar(scale, ax=axes, fraction=0.04, pad=0.02)
    bar.set_label("wall trust (0-1): share of the positions that saw the wall\nthat returned from it "
                  "(low: mostly seen through)", fontsize="small")
    bar.ax.tick_params(labelsize="small")


def map_figure(folder: str | Path, *, size: tuple[float, float] = DEFAULT_MAP_SIZE, dpi: float = 100.0,
               title: str | None = None, path: bool = True, frontiers: bool = True, walls: bool = False,
               memory_limit: int | float | str | None = DEFAULT_MEMORY_LIMIT) -> Any:
    """Free (white), occupied (black) and unknown (grey; pale blue in a scale map, whose graded
    cells are greys) cells in the map frame, the run's
    path (blue), the frontier points (green) and (``walls``) the world map's wall
    segments, from ``world.occmap``, red where every position that saw them returned from
    them and paler as more saw through them, with a colour bar of that trust (0-1).

    A map with more cells than the axes have pixels is read and drawn block by block, each
    block its darkest cell (:func:`decimate`), so memory is that of the picture, not of the
    map (a PNG map is decoded whole: ``memory_limit``, :func:`occtool.formats.nav2.read_nav2`)."""
    from occtool.formats.nav2 import CELL_UNKNOWN, nav2_shape

    rows, cols = nav2_shape(_map_yaml(Path(folder)))
    # At equal aspect the axes show the map at the smaller of the two pixels-per-cell ratios.
    width_px, height_px = size[0] * dpi * _AXES_SHARE, size[1] * dpi * _AXES_SHARE
    factor = max(1, math.ceil(max(cols / width_px, rows / height_px)))
    nav2, run_path, frontier_points = read_map_folder(folder, decimate=factor, memory_limit=memory_limit)
    cells = nav2.cells
    figure = new_figure(size, dpi)
    axes = figure.add_subplot(1, 1, 1)
    # Grey from white (free, 0) to black (occupied, 100); a scale map's graded cells between.
    # Unknown: mid grey in a trinary map, pale blue in a scale map, whose greys are taken.
    grey = 1.0 - np.clip(cells, 0, 100).astype(np.float32) / 100.0
    rgb = np.repeat(grey[:, :, None], 3, axis=2)
    rgb[cells == CELL_UNKNOWN] = (0.75, 0.75, 0.75) if nav2.mode != "scale" else (0.78, 0.85, 0.93)
    x0, y0 = nav2.origin[0], nav2.origin[1]
    # Padded edge blocks reach past the map by less than one block: less than a pixel.
    extent = (x0, x0 + cells.shape[1] * factor * nav2.resolution, y0, y0 + cells.shape[0] * factor * nav2.resolution)
    axes.imshow(rgb, origin="lower", extent=extent, interpolation="nearest")
    if path and run_path:
        xy = np.asarray(run_path, dtype=np.float64).reshape(-1, 2)
        axes.plot(xy[:, 0], xy[:, 1], color="tab:blue", linewidth=0.8, label="path")
    if walls:
        from matplotlib.collections import LineCollection

        from occtool.fuse import WorldMap, load_map

        if not (Path(folder) / "world.occmap").is_file():
            raise InputError(f"{folder}: no world.occmap to draw walls from (written by `occtool map`)")
        world = load_map(Path(folder) / "world.occmap")
        if isinstance(world, WorldMap):
            lines, trust = list(np.stack([world.start, world.end], axis=1)), world.trust
        else:
            lines, trust = _patch_traces(world)
        colours = np.column_stack([np.ones(len(trust)), 1.0 - trust, 1.0 - trust, np.ones(len(trust))])
        axes.add_collection(LineCollection(lines, colors=colours * _WALL_SHADE, linewidths=0.6,
                                           label="walls (world.occmap)"))
        _trust_key(figure, axes)
    if frontiers and len(frontier_points):
        axes.scatter(frontier_points[:, 0], frontier_points[:, 1], s=6, color="tab:green", label="frontiers")
    axes.set_aspect("equal")
    axes.set_xlabel("x (m, map)")
    axes.set_ylabel("y (m, map)")
    axes.set_title(title if title is not None else
                   f"{Path(folder).name}: free / occupied / unknown at {nav2.resolution:g} m"
                   + (", graded (scale)" if nav2.mode == "scale" else ""))
    if axes.get_legend_handles_labels()[0]:
        axes.legend(loc="upper right", fontsize="small")
    return figure


__all__ = ["decimate", "map_figure", "read_map_folder"]
