"""Unobserved space: its readings, the observed height band, the first unobserved column."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.grid._traverse import _SEGMENTS_PER_CHUNK, _chunks, traverse

FloatArray = NDArray[np.float64]

#: The readings of unobserved space ``inverse_range`` offers (see the package docstring).
UNKNOWN_SPACE = ("free", "occupied")


def check_unknown(unknown: str) -> str:
    """``unknown`` if it is one of :data:`UNKNOWN_SPACE`; an :class:`InputError` otherwise."""
    if unknown not in UNKNOWN_SPACE:
        raise InputError(f"unobserved space must be read as 'free' or 'occupied', got {unknown!r}")
    return unknown


def footprint_columns_reached(columns: ArrayLike, radius: float, resolution: float) -> NDArray[np.bool_]:
    """Which ``(N, 2)`` global column indices come within half a cell of the disk of ``radius``
    around the sensor axis (their nearest point lies closer than ``radius + resolution / 2``)."""
    ij = np.asarray(columns, dtype=np.int64)
    # Nearest point of cell [i, i + 1) * resolution to 0, per axis.
    nearest = np.maximum(np.maximum(ij * resolution, -(ij + 1) * resolution), 0.0)
    return np.hypot(nearest[:, 0], nearest[:, 1]) < radius + 0.5 * resolution


def band_layers(band: tuple[float, float], resolution: float) -> tuple[int, int]:
    """First and last global lattice layer (z index) of the cells a height band touches.

    ``band`` is ``(low, high)`` in sensor-frame metres; the layers are those whose cells
    overlap it, ``floor(low / resolution)`` to ``floor(high / resolution)``, as for the
    footprint prior.
    """
    low, high = (float(v) for v in band)
    if not (np.isfinite(low) and np.isfinite(high) and low <= high):
        raise InputError(f"the observation band must be two finite heights, low <= high, got {band}")
    return int(np.floor(low / resolution)), int(np.floor(high / resolution))


def first_unobserved(
    observed: NDArray[np.bool_],
    offset: ArrayLike,
    angles: ArrayLike,
    max_range: float,
    resolution: float,
    footprint: float = 0.0,
) -> FloatArray:
    """Horizontal distance along rays from the sensor axis to the first unobserved column.

    Parameters
    ----------
    observed
        ``(nx, ny)`` boolean mask of the observed columns; columns outside it are unobserved.
    offset
        Global lattice index ``(i, j)`` of ``observed[0, 0]``.
    angles
        Pan angles of the rays, radians.
    max_range
        Length of the rays, metres.
    resolution
        Cell edge, metres.
    footprint
        Radius of the robot's footprint, metres (0: none). The robot stands on it, so
        every column that comes within half a cell of its disk counts as observed
        (:func:`footprint_columns_reached`): the cells the prior sets free only
        approximate the disk, and those it clips must not put the robot in collision.

    Returns
    -------
    numpy.ndarray
        The distance where each ray enters its first unobserved column (the same 2D walk
        as :meth:`OccupancyGrid.inverse_range`), ``inf`` if there is none within ``max_range``.
    """
    angles = np.asarray(angles, dtype=np.float64).reshape(-1)
    offset = np.asarray(offset, dtype=np.int64).reshape(-1)[:2]
    columns = np.asarray(observed.shape[:2])
    distance = np.full(angles.shape[0], np.inf)
    cells_per_ray = 2 * int(max_range / resolution) + 2
    for lo, hi in _chunks(angles.shape[0], max(1, _SEGMENTS_PER_CHUNK // cells_per_ray)):
        ends = np.column_stack(
            [max_range * np.cos(angles[lo:hi]), max_range * np.sin(angles[lo:hi]), np.zeros(hi - lo)]
        )
        seg = traverse(np.zeros(3), ends, resolution)
        ij = seg.cell[:, :2] - offset
        inside = ((ij >= 0) & (ij < columns)).all(axis=1)
        ij = np.clip(ij, 0, columns - 1)
        unseen = ~(inside & observed[ij[:, 0], ij[:, 1]])
        if footprint > 0:
            unseen &= ~footprint_columns_reached(seg.cell[:, :2], footprint, resolution)
        entry = np.where(unseen, seg.t_enter, np.inf)
        starts = np.flatnonzero(np.r_[True, seg.ray[1:] != seg.ray[:-1]])
        distance[lo + seg.ray[starts]] = np.minimum.reduceat(entry, starts) * max_range
    return distance
