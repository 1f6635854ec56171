"""The 3D world map's cell size, chosen on the run's own scans (an inner held-out split).

The best cell for a run depends on its sensor and scene: a depth camera a metre or two from
the furniture wants small cells, a lidar whose returns lie 15 m away larger ones (a finer cell
is crossed by fewer rays and stays unknown). :func:`choose_resolution` asks the data, as a
reviewer tunes a baseline: it holds out blocks of consecutive scans (``groups``: the frames
a position gathered, :func:`occtool.fuse._log3d.rays_of_log`), builds the map of
the rest at each candidate cell size, scores it on the held-out rays (their returns occupied,
points every :data:`FREE_STEP` along them free; ROC AUC), coarsest first, and refines only
while a finer cell scores better by more than :data:`AUC_TOLERANCE`: a finer cell costs
four to eight times the bytes (and the walk twice the time) and must earn them by more than
the split's noise. Rays are subsampled by a seeded
generator, so the choice is deterministic and cheap.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool._stats import roc_auc
from occtool.formats.occmap3d import free_table
from occtool.fuse._world3d import FREE_SATURATION, build_world_map_3d

FloatArray = NDArray[np.float64]

#: Cell sizes tried (metres).
CANDIDATES = (0.1, 0.2, 0.4)
#: Share of the positions held out, in blocks of about a twelfth of the run.
HOLD_OUT = 0.15
BLOCKS_PER_RUN = 12
#: Rays each inner map is built from, and held-out rays it is scored on (subsampled above).
MAX_TRAIN_RAYS = 100_000
MAX_TEST_RAYS = 3_000
#: Spacing of the free test points along a held-out ray (metres), as bench/heldout3d.py.
FREE_STEP = 0.1
#: Most half-cell steps a candidate may walk on the inner training rays: finer cells that
#: would take longer are not tried.
MAX_STEPS = 30_000_000
#: How much better (held-out AUC) a finer cell must score than a coarser one to be kept:
#: about the spread of one inner split's AUC between seeds on the bench's sequences.
AUC_TOLERANCE = 0.005
#: Fewest positions an inner split needs (fewer: the default cell is kept).
MIN_POSITIONS = 4
#: How many walk points a square metre of a free cell's face needs to be believed free
#: (``saturation`` of :func:`occtool.fuse.build_world_map_3d`), tried on the chosen cell's
#: inner map: a dense depth camera's held-out returns lie where few training rays passed
#: (the TUM cabinet scores best near 1600), a sparse lidar's where many did (the Livox run:
#: 50, 0.978 / 0.948 held-out AUC in 3D / band against 0.962 / 0.944 at 1600).
SATURATIONS = (25.0, 100.0, 400.0, 1600.0, 6400.0)


def held_out_blocks(count: int, seed: int = 0) -> NDArray[np.bool_]:
    """Which of ``count`` positions an inner split holds out: blocks of ``count / 12``
    consecutive positions, 15 % of them, picked by the seed."""
    block = max(1, round(count / BLOCKS_PER_RUN))
    blocks = math.ceil(count / block)
    chosen = np.random.default_rng(seed).choice(blocks, size=max(1, round(HOLD_OUT * count / block)), replace=False)
    out = np.zeros(count, dtype=bool)
    for b in chosen:
        out[b * block:(b + 1) * block] = True
    return out


def _test_points(origins: FloatArray, ends: FloatArray, hits: NDArray[np.bool_]) -> tuple[FloatArray, FloatArray]:
    """Held-out returns and points every :data:`FREE_STEP` along the rays before them."""
    vector = ends - origins
    length = np.linalg.norm(vector, axis=1)
    last = np.where(hits, length - FREE_STEP, length)
    count = np.maximum(np.floor(last / FREE_STEP).astype(np.int64), 0)
    ray = np.repeat(np.arange(len(length)), count)
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count) + 1
    free = origins[ray] + (k * FREE_STEP / np.maximum(length[ray], 1e-12))[:, None] * vector[ray]
    return ends[hits], free


def choose_resolution(origins: FloatArray, ends: FloatArray, hits: NDArray[np.bool_], groups: NDArray[np.intp], *,
                      candidates: tuple[float, ...] = CANDIDATES, default: float | None = None, seed: int = 0,
                      **options: Any) -> tuple[float, dict[str, Any]]:
    """The cell size of :data:`CANDIDATES` chosen on held-out blocks of positions, refined
    coarse to fine while a finer one earns its bytes (module docstring), and a report (the
    inner AUC of each size tried).

    ``groups`` ``(N,)`` numbers each ray's position (0, 1, ... in the run's order);
    ``options`` are :func:`occtool.fuse.build_world_map_3d`'s. Fewer than
    :data:`MIN_POSITIONS` positions keep ``default`` (``None``: the coarsest candidate, as
    a finer cell has nothing to earn its bytes on).
    """
    default = max(candidates) if default is None else default
    count = int(groups.max()) + 1 if groups.size else 0
    if count < MIN_POSITIONS:
        return default, {"chosen": default, "why": f"{count} positions: too few to hold some out"}
    rng = np.random.default_rng(seed)
    test = held_out_blocks(count, seed)[groups]
    train_rays, test_rays = np.flatnonzero(~test), np.flatnonzero(test)
    if train_rays.size > MAX_TRAIN_RAYS:
        train_rays = np.sort(rng.choice(train_rays, MAX_TRAIN_RAYS, replace=False))
    if test_rays.size > MAX_TEST_RAYS:
        test_rays = np.sort(rng.choice(test_rays, MAX_TEST_RAYS, replace=False))
    occupied, free = _test_points(origins[test_rays], ends[test_rays], hits[test_rays])
    if occupied.shape[0] == 0 or free.shape[0] == 0:
        return default, {"chosen": default, "why": "the held-out positions hold no returns"}
    walked = float(np.linalg.norm(ends[train_rays] - origins[train_rays], axis=1).sum())
    points = np.vstack([occupied, free])  # the world's own frame: predict's without to_map
    scores: dict[str, float] = {}
    best, best_auc, best_world, best_ridges = None, -1.0, None, None
    for size in sorted(candidates, reverse=True):  # coarse first: the coarsest is always tried
        if best is not None and walked / (0.5 * size) > MAX_STEPS:
            break
        world = build_world_map_3d(origins[train_rays], ends[train_rays], hits[train_rays], resolution=size,
                                   **options)
        ridges = world.ridges(points)
        p = np.maximum(world.background(points), ridges)
        auc = roc_auc(p[:len(occupied)], p[len(occupied):])
        scores[f"{size:g}"] = round(auc, 4)
        if best is not None and auc < best_auc + AUC_TOLERANCE:
            break  # no finer cell is tried once one does not earn its bytes
        best, best_auc, best_world, best_ridges = size, auc, world, ridges
    assert best is not None and best_world is not None and best_ridges is not None
    report: dict[str, Any] = {"chosen": best, "inner_auc": scores,
                              "held_out_positions": int(held_out_blocks(count, seed).sum()), "positions": count}
    if "saturation" not in options and best_world.free_table is not None:
        report["saturation"], report["saturation_auc"] = _saturation(best_world, points, len(occupied), best_ridges)
    return best, report


def _saturation(world: Any, points: FloatArray, occupied: int, ridges: FloatArray) -> tuple[float, dict[str, float]]:
    """The :data:`SATURATIONS` value under which ``world``'s free space scores the held-out
    points (the first ``occupied`` of them returns) best; the patches' ``ridges`` there are
    the same for every one."""
    _, _, size = world.free_box
    scores: dict[str, float] = {}
    best, best_auc = FREE_SATURATION, -1.0
    for saturation in SATURATIONS:
        world.free_table = free_table(size, world.free_level, saturation, world.free_table.size)
        p = np.maximum(world.background(points), ridges)
        auc = roc_auc(p[:occupied], p[occupied:])
        scores[f"{saturation:g}"] = round(auc, 4)
        if auc > best_auc:
            best, best_auc = saturation, auc
    return best, scores


__all__ = ["AUC_TOLERANCE", "CANDIDATES", "choose_resolution", "held_out_blocks"]
