"""The memory a run of ``occtool map`` needs, estimated before the work starts (:func:`estimate_map_memory`),
and the refusal of a run over the user's limit (:func:`check_map_memory`).

What a run holds at its peak grows with two things a log says up front:

* its **positions** (scans): each one's features while it is fitted, its keyframe model,
  its returns per pan bin (:class:`occtool.fuse.RunReturns`), its navigation map and its
  share of the navigation region;
* the **raster** of its extent: the world map's Nav2 cells (a byte each, held whole or,
  in a lean run, kept in a file) and explored flags (an eighth), with the MCAP grid (at
  most 2**25 cells) and the strips' temporaries beside them at the peak (a ``scale``
  map's and a 3D map's raster hold their occupancy too). The world map's walls reach
  :data:`WALL_REACH` from each position, so the extent is the box of every position and
  of its features within that reach.

The figures are from runs on the project's 2-core machine (:data:`BASE_BYTES`, ...); the
estimate errs high, so a run it passes fits.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from occtool.errors import InputError
from occtool.limits import DEFAULT_MEMORY_LIMIT, memory_bytes

#: The process before any data: Python, numpy, scipy, shapely and occtool's modules (an
#: ``occtool map`` of a 10-scan log peaks near 100 MB).
BASE_BYTES = 100 * 10**6
#: Per position of the log: its model and returns while fused, its navigation map and its
#: share of the navigation region ...
POSITION_BYTES = 120 * 10**3
#: ... and per feature: its float64 point and evidence, and the copies a fit makes. With
#: :data:`RASTER_CELL_BYTES` these put the four CARMEN logs and the two largest at 1.1-1.6
#: times their measured peaks (Intel 226 MB for 153, FR-079 388 for 246, the Freiburg campus
#: 651 for 586, the MIT corridor 670 for 576).
FEATURE_BYTES = 60
#: Per cell of a 3D map's trinary raster at the peak: the cells (1 byte), occupancy (4), explored (1),
#: then the frontier labels (4) and flags or the MCAP grid's copies (int8 values, bytes, message).
RASTER_CELL_BYTES = 14
#: ... and of a ``scale`` raster, whose PNG is made from the graded occupancy (float32 and RGBA copies).
SCALE_CELL_BYTES = 28
#: Per cell of a 2D map's trinary raster, which keeps no occupancy (:func:`occtool.fuse.map_log`):
#: its cells and explored flags, held whole ...
TRINARY_CELL_BYTES = 2
#: ... or, kept in a file while the files are written (:func:`occtool.fuse.map_log`'s ``lean``,
#: over :data:`occtool.fuse._rasterise.SPILL_CELLS` cells), its explored flags (an eighth) and
#: the strips read back ...
SPILLED_CELL_BYTES = 1
#: ... per cell of its MCAP grid (at most :data:`occtool.formats.foxglove.MAX_GRID_CELLS`):
#: the int8 values, their bytes, the message and the MCAP's buffer ...
GRID_CELL_BYTES = 4
#: ... and the temporaries of the strips the raster is drawn, searched and written in: about
#: 200 bytes a cell of a strip, strips of up to 2**19 cells and a share for the others.
STRIP_CELL_BYTES = 200
STRIP_BYTES = 150 * 10**6
#: Per ray of a 3D world map's build (:func:`occtool.fuse.map_log_3d`): its origin, end and
#: direction, its samples' cell keys and the free cells' keys. Seosan's whole run, 1.22 M
#: rays (long outdoor rays: the most distinct cells crossed a ray of the shared data), built
#: its map in 524 MB over what reading it held (639 MB peak for the whole map; 1,025-1,302 MB
#: before the build kept one copy of the rays and the walk merged its counts as it went);
#: the TUM cabinet's frames four times over, 2.3 M rays, in 423 MB.
RAY_BYTES = 480


@dataclass(frozen=True)
class MemoryEstimate:
    """What :func:`estimate_map_memory` found: ``total`` bytes, and its parts by name."""

    total: int
    parts: dict[str, int] = field(default_factory=dict)
    #: The raster's rows and columns, as estimated from the positions and their features.
    raster_shape: tuple[int, int] = (0, 0)
    resolution: float = 0.05


def _gb(size: int) -> str:
    if size >= 10**8:
        return f"{size / 1e9:.1f} GB"
    return f"{size / 1e6:.0f} MB" if size >= 10**6 else "under 1 MB"


def raster_extent(log: Any, reach: float | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """World ``(x, y)`` lower and upper corners of the positions of ``log`` (a
    :class:`~occtool.features.RangeLog`) and their features within ``reach`` metres (a
    position without a pose in its own frame; default: the walls' reach,
    :data:`occtool.fuse._refit.WALL_REACH`); ``None`` when the log has no positions."""
    if reach is None:
        from occtool.fuse._refit import WALL_REACH

        reach = WALL_REACH
    lower = np.full(2, np.inf)
    upper = np.full(2, -np.inf)
    for position in log.positions:  # a loop over positions, each vectorised over its features
        points = position.features.points
        near = points[np.hypot(points[:, 0], points[:, 1]) <= reach, :2]
        pose = position.pose
        # A position without a pose is mapped in its own frame.
        xy = np.concatenate([near, [[0.0, 0.0]]]) if pose is None else \
            np.concatenate([pose.to_world(near), [[pose.x, pose.y]]])
        lower = np.minimum(lower, xy.min(axis=0))
        upper = np.maximum(upper, xy.max(axis=0))
    return (lower, upper) if np.isfinite(lower).all() else None


def estimate_map_memory(log: Any, *, resolution: float = 0.05, nav2_mode: str = "trinary",
                        world3d: bool = False, spill: bool = False) -> MemoryEstimate:
    """The peak memory ``occtool map`` needs for ``log`` (a :class:`~occtool.features.RangeLog`),
    in bytes, from its positions, its features and the raster of its extent at
    ``resolution`` metres (``nav2_mode`` ``"scale"`` costs more a cell), and with
    ``world3d`` the build of its 3D world map (:data:`RAY_BYTES` a feature); ``spill``: a
    large 2D trinary raster's cells wait in a file (:func:`occtool.fuse.map_log`'s ``lean``)."""
    if not resolution > 0:
        raise InputError(f"resolution must be a positive number of metres, got {resolution}")
    positions = len(log.positions)
    features = sum(len(position.features) for position in log.positions)
    extent = raster_extent(log)
    rows = columns = 0
    if extent is not None:
        # As WorldMap.rasterise places it: origin on the grid, one cell more each way.
        lower, upper = extent
        origin = np.floor(lower / resolution) * resolution
        columns, rows = (np.ceil((upper - origin) / resolution).astype(np.int64) + 1).tolist()
    from occtool.formats.foxglove import MAX_GRID_CELLS
    from occtool.fuse._rasterise import SPILL_CELLS

    cells = int(rows) * int(columns)
    if nav2_mode == "scale":
        raster = cells * SCALE_CELL_BYTES
    elif world3d:
        raster = cells * RASTER_CELL_BYTES
    else:
        held = SPILLED_CELL_BYTES if spill and cells > SPILL_CELLS else TRINARY_CELL_BYTES
        raster = (cells * held + min(cells, MAX_GRID_CELLS) * GRID_CELL_BYTES
                  + min(cells * STRIP_CELL_BYTES, STRIP_BYTES))
    parts = {"base": BASE_BYTES, "positions": positions * POSITION_BYTES + features * FEATURE_BYTES,
             "raster": raster}
    if world3d:
        parts["world3d"] = features * RAY_BYTES
    return MemoryEstimate(sum(parts.values()), parts, (int(rows), int(columns)), float(resolution))


def check_map_memory(log: Any, *, memory_limit: int | float | str | None = DEFAULT_MEMORY_LIMIT,
                     resolution: float = 0.05, nav2_mode: str = "trinary", world3d: bool = False,
                     spill: bool = False) -> MemoryEstimate:
    """:func:`estimate_map_memory`, refused with an :class:`InputError` naming
    ``memory_limit=`` (the command line's ``--memory-limit``) when the estimate is over
    ``memory_limit`` (bytes, or a size such as ``"8G"``; ``None``: no limit). Returns the estimate."""
    limit = memory_bytes(memory_limit)
    estimate = estimate_map_memory(log, resolution=resolution, nav2_mode=nav2_mode, world3d=world3d, spill=spill)
    if limit is not None and estimate.total > limit:
        rows, columns = estimate.raster_shape
        wanted = max(1, -(-estimate.total // 10**9))  # whole gigabytes, rounded up
        raise InputError(
            f"mapping {log.source or 'this log'} needs about {_gb(estimate.total)} of memory "
            f"({len(log.positions)} positions: {_gb(estimate.parts['positions'])}; a {rows} x {columns} raster "
            f"at {resolution:g} m: {_gb(estimate.parts['raster'])}"
            + (f"; the 3D map of {sum(len(p.features) for p in log.positions):,} rays: "
               f"{_gb(estimate.parts['world3d'])}" if "world3d" in estimate.parts else "")
            + f"), over the limit of {_gb(limit)}: "
            f"raise it with memory_limit='{wanted}G' or map at a coarser resolution=")
    return estimate


__all__ = ["MemoryEstimate", "check_map_memory", "estimate_map_memory", "raster_extent"]
