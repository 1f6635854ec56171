"""The :class:`OccupancyGrid`: a dense 3D array of log-odds, read by point and by ray."""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.grid._logodds import OCTOMAP_DEFAULTS, LogOddsParams, logit, probability
from occtool.grid._traverse import _SEGMENTS_PER_CHUNK, _chunks, traverse
from occtool.grid._unknown import band_layers, check_unknown, first_unobserved

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(eq=False)
class OccupancyGrid:
    """A dense 3D grid of occupancy log-odds in the sensor-centred robot frame.

    Parameters
    ----------
    log_odds
        ``(nx, ny, nz)`` float32 log-odds; 0 (probability 0.5) where nothing was observed.
    resolution
        Cell edge length, metres.
    offset
        Integer index of cell ``[0, 0, 0]`` in the global lattice whose boundaries lie on
        multiples of ``resolution``.
    samples
        Number of (ray, cell) samples fused into the grid.
    params
        The log-odds parameters used.
    footprint
        Radius of the robot footprint the prior set free, metres (0: no prior); with
        ``unknown="occupied"`` the robot's disk counts as observed (:func:`first_unobserved`).
    """

    log_odds: NDArray[np.float32]
    resolution: float
    offset: IntArray
    samples: int = 0
    params: LogOddsParams = OCTOMAP_DEFAULTS
    footprint: float = 0.0

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(v) for v in self.log_odds.shape)  # type: ignore[return-value]

    @property
    def nbytes(self) -> int:
        """Memory of the grid's arrays, bytes."""
        return int(self.log_odds.nbytes + self.offset.nbytes)

    @property
    def memory_bytes(self) -> int:
        """Memory of the grid, bytes: its :attr:`nbytes` (the name OctoMap's model uses)."""
        return self.nbytes

    def file_bytes(self) -> int:
        """Size of the grid on disk in its best case, bytes: the log-odds array (with offset
        and resolution) compressed by ``numpy.savez_compressed``."""
        fd, name = tempfile.mkstemp(suffix=".npz")
        os.close(fd)
        try:
            with open(name, "wb") as handle:
                np.savez_compressed(handle, log_odds=self.log_odds, offset=self.offset, resolution=self.resolution)
            return os.path.getsize(name)
        finally:
            os.unlink(name)

    @property
    def lower(self) -> FloatArray:
        """Lower corner of the grid, metres."""
        return (self.offset * self.resolution).astype(np.float64, copy=False)

    @property
    def upper(self) -> FloatArray:
        """Upper corner of the grid, metres."""
        return (self.offset + np.asarray(self.shape)) * self.resolution

    @property
    def observed_cells(self) -> int:
        """Number of cells that received at least one sample."""
        return int(np.count_nonzero(self.log_odds))

    def observed_columns(self, band: tuple[float, float] | None = None) -> NDArray[np.bool_]:
        """Which columns of the grid hold an observed cell between a band's heights.

        A cell is observed when it received a sample (or the footprint prior): its
        log-odds are not 0, as :attr:`observed_cells` counts them.

        Parameters
        ----------
        band
            ``(low, high)`` sensor-frame heights, metres; the layers whose cells overlap it
            count (:func:`band_layers`). Default: every layer of the grid.

        Returns
        -------
        numpy.ndarray
            ``(nx, ny)`` booleans, indexed as the grid's first two axes.
        """
        if band is None:
            layers = self.log_odds
        else:
            k_lo, k_hi = band_layers(band, self.resolution)
            lo = min(max(k_lo - int(self.offset[2]), 0), self.shape[2])
            hi = min(max(k_hi - int(self.offset[2]) + 1, 0), self.shape[2])
            layers = self.log_odds[:, :, lo:hi]
        return (layers != 0).any(axis=2)

    def cell_of(self, points: ArrayLike) -> tuple[IntArray, NDArray[np.bool_]]:
        """Array indices of the cells holding ``(N, 3)`` points, and which lie in the grid."""
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        index = np.floor(pts / self.resolution).astype(np.int64) - self.offset
        inside: NDArray[np.bool_] = np.all((index >= 0) & (index < np.asarray(self.shape)), axis=1)
        return index, inside

    def occupancy(self, points: ArrayLike) -> FloatArray:
        """Occupancy probability at ``(N, 3)`` points; 0.5 (unknown) outside the grid."""
        index, inside = self.cell_of(points)
        out = np.full(index.shape[0], 0.5)
        i = index[inside]
        out[inside] = probability(self.log_odds[i[:, 0], i[:, 1], i[:, 2]])
        return out

    def occupied(self, level: float | None = None) -> NDArray[np.bool_]:
        """Boolean grid of the cells whose occupancy reaches ``level`` (OctoMap's 0.5 if None)."""
        level = self.params.occupancy_thres if level is None else level
        return self.log_odds >= np.float32(logit(level))

    def inverse_range(
        self,
        alpha: ArrayLike,
        h: ArrayLike,
        level: float,
        max_range: float | None = None,
        *,
        unknown: str = "free",
        band: tuple[float, float] | None = None,
    ) -> FloatArray:
        """Distance from the sensor to the first cell at or above ``level`` along horizontal rays.

        The ray at pan angle ``alpha`` and sensor-frame height ``h`` runs from ``(0, 0, h)``
        outwards; the returned value is the 3D distance ``r`` from the sensor to the point
        where it enters the first cell whose occupancy is ``>= level``, so that
        ``sqrt(r**2 - h**2)`` is the free horizontal distance, as for the parametric model.
        Outside the grid the occupancy is unknown (0.5). A ray that meets no such cell
        within ``max_range`` (horizontal; by default the farthest grid corner) returns
        ``inf``.

        Parameters
        ----------
        alpha, h
            Pan angles (radians) and heights (metres), broadcast together.
        level
            Occupancy level in (0, 1).
        max_range
            Horizontal distance to search up to, metres.
        unknown
            ``"free"``: unobserved cells are read at their prior 0.5, as above.
            ``"occupied"``: the ray also ends where it enters a column with no observed
            cell between the ``band``'s heights (:meth:`observed_columns`; outside the
            grid nothing is observed), at every height ``h``. The robot's footprint
            (:attr:`footprint`) counts as observed: it stands there.
        band
            ``(low, high)`` sensor-frame heights whose cells make a column observed, with
            ``unknown="occupied"``; default every layer of the grid.

        Returns
        -------
        numpy.ndarray
            ``r`` with the broadcast shape of ``alpha`` and ``h``.
        """
        alpha_b, h_b = np.broadcast_arrays(np.asarray(alpha, dtype=np.float64), np.asarray(h, dtype=np.float64))
        shape = alpha_b.shape
        a = alpha_b.reshape(-1)
        hh = h_b.reshape(-1)
        if max_range is None:
            corners = np.abs(np.stack([self.lower[:2], self.upper[:2]]))
            max_range = float(np.hypot(corners[:, 0].max(), corners[:, 1].max())) + self.resolution
        if not (np.isfinite(max_range) and max_range > 0):
            raise InputError(f"max range must be a finite number > 0, got {max_range}")
        check_unknown(unknown)
        blocked_beyond = level <= 0.5
        threshold = np.float32(logit(level))
        # Every horizontal ray at one pan angle crosses the same columns whatever its
        # height: traverse each angle once in the plane and read the column at each height.
        angles, angle_of = np.unique(a, return_inverse=True)
        heights, height_of = np.unique(hh, return_inverse=True)
        layer = np.floor(heights / self.resolution).astype(np.int64) - self.offset[2]
        layer_inside = (layer >= 0) & (layer < self.shape[2])
        layer_index = np.clip(layer, 0, self.shape[2] - 1)
        columns = np.asarray(self.shape[:2])
        distance = np.full((angles.shape[0], heights.shape[0]), np.inf)
        # A horizontal ray crosses at most two cell boundaries per cell length.
        cells_per_ray = 2 * int(max_range / self.resolution) + 2
        per_chunk = max(1, _SEGMENTS_PER_CHUNK // (cells_per_ray * max(1, heights.shape[0])))
        for lo, hi in _chunks(angles.shape[0], per_chunk):
            ends = np.column_stack(
                [max_range * np.cos(angles[lo:hi]), max_range * np.sin(angles[lo:hi]), np.zeros(hi - lo)]
            )
            seg = traverse(np.zeros(3), ends, self.resolution)
            ij = seg.cell[:, :2] - self.offset[:2]
            column_inside: NDArray[np.bool_] = np.all((ij >= 0) & (ij < columns), axis=1)
            ij = np.clip(ij, 0, columns - 1)
            values = self.log_odds[ij[:, 0, None], ij[:, 1, None], layer_index[None, :]]
            hit = np.where(column_inside[:, None] & layer_inside[None, :], values >= threshold, blocked_beyond)
            entry = np.where(hit, seg.t_enter[:, None], np.inf)
            # Segments come in ray order: the earliest hit of each ray is a minimum over its run.
            starts = np.flatnonzero(np.r_[True, seg.ray[1:] != seg.ray[:-1]])
            distance[lo + seg.ray[starts]] = np.minimum.reduceat(entry, starts, axis=0) * max_range
        if unknown == "occupied":
            unseen = first_unobserved(
                self.observed_columns(band), self.offset[:2], angles, max_range, self.resolution, self.footprint
            )
            distance = np.minimum(distance, unseen[:, None])
        horizontal = distance[angle_of, height_of]
        return np.sqrt(horizontal**2 + hh**2).reshape(shape)
