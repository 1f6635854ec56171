"""Ray traversal: the cells of the lattice a set of straight rays crosses (:func:`traverse`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# Rays are traversed in chunks so that the segment arrays of one chunk stay near this size.
_SEGMENTS_PER_CHUNK = 2_000_000


@dataclass(frozen=True)
class RaySegments:
    """Cells crossed by a set of rays: one row per (ray, cell) pair, in ray order.

    ``t_enter`` and ``t_exit`` are fractions of the ray (0 at its start, 1 at its end);
    ``last`` marks the cell holding the end of each ray.
    """

    ray: IntArray
    cell: IntArray
    t_enter: FloatArray
    t_exit: FloatArray
    last: NDArray[np.bool_]


def traverse(start: ArrayLike, end: ArrayLike, resolution: float) -> RaySegments:
    """Cells of a regular grid crossed by straight rays (a vectorised 3D DDA).

    Cell ``(i, j, k)`` spans ``[i, i + 1) * resolution`` along x and likewise along y and
    z, so the cell boundaries lie on multiples of the resolution, as in OctoMap. For every
    ray all its boundary crossings along the three axes are generated at once, sorted
    along the ray, and each piece between consecutive crossings is one cell, found from
    the piece's midpoint. Pieces shorter than ``1e-12`` of the ray (crossings of two
    boundaries at a corner) are dropped. The last cell of each ray is the one holding its
    end point, even when the end point lies exactly on a boundary.

    Parameters
    ----------
    start, end
        ``(N, 3)`` ray start and end points (or one ``(3,)`` start for all rays), metres.
    resolution
        Cell edge length, metres.

    Returns
    -------
    RaySegments
        The crossed cells as integer ``(K, 3)`` indices, with the ray each belongs to.
    """
    end = np.atleast_2d(np.asarray(end, dtype=np.float64))
    start = np.broadcast_to(np.asarray(start, dtype=np.float64), end.shape)
    n = end.shape[0]
    u0 = start / resolution
    u1 = end / resolution
    lo = np.minimum(u0, u1)
    hi = np.maximum(u0, u1)
    # Integer boundaries strictly between the two ends, per axis.
    first = np.floor(lo).astype(np.int64) + 1
    counts = np.maximum(np.ceil(hi).astype(np.int64) - first, 0)
    delta = u1 - u0
    ray_parts = []
    t_parts = []
    ids = np.arange(n, dtype=np.int64)
    for axis in range(3):
        c = counts[:, axis]
        total = int(c.sum())
        # Per ray, the boundaries first, first + 1, ... as one flat array (a ragged arange).
        offsets = np.arange(total, dtype=np.int64) - np.repeat(np.cumsum(c) - c, c)
        boundary = np.repeat(first[:, axis] - u0[:, axis], c) + offsets
        ray_parts.append(np.repeat(ids, c))
        t_parts.append(boundary / np.repeat(delta[:, axis], c))
    ray_parts += [ids, ids]
    t_parts += [np.zeros(n), np.ones(n)]
    ray_all = np.concatenate(ray_parts)
    # t lies in [0, 1], so 2 * ray + t sorts by ray, then along the ray.
    key = 2.0 * ray_all + np.clip(np.concatenate(t_parts), 0.0, 1.0)
    key.sort()
    ray_sorted = np.floor(key * 0.5).astype(np.int64)
    t_sorted = key - 2.0 * ray_sorted
    same_ray = ray_sorted[1:] == ray_sorted[:-1]
    t_a = t_sorted[:-1]
    t_b = t_sorted[1:]
    keep = same_ray & (t_b - t_a > 1e-12)
    ray = ray_sorted[:-1][keep]
    t_enter = t_a[keep]
    t_exit = t_b[keep]
    mid = 0.5 * (t_enter + t_exit)
    cell = np.floor(u0[ray] + delta[ray] * mid[:, None]).astype(np.int64)
    last = np.ones(ray.shape[0], dtype=bool)
    if ray.size:
        last[:-1] = ray[1:] != ray[:-1]
    # A ray ending exactly on a cell boundary has its last piece in the cell before the
    # end point; the end point's own cell (where lookups and OctoMap put it) is added.
    end_cell = np.floor(u1).astype(np.int64)
    short = np.zeros(n, dtype=bool)
    short[ray[last]] = (cell[last] != end_cell[ray[last]]).any(axis=1)
    short_rays = np.flatnonzero(short)
    if short_rays.size:
        last[last] = ~short[ray[last]]
        ray = np.concatenate([ray, short_rays])
        order = np.argsort(ray, kind="stable")
        ray = ray[order]
        cell = np.concatenate([cell, end_cell[short_rays]])[order]
        t_enter = np.concatenate([t_enter, np.ones(short_rays.size)])[order]
        t_exit = np.concatenate([t_exit, np.ones(short_rays.size)])[order]
        last = np.concatenate([last, np.ones(short_rays.size, dtype=bool)])[order]
    return RaySegments(ray=ray, cell=cell, t_enter=t_enter, t_exit=t_exit, last=last)


def _chunks(n: int, size: int) -> list[tuple[int, int]]:
    return [(i, min(n, i + size)) for i in range(0, n, size)] or [(0, 0)]
