"""How well a free/occupied/unknown raster agrees with the scans it was built from
(:func:`nav2_agreement`), and a world grid read as Nav2 reads a map (:func:`grid_raster`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.features import Position
from occtool.fuse import FREE, OCCUPIED, UNKNOWN, Raster
from occtool.grid import traverse
from occtool.scoring._heldout import END_MARGIN, world_rays

#: Rays traversed per chunk, here and by the world grid (bounds the temporary arrays).
RAYS_PER_CHUNK = 20_000


def grid_raster(grid: Any) -> Raster:
    """A one-layer world grid as Nav2 would load it (trinary: occupied at or above 0.65,
    free at or below 0.196, unknown between and where no ray passed): the reference for
    :func:`nav2_agreement`."""
    from scipy.special import expit

    log_odds = np.asarray(grid.log_odds, dtype=np.float64)[:, :, 0].T  # rows along y
    p = expit(log_odds)
    cells = np.full(p.shape, UNKNOWN, dtype=np.uint8)
    cells[(log_odds != 0) & (p <= 0.196)] = FREE
    cells[p >= 0.65] = OCCUPIED
    origin = (float(grid.lower[0]), float(grid.lower[1]))
    return Raster(cells, float(grid.resolution), origin, p.astype(np.float32), np.zeros(p.shape, dtype=bool))


def nav2_agreement(raster: Raster, scans: list[Position], margin: float = END_MARGIN) -> dict[str, float]:
    """How well a free/occupied/unknown raster agrees with scans, per beam and per cell.

    Both count a return as agreeing when it falls on an occupied cell or one of its eight
    neighbours, and a stretch of beam as agreeing when no cell it crosses, from the sensor
    to ``margin`` before the return, is occupied (outside the raster counts as not occupied).

    *Per beam* (the stricter figures, kept as the target's wording reads): ``returns_on_occupied``
    and ``beams_clear`` are shares of returns and of beams; a beam fails when a single cell
    of its whole length is occupied. ``scans_returns_95``, ``scans_beams_95`` and
    ``scans_both_95`` are the shares of scans where at least 95 % of the returns, the
    beams, or both pass.

    *Per cell* (OctoMap's "map accuracy", Hornung et al. 2013: the share of a scan's cells
    the map holds as the scan says, its end-point cells occupied and the cells its beams
    traverse not occupied): each scan's distinct end-point cells and distinct traversed
    cells are counted once, whichever and however many beams touch them; a traversed cell
    that is also one of that scan's own end-point cells is counted as an end point only
    (OctoMap's scan insertion does the same: a cell a scan both hits and passes is
    occupied for it). ``endpoint_cells_on_occupied`` and ``traversed_cells_clear`` are the
    shares over all scans' cells; ``scans_endpoint_cells_95``, ``scans_traversed_cells_95``
    and ``scans_cells_both_95`` the shares of scans where at least 95 % of their cells pass.
    A grazing beam that crosses one occupied cell near a wall fails as a beam but counts
    one wrong cell among the dozens it crosses: the per-cell figures are the looser ones.
    """
    starts, ends, returns, owner = world_rays(scans)
    starts, ends, owner = starts[returns], ends[returns], owner[returns]
    occupied = raster.cells == OCCUPIED
    padded = np.pad(occupied, 1)
    near = np.zeros_like(occupied)
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            near |= padded[1 + dj:1 + dj + occupied.shape[0], 1 + di:1 + di + occupied.shape[1]]
    row, col, inside = raster.cell_of(ends[:, :2])
    hit = inside & near[row, col]
    # Beams: the cells crossed from the sensor to ``margin`` before the end.
    length = np.hypot(*(ends[:, :2] - starts[:, :2]).T)
    short = np.clip((length - margin) / np.maximum(length, 1e-12), 0.0, 1.0)[:, None]
    stop = starts[:, :2] + short * (ends[:, :2] - starts[:, :2])
    clear = np.ones(length.size, dtype=bool)
    origin = np.array(raster.origin)
    # Cells are keyed (scan, row, column) over a box holding every beam, inside the raster or not.
    both = np.concatenate([starts[:, :2], ends[:, :2]]) if length.size else origin[None, :]
    corner = np.floor((both.min(axis=0) - origin) / raster.resolution).astype(np.int64) - 1
    far = np.floor((both.max(axis=0) - origin) / raster.resolution).astype(np.int64) + 2
    width, height = int(far[0] - corner[0]), int(far[1] - corner[1])

    def cell_key(scan: NDArray[np.intp], i: NDArray[np.int64], j: NDArray[np.int64]) -> NDArray[np.int64]:
        return (scan.astype(np.int64) * height + (j - corner[1])) * width + (i - corner[0])

    end_i = np.floor((ends[:, 0] - origin[0]) / raster.resolution).astype(np.int64)
    end_j = np.floor((ends[:, 1] - origin[1]) / raster.resolution).astype(np.int64)
    end_keys, first = np.unique(cell_key(owner, end_i, end_j), return_index=True)
    end_cell_hit = hit[first]  # a cell's verdict depends on the cell alone
    traversed_keys, traversed_blocked = [], []
    for lo in range(0, length.size, RAYS_PER_CHUNK):
        hi = min(length.size, lo + RAYS_PER_CHUNK)
        a = np.column_stack([starts[lo:hi, :2] - origin, np.full(hi - lo, 0.5 * raster.resolution)])
        b = np.column_stack([stop[lo:hi] - origin, np.full(hi - lo, 0.5 * raster.resolution)])
        seg = traverse(a, b, raster.resolution)
        j, i = seg.cell[:, 1], seg.cell[:, 0]
        valid = (j >= 0) & (j < occupied.shape[0]) & (i >= 0) & (i < occupied.shape[1])
        blocked = np.zeros(seg.ray.size, dtype=bool)
        blocked[valid] = occupied[j[valid], i[valid]]
        bad = np.zeros(hi - lo, dtype=bool)
        bad[seg.ray[blocked]] = True
        clear[lo:hi] = ~bad
        keys, once = np.unique(cell_key(owner[lo:hi][seg.ray], i, j), return_index=True)
        traversed_keys.append(keys)
        traversed_blocked.append(blocked[once])
    n_scans = len(scans)
    per_scan = np.bincount(owner, minlength=n_scans).astype(np.float64)
    has = per_scan > 0
    hit_share = np.bincount(owner, weights=hit, minlength=n_scans)[has] / per_scan[has]
    clear_share = np.bincount(owner, weights=clear, minlength=n_scans)[has] / per_scan[has]
    # Per cell: a scan's traversed cells once each (beams of one chunk share cells with the
    # next chunk's), less its own end-point cells.
    keys = np.concatenate(traversed_keys) if traversed_keys else np.zeros(0, np.int64)
    keys, once = np.unique(keys, return_index=True)
    cell_blocked = (np.concatenate(traversed_blocked) if traversed_blocked else np.zeros(0, bool))[once]
    own_end = np.isin(keys, end_keys, assume_unique=True)
    keys, cell_blocked = keys[~own_end], cell_blocked[~own_end]
    cells_per_scan = width * height
    end_owner = end_keys // cells_per_scan
    traversed_owner = keys // cells_per_scan
    ends_of = np.bincount(end_owner, minlength=n_scans).astype(np.float64)
    traversed_of = np.bincount(traversed_owner, minlength=n_scans).astype(np.float64)
    end_cell_share = (np.bincount(end_owner, weights=end_cell_hit, minlength=n_scans)[has]
                      / np.maximum(ends_of[has], 1.0))
    # A scan whose beams cross no cell before their margin (all returns within 0.1 m) passes.
    traversed_share = np.where(traversed_of[has] > 0,
                               np.bincount(traversed_owner, weights=~cell_blocked, minlength=n_scans)[has]
                               / np.maximum(traversed_of[has], 1.0), 1.0)
    return {
        "returns_on_occupied": float(hit.mean()) if hit.size else math.nan,
        "beams_clear": float(clear.mean()) if clear.size else math.nan,
        "scans_returns_95": float((hit_share >= 0.95).mean()),
        "scans_beams_95": float((clear_share >= 0.95).mean()),
        "scans_both_95": float(((hit_share >= 0.95) & (clear_share >= 0.95)).mean()),
        "endpoint_cells_on_occupied": float(end_cell_hit.mean()) if end_cell_hit.size else math.nan,
        "traversed_cells_clear": float((~cell_blocked).mean()) if cell_blocked.size else math.nan,
        "scans_endpoint_cells_95": float((end_cell_share >= 0.95).mean()),
        "scans_traversed_cells_95": float((traversed_share >= 0.95).mean()),
        "scans_cells_both_95": float(((end_cell_share >= 0.95) & (traversed_share >= 0.95)).mean()),
        "scans": int(has.sum()),
    }


__all__ = ["grid_raster", "nav2_agreement"]
