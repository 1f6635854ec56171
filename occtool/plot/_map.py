"""The picture of a run's map (``occtool plot map``): the fused raster, the path, frontiers, walls.

Reads a folder written by ``occtool map`` (``map.yaml`` by map_server's rules,
``summary.json`` for the path, ``frontiers.geojson``, ``world.occmap`` for the walls);
drawing needs the ``plot`` extra.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from occtool.errors import InputError
from occtool.plot._canvas import new_figure

DEFAULT_MAP_SIZE = (8.0, 8.0)


def read_map_folder(folder: str | Path) -> tuple[Any, list[list[float]], np.ndarray]:
    """The Nav2 map, the path and the frontier points of an ``occtool map`` folder."""
    from occtool.formats.nav2 import read_nav2

    folder = Path(folder)
    if not (folder / "map.yaml").is_file():
        raise InputError(f"{folder}: no map.yaml (write the folder with `occtool map LOG -o {folder}/`)")
    nav2 = read_nav2(folder / "map.yaml")
    path: list[list[float]] = []
    frontiers = np.zeros((0, 2))
    try:
        if (folder / "summary.json").is_file():
            path = json.loads((folder / "summary.json").read_text(encoding="utf-8")).get("path") or []
        if (folder / "frontiers.geojson").is_file():
            data = json.loads((folder / "frontiers.geojson").read_text(encoding="utf-8"))
            if data.get("properties", {}).get("frame") == "map":
                frontiers = np.array([f["geometry"]["coordinates"] for f in data["features"]],
                                     dtype=np.float64).reshape(-1, 2)
    except (json.JSONDecodeError, KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"{folder}: malformed summary.json or frontiers.geojson ({exc})") from None
    return nav2, path, frontiers


def map_figure(folder: str | Path, *, size: tuple[float, float] = DEFAULT_MAP_SIZE, dpi: float = 100.0,
               title: str | None = None, path: bool = True, frontiers: bool = True, walls: bool = False) -> Any:
    """Free (white), occupied (black) and unknown (grey; pale blue in a scale map, whose graded
    cells are greys) cells in the map frame, the run's
    path (blue), the frontier points (green) and (``walls``) the world map's wall
    segments, from ``world.occmap``, red where every position that saw them returned from
    them and paler as more saw through them."""
    from occtool.formats.nav2 import CELL_UNKNOWN

    nav2, run_path, frontier_points = read_map_folder(folder)
    figure = new_figure(size, dpi)
    axes = figure.add_subplot(1, 1, 1)
    rows, cols = nav2.cells.shape
    # Grey from white (free, 0) to black (occupied, 100); a scale map's graded cells between.
    # Unknown: mid grey in a trinary map, pale blue in a scale map, whose greys are taken.
    grey = 1.0 - np.clip(nav2.cells, 0, 100).astype(np.float32) / 100.0
    rgb = np.repeat(grey[:, :, None], 3, axis=2)
    rgb[nav2.cells == CELL_UNKNOWN] = (0.75, 0.75, 0.75) if nav2.mode != "scale" else (0.78, 0.85, 0.93)
    x0, y0 = nav2.origin[0], nav2.origin[1]
    extent = (x0, x0 + cols * nav2.resolution, y0, y0 + rows * nav2.resolution)
    axes.imshow(rgb, origin="lower", extent=extent, interpolation="nearest")
    if path and run_path:
        xy = np.asarray(run_path, dtype=np.float64).reshape(-1, 2)
        axes.plot(xy[:, 0], xy[:, 1], color="tab:blue", linewidth=0.8, label="path")
    if walls:
        from matplotlib.collections import LineCollection

        from occtool.fuse import load_map

        if not (Path(folder) / "world.occmap").is_file():
            raise InputError(f"{folder}: no world.occmap to draw walls from (written by `occtool map`)")
        world = load_map(Path(folder) / "world.occmap")
        lines = list(np.stack([world.start, world.end], axis=1))
        colours = np.column_stack([np.ones(len(world)), 1.0 - world.trust, 1.0 - world.trust, np.ones(len(world))])
        axes.add_collection(LineCollection(lines, colors=colours * [0.85, 0.6, 0.6, 1.0], linewidths=0.6,
                                           label="walls (world.occmap)"))
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


__all__ = ["map_figure", "read_map_folder"]
