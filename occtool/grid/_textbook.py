"""The textbook 2D log-odds grid: :func:`textbook_grid` from world-frame beams.

The occupancy grid as the textbook builds it (Thrun, Burgard and Fox, *Probabilistic
Robotics*, table 9.1 and the inverse range-sensor model of table 9.2, simplified to a
point beam): every scan updates each cell of its perceptual field **once**, the cell
holding a beam's return with ``l_occ``, the cells the beam traverses before it with
``l_free`` (a cell that is the return of one beam and traversed by another of the same
scan is the return's: occupied wins, as OctoMap's scan insertion decides too), and the
cell's log-odds is clamped to ``clamp`` after every scan. A beam without a return (a free
ray) only frees its cells. Cells no beam reached keep log-odds 0: probability 0.5.

Scans are applied in their order, each one vectorised over its cells; the traversal is
that of :func:`occtool.grid.traverse` (all beams of a chunk at once). The per-scan cell
updates depend on the resolution only, so :class:`ScanUpdates` keeps them and
:meth:`ScanUpdates.grid` applies any ``l_occ``, ``l_free`` and clamp to them: the tuner
(:mod:`occtool.scoring`'s tuners) traverses once per resolution.

Two switches exist to measure how the repository's older grid
(:func:`occtool.scoring.world_grid`, OctoMap's parameters) differs: ``per_scan=False``
updates a cell once per *beam* (a cell crossed by twenty beams of a scan gets twenty
misses) and ``clamp_every_scan=False`` clamps once at the end, after summing everything.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.grid._traverse import traverse

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Beams traversed per chunk (bounds the temporary segment arrays).
BEAMS_PER_CHUNK = 20_000
#: A grid larger than this many cells is refused (a bounding box of a bad pose, say).
MAX_TEXTBOOK_CELLS = 200_000_000


@dataclass(frozen=True)
class TextbookParams:
    """Settings of the textbook inverse sensor model.

    Parameters
    ----------
    resolution
        Cell edge, metres.
    l_occ
        Log-odds added to the cell holding a return (> 0).
    l_free
        Log-odds added to a cell a beam traverses (< 0).
    clamp
        ``(low, high)`` log-odds bounds, ``low < 0 < high``.
    """

    resolution: float = 0.05
    l_occ: float = 0.85
    l_free: float = -0.4
    clamp: tuple[float, float] = (-2.0, 3.5)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.resolution) and self.resolution > 0):
            raise InputError(f"the grid's resolution must be a positive number of metres, got {self.resolution}")
        if not (np.isfinite(self.l_occ) and self.l_occ > 0):
            raise InputError(f"l_occ must be a positive log-odds, got {self.l_occ}")
        if not (np.isfinite(self.l_free) and self.l_free < 0):
            raise InputError(f"l_free must be a negative log-odds, got {self.l_free}")
        low, high = self.clamp
        if not (np.isfinite(low) and np.isfinite(high) and low < 0 < high):
            raise InputError(f"the clamp must be (low, high) with low < 0 < high, got {self.clamp}")

    def as_dict(self) -> dict[str, float | list[float]]:
        return {"resolution": self.resolution, "l_occ": self.l_occ, "l_free": self.l_free,
                "clamp": [float(self.clamp[0]), float(self.clamp[1])]}


#: The inverse sensor model of issue 20: l_occ +0.85, l_free -0.4, clamped to [-2, 3.5].
TEXTBOOK_DEFAULTS = TextbookParams()


@dataclass(frozen=True)
class WorldBeams:
    """Beams of scans in the world plane, in scan order.

    Parameters
    ----------
    start, end
        ``(N, 2)`` world x, y of each beam's sensor and end point, metres.
    hit
        ``(N,)`` whether the beam returned (its end is an obstacle) or is a free ray.
    scan
        ``(N,)`` the scan each beam belongs to, ``0 .. n_scans - 1``, non-decreasing.
    """

    start: FloatArray
    end: FloatArray
    hit: NDArray[np.bool_]
    scan: NDArray[np.intp]

    def __post_init__(self) -> None:
        n = self.hit.shape[0]
        if self.start.shape != (n, 2) or self.end.shape != (n, 2) or self.scan.shape != (n,):
            raise InputError("beams need (N, 2) starts and ends and (N,) hit flags and scan numbers")
        if n and (np.any(np.diff(self.scan) < 0) or self.scan[0] < 0):
            raise InputError("beams must come in scan order (non-decreasing scan numbers from 0)")
        if not (np.isfinite(self.start).all() and np.isfinite(self.end).all()):
            raise InputError("beams must have finite start and end points")

    @property
    def n_scans(self) -> int:
        return int(self.scan[-1]) + 1 if self.scan.size else 0

    def of_scans(self, keep: NDArray[np.bool_]) -> WorldBeams:
        """The beams of the scans ``keep`` marks (``(n_scans,)`` booleans), renumbered from 0."""
        keep = np.asarray(keep, dtype=bool)
        if keep.shape != (self.n_scans,):
            raise InputError(f"scan selection has {keep.shape[0]} flags for {self.n_scans} scans")
        rows = keep[self.scan]
        renumber = np.cumsum(keep) - 1
        return WorldBeams(self.start[rows], self.end[rows], self.hit[rows], renumber[self.scan[rows]].astype(np.intp))

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Lower and upper corner of the box holding every start and end, metres."""
        if not self.hit.size:
            raise InputError("no beams to build a grid from")
        both = np.concatenate([self.start, self.end])
        return both.min(axis=0), both.max(axis=0)


@dataclass(eq=False)
class TextbookGrid:
    """A 2D grid of log-odds: cell ``[i, j]`` spans ``[(lower + (i, j)) * resolution, + resolution)``.

    Parameters
    ----------
    log_odds
        ``(nx, ny)`` float32 log-odds, 0 where no beam reached.
    lower
        Integer index of cell ``[0, 0]`` on the lattice of multiples of ``params.resolution``.
    params
        The settings it was built with.
    """

    log_odds: NDArray[np.float32]
    lower: IntArray
    params: TextbookParams

    @property
    def resolution(self) -> float:
        return self.params.resolution

    @property
    def cells(self) -> int:
        return int(self.log_odds.size)

    @property
    def byte_size(self) -> int:
        """The grid at one byte a cell (its bounding box), bytes."""
        return self.cells

    def occupancy(self, points: ArrayLike) -> FloatArray:
        """Occupancy probability at ``(K, 2)`` or ``(K, 3)`` world points (z ignored); 0.5 outside."""
        values, inside = cell_values(points, self.lower, self.resolution, self.log_odds)
        out = np.full(inside.shape[0], 0.5)
        out[inside] = 1.0 / (1.0 + np.exp(-values.astype(np.float64)))
        return out


def cell_values(points: ArrayLike, lower: IntArray, resolution: float,
                grid: NDArray[np.floating]) -> tuple[NDArray[np.floating], NDArray[np.bool_]]:
    """The cells of ``grid`` (cell ``[0, 0]`` at lattice index ``lower``) holding ``(K, 2)`` or
    ``(K, 3)`` world points (z ignored): their values, and which points fall inside (finite)."""
    xy = np.atleast_2d(np.asarray(points, dtype=np.float64))[:, :2]
    finite = np.asarray(np.isfinite(xy).all(axis=1), dtype=bool)
    index = np.floor(np.where(finite.reshape(-1, 1), xy, 0.0) / resolution).astype(np.int64) - lower
    inside = np.all((index >= 0) & (index < np.array(grid.shape)), axis=1) & finite
    i = index[inside]
    return grid[i[:, 0], i[:, 1]], inside


@dataclass(eq=False)
class ScanUpdates:
    """Each scan's distinct cells with how many of its beams end (``hits``) and pass (``misses``) there.

    ``key`` is the flat cell index ``i * ny + j`` of the grid ``shape`` at ``lower``, sorted by
    scan and then by cell; ``first[s]:first[s + 1]`` are scan ``s``'s rows.
    """

    resolution: float
    lower: IntArray
    shape: tuple[int, int]
    key: IntArray
    hits: NDArray[np.int32]
    misses: NDArray[np.int32]
    first: IntArray

    @classmethod
    def from_beams(cls, beams: WorldBeams, resolution: float,
                   bounds: tuple[FloatArray, FloatArray] | None = None) -> ScanUpdates:
        """Traverse ``beams`` at ``resolution`` over ``bounds`` (default: the beams' own box)."""
        if not (np.isfinite(resolution) and resolution > 0):
            raise InputError(f"the grid's resolution must be a positive number of metres, got {resolution}")
        low, high = beams.bounds() if bounds is None else bounds
        lower = np.floor(np.asarray(low) / resolution).astype(np.int64)
        upper = np.floor(np.asarray(high) / resolution).astype(np.int64)
        nx, ny = (int(v) for v in upper - lower + 1)
        if nx * ny > MAX_TEXTBOOK_CELLS:
            raise InputError(f"a {resolution:g} m grid of {nx}x{ny} cells is larger than "
                             f"{MAX_TEXTBOOK_CELLS:,} cells: check the poses")
        n_cells = nx * ny
        keys, hits, misses = [], [], []
        z = 0.5 * resolution
        for lo in range(0, beams.hit.size, BEAMS_PER_CHUNK):
            hi = min(beams.hit.size, lo + BEAMS_PER_CHUNK)
            count = hi - lo
            seg = traverse(np.column_stack([beams.start[lo:hi], np.full(count, z)]),
                           np.column_stack([beams.end[lo:hi], np.full(count, z)]), resolution)
            cell = seg.cell[:, :2] - lower
            inside = np.all((cell >= 0) & (cell < (nx, ny)), axis=1)
            ray = seg.ray[inside]
            flat = cell[inside, 0] * ny + cell[inside, 1]
            is_hit = seg.last[inside] & beams.hit[lo:hi][ray]
            # One row per (scan, cell) of this chunk, with its hit and miss counts.
            scan_cell = beams.scan[lo:hi][ray].astype(np.int64) * n_cells + flat
            unique, inverse = np.unique(scan_cell, return_inverse=True)
            keys.append(unique)
            hits.append(np.bincount(inverse, weights=is_hit, minlength=unique.size).astype(np.int32))
            misses.append(np.bincount(inverse, weights=~is_hit, minlength=unique.size).astype(np.int32))
        scan_cell = np.concatenate(keys) if keys else np.zeros(0, np.int64)
        # A scan split between two chunks has rows in both: merged here.
        unique, inverse = np.unique(scan_cell, return_inverse=True)
        hit_counts = np.bincount(inverse, weights=np.concatenate(hits) if hits else None,
                                 minlength=unique.size).astype(np.int32)
        miss_counts = np.bincount(inverse, weights=np.concatenate(misses) if misses else None,
                                  minlength=unique.size).astype(np.int32)
        scan = unique // n_cells
        first = np.searchsorted(scan, np.arange(beams.n_scans + 1)).astype(np.int64)
        return cls(float(resolution), lower, (nx, ny), unique % n_cells, hit_counts, miss_counts, first)

    @property
    def n_scans(self) -> int:
        return int(self.first.size - 1)

    def of_scans(self, keep: NDArray[np.bool_]) -> ScanUpdates:
        """The updates of the scans ``keep`` marks (``(n_scans,)`` booleans), on the same grid:
        the same as traversing only those scans' beams over these bounds."""
        keep = np.asarray(keep, dtype=bool)
        if keep.shape != (self.n_scans,):
            raise InputError(f"scan selection has {keep.shape[0]} flags for {self.n_scans} scans")
        counts = np.diff(self.first)
        rows = np.repeat(keep, counts)
        first = np.concatenate([[0], np.cumsum(counts[keep])]).astype(np.int64)
        return ScanUpdates(self.resolution, self.lower, self.shape, self.key[rows], self.hits[rows],
                           self.misses[rows], first)

    def grid(self, params: TextbookParams, *, per_scan: bool = True, clamp_every_scan: bool = True) -> TextbookGrid:
        """Apply the inverse sensor model ``params`` (its resolution must be this one's).

        ``per_scan`` (the textbook): a scan adds ``l_occ`` to a cell where one of its beams
        ends, else ``l_free``; otherwise every beam adds its own (``hits * l_occ + misses *
        l_free``). ``clamp_every_scan`` (the textbook) clamps after each scan, otherwise once
        at the end.
        """
        if not np.isclose(params.resolution, self.resolution):
            raise InputError(f"updates at {self.resolution:g} m cannot build a {params.resolution:g} m grid")
        if per_scan:
            value = np.where(self.hits > 0, params.l_occ, params.l_free)
        else:
            value = self.hits * params.l_occ + self.misses * params.l_free
        low, high = params.clamp
        log_odds = np.zeros(self.shape[0] * self.shape[1], dtype=np.float64)
        if clamp_every_scan:
            # Scan after scan (each vectorised over its cells: no cell twice within a scan).
            for s in range(self.first.size - 1):
                a, b = int(self.first[s]), int(self.first[s + 1])
                if a == b:
                    continue
                cells = self.key[a:b]
                log_odds[cells] = np.clip(log_odds[cells] + value[a:b], low, high)
        else:
            np.add.at(log_odds, self.key, value)
            np.clip(log_odds, low, high, out=log_odds)
        return TextbookGrid(log_odds.astype(np.float32).reshape(self.shape), self.lower.copy(), params)


def textbook_grid(beams: WorldBeams, params: TextbookParams = TEXTBOOK_DEFAULTS, *,
                  bounds: tuple[FloatArray, FloatArray] | None = None) -> TextbookGrid:
    """The textbook log-odds grid of ``beams`` (module docstring), over ``bounds`` (default: theirs).

    Parameters
    ----------
    beams
        World-frame beams in scan order.
    params
        Resolution and inverse sensor model.
    bounds
        ``(lower, upper)`` world corners the grid covers; beams' cells outside are dropped.

    Returns
    -------
    TextbookGrid
        Log-odds per cell, 0 (probability 0.5) where no beam reached.
    """
    return ScanUpdates.from_beams(beams, params.resolution, bounds).grid(params)


__all__ = ["TEXTBOOK_DEFAULTS", "ScanUpdates", "TextbookGrid", "TextbookParams", "WorldBeams", "textbook_grid"]
