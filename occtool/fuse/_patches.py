"""Planar patches and the crossed free space of a 3D run: the numbers of :class:`~occtool.fuse._world3d.WorldMap3D`.

The 3D counterpart of :mod:`occtool.fuse._walls`: where the 2D map fits a wall segment to the
second moments of a cell's returns, this fits a plane to the returns in each cubic cell of
``resolution`` metres (centre, normal from the smallest eigenvector, extent along the plane
from the two largest eigenvalues, thickness from the smallest). Every training ray, not only
each position's nearest return, is walked in steps of half a cell: the cells it crosses before
its return are free, and a ray that goes through a patch's slab counts against the patch's
trust (``hits / (hits + crossings)``).

Everything is quantised here (:class:`PatchCodes`), so that a map read back from its file
answers bit for bit as the one built.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from occtool.formats.occmap3d import AZIMUTH_STEPS, POLAR_STEPS, PatchCodes, PatchCodesV5, level_box

FloatArray = NDArray[np.float64]

#: Rays are walked in chunks of at most this many samples: a chunk's dozen temporaries
#: stay within the caches (on the TUM cabinet, 3.7 M walk points at 0.2 m: 1 << 20 a
#: chunk took 1.35-1.6 s of CPU on this project's shared 2-core machine, 1 << 18 0.42-0.45 s).
CHUNK_SAMPLES = 1 << 18
#: A patch is never thinner than this (metres): range noise of the sensors read.
MIN_THICKNESS = 0.01
#: A patch fitted to fewer returns than this takes its normal from the rays that hit it.
MIN_PLANE_POINTS = 4
#: A coarse-level patch holds at least this many returns.
MIN_FLAT_POINTS = 8
#: Smallest half-extent of a patch along the plane, as a share of the cell.
MIN_EXTENT = 0.25
#: A patch of the finest level holds at least this share of the mean returns of the cells
#: holding any, within :data:`MIN_RETURNS`: a cell with fewer (a flying pixel, the edge of a
#: surface) is left to the free space and its neighbours' ridges. Dense depth frames (the
#: TUM cabinet: 64 returns a 0.2 m cell) leave out the cells of fewer than 24, which took its
#: patches from about 2000 to 650 and the held-out AUC (bench/heldout3d.py, seeds 0-2) by at
#: most 0.003; a sparse lidar (the Livox run: 18 a 0.4 m cell) keeps those of 8 or more (24
#: took its band AUC from 0.944 to 0.923), the sparser Seosan run those of 2 or more (8
#: took its held-out AUC from 0.971 / 0.968 to 0.949 / 0.955).
MIN_RETURNS_SHARE = 0.4
MIN_RETURNS = (2, 24)
#: Levels each number of a version-5 patch was rounded to (its file is still read): the
#: centre's offset in its cell per axis, the normal's polar angle and azimuth, the in-plane
#: axis, the two extents and the trust.
LEVELS = {"offset": 16, "polar": 33, "azimuth": 64, "axis": 16, "extent": 16, "trust": 16}
#: Most distance (metres) between the planes of neighbouring cells, and from a group's plane
#: to a member's returns, for the cells to share one plane: about a depth camera's range
#: noise at 2-3 m.
MERGE_DISTANCE = 0.03
#: Neighbouring cells' own normals within this angle's cosine may share a plane (20 degrees).
MERGE_COSINE = math.cos(math.radians(20.0))
#: Levels of a version-6 patch's trust and of its plane's distance from the cell's centre
#: (over [-cell, cell]): a ridge falls over half a cell, so a plane a 64th of a cell off
#: costs little, and its position along the normal is what the held-out score feels most.
TRUST_LEVELS = 8
OFFSET_STEPS = 32
#: A version-6 patch's half-extent along its plane, as a share of its cell: a patch covers
#: its cell's part of the plane and reaches half a cell into its neighbours' (the returns of
#: a surface rarely stop where the cell does).
EXTENT = 0.5
#: Half-thicknesses a patch may take (mm): rounded up to the next.
THICKNESS_MM = (10, 14, 20, 28, 40, 56, 80, 113, 160, 226, 255)
#: Normal angle steps: polar over [0, pi/2] (a normal is kept in the upper half-sphere),
#: azimuth over [0, 2 pi); the in-plane axis over [0, pi).
ANGLE_STEPS = 256


@dataclass
class PatchGeometry:
    """The patches as floats (what :func:`geometry` derives from :class:`PatchCodes`)."""

    centres: FloatArray  # (S, 3) world
    normals: FloatArray  # (S, 3) unit
    u: FloatArray  # (S, 3) unit, in-plane, along the larger extent
    v: FloatArray  # (S, 3) unit, in-plane
    extents: FloatArray  # (S, 2) half-extents along u and v (m)
    thickness: FloatArray  # (S,) half-thickness (m)
    trust: FloatArray  # (S,) in (0, 1]


def cell_keys(points: FloatArray, lo: NDArray[np.int64], shape: tuple[int, int, int],
              resolution: float) -> NDArray[np.int64]:
    """Linear cell index (x slowest, z fastest) of ``(K, 3)`` points inside the box; -1 outside."""
    return index_keys(np.floor(points / resolution).astype(np.int64), lo, shape)


def index_keys(ijk: NDArray[np.int64], lo: NDArray[np.int64], shape: tuple[int, int, int]) -> NDArray[np.int64]:
    """Linear cell index of ``(K, 3)`` integer cell coordinates inside the box; -1 outside."""
    i, j, k = ijk[:, 0] - lo[0], ijk[:, 1] - lo[1], ijk[:, 2] - lo[2]
    inside = (i >= 0) & (i < shape[0]) & (j >= 0) & (j < shape[1]) & (k >= 0) & (k < shape[2])
    return np.where(inside, (i * shape[1] + j) * shape[2] + k, -1)


def key_corners(keys: NDArray[np.int64], lo: NDArray[np.int64], shape: tuple[int, int, int],
                resolution: float) -> FloatArray:
    """World corner (lowest x, y, z) of each cell key."""
    i, rest = np.divmod(keys, shape[1] * shape[2])
    j, k = np.divmod(rest, shape[2])
    return np.asarray((np.column_stack([i, j, k]) + lo) * resolution, dtype=np.float64)


def _frame(normals: FloatArray) -> tuple[FloatArray, FloatArray]:
    """A fixed in-plane pair ``(a, b)`` for each unit normal (so one byte can name an axis)."""
    reference = np.where((np.abs(normals[:, 2]) < 0.9)[:, None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    a = np.cross(normals, reference)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    return a, np.asarray(np.cross(normals, a), dtype=np.float64)


def _normal_of(codes: NDArray[np.uint8]) -> FloatArray:
    polar = codes[:, 0].astype(np.float64) * (0.5 * math.pi / (ANGLE_STEPS - 1))
    azimuth = codes[:, 1].astype(np.float64) * (2.0 * math.pi / ANGLE_STEPS)
    return np.column_stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)])


def normal_of(codes: NDArray[np.uint8]) -> FloatArray:
    """Unit normals of version-6 direction codes: ``polar * AZIMUTH_STEPS + azimuth``, the polar
    angle on :data:`~occtool.formats.occmap3d.POLAR_STEPS` steps over [0, pi/2] (a normal is
    kept in the upper half-sphere), the azimuth on ``AZIMUTH_STEPS`` over [0, 2 pi)."""
    polar = (codes // AZIMUTH_STEPS).astype(np.float64) * (0.5 * math.pi / (POLAR_STEPS - 1))
    azimuth = (codes % AZIMUTH_STEPS).astype(np.float64) * (2.0 * math.pi / AZIMUTH_STEPS)
    return np.column_stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)])


def normal_codes(normals: FloatArray) -> NDArray[np.uint8]:
    """The version-6 direction codes of unit normals (flipped into the upper half-sphere)."""
    normals = np.where((normals[:, 2] < 0.0)[:, None], -normals, normals)
    polar = np.round(np.arccos(np.clip(normals[:, 2], -1.0, 1.0)) / (0.5 * math.pi) * (POLAR_STEPS - 1))
    azimuth = np.round(np.arctan2(normals[:, 1], normals[:, 0]) / (2.0 * math.pi) * AZIMUTH_STEPS) % AZIMUTH_STEPS
    return (polar * AZIMUTH_STEPS + np.where(polar > 0, azimuth, 0)).astype(np.uint8)


def geometry(codes: PatchCodes | PatchCodesV5, lo: NDArray[np.int64], shape: tuple[int, int, int],
             resolution: float, extent: float = EXTENT) -> PatchGeometry:
    """The floats a map answers with, from its codes alone (so a file read back answers the same)."""
    if isinstance(codes, PatchCodesV5):
        return _geometry_v5(codes, lo, shape, resolution)
    root = plane_roots(codes.keys, codes.refs, shape)
    normals = normal_of(codes.normals[root])
    middle = key_corners(codes.keys, lo, shape, resolution) + 0.5 * resolution
    on_plane = middle[root] + ((codes.offsets[root].astype(np.float64) - 128.0)
                               * (resolution / OFFSET_STEPS))[:, None] * normals
    # A merged cell's patch is its root's plane through this cell: the cell's middle moved
    # onto that plane along the normal.
    centres = np.where((codes.refs == 0)[:, None], on_plane,
                       middle - np.sum((middle - on_plane) * normals, axis=1, keepdims=True) * normals)
    u, v = _frame(normals)
    return PatchGeometry(centres, normals, u, v, np.full((len(codes), 2), extent * resolution),
                         codes.thickness.astype(np.float64) * 0.001, codes.trust.astype(np.float64) / 255.0)


def ref_steps(shape: tuple[int, int, int]) -> NDArray[np.int64]:
    """Key differences of a patch's reference codes: 0 its own plane, 1-3 the plane of the
    cell before it along z, y, x."""
    return np.array([0, 1, shape[2], shape[1] * shape[2]], dtype=np.int64)


def plane_roots(keys: NDArray[np.int64], refs: NDArray[np.uint8], shape: tuple[int, int, int]) -> NDArray[np.intp]:
    """The index of the patch whose plane each patch takes (itself, or by its reference the
    root of the neighbour before it, :func:`ref_steps`); ``refs`` checked by the file's reader."""
    parent = np.arange(keys.size)
    linked = np.flatnonzero(refs > 0)
    parent[linked] = np.searchsorted(keys, keys[linked] - ref_steps(shape)[refs[linked]])
    while True:  # pointer jumping: every parent has a smaller key, so this ends
        jumped = parent[parent]
        if np.array_equal(jumped, parent):
            return parent
        parent = jumped


def _geometry_v5(codes: PatchCodesV5, lo: NDArray[np.int64], shape: tuple[int, int, int],
                 resolution: float) -> PatchGeometry:
    centres = key_corners(codes.keys, lo, shape, resolution) + (codes.offsets.astype(np.float64) + 0.5) * (
        resolution / 256.0)
    normals = _normal_of(codes.normals)
    a, b = _frame(normals)
    angle = codes.axes.astype(np.float64) * (math.pi / ANGLE_STEPS)
    u = np.cos(angle)[:, None] * a + np.sin(angle)[:, None] * b
    v = np.cross(normals, u)
    return PatchGeometry(centres, normals, u, v, codes.extents.astype(np.float64) * (resolution / 255.0),
                         codes.thickness.astype(np.float64) * 0.001, codes.trust.astype(np.float64) / 255.0)


def fit_patches(returns: FloatArray, directions: FloatArray, lo: NDArray[np.int64], shape: tuple[int, int, int],
                resolution: float, flat: float | None = None, min_returns: int = MIN_RETURNS[0]
                ) -> tuple[PatchCodes, NDArray[np.bool_], NDArray[np.int64]]:
    """One plane per cell holding returns, from their second moments, quantised (trust 1 for now).

    ``directions`` ``(H, 3)`` the unit direction of the ray of each return: the normal of a cell
    with fewer than :data:`MIN_PLANE_POINTS` returns (a surface seen face on). With ``flat``
    (metres), only the cells whose returns lie within that RMS distance of their plane, and
    hold at least :data:`MIN_FLAT_POINTS`, get a patch (a coarse level: the rest is fitted
    finer); without, the cells of at least ``min_returns`` returns. Returns the patches,
    which returns they took, and how many each took.
    """
    keys = cell_keys(returns, lo, shape, resolution)
    order = np.argsort(keys, kind="stable")
    keys, points, directions = keys[order], returns[order], directions[order]
    starts = np.r_[0, np.flatnonzero(keys[1:] != keys[:-1]) + 1] if keys.size else np.zeros(0, dtype=np.int64)
    cells, counts = keys[starts], np.diff(np.r_[starts, keys.size])
    n = counts.astype(np.float64)
    corner = key_corners(cells, lo, shape, resolution)
    local = points - np.repeat(corner, counts, axis=0)  # cell-relative: no cancellation in the moments
    mean = np.add.reduceat(local, starts, axis=0) / n[:, None]
    # The six distinct second moments one at a time (a (H, 3, 3) array of products is 72
    # bytes a return), each summed as a column: in order within each cell, as the whole was.
    outer = np.empty((cells.size, 3, 3))
    for a, b in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)):
        outer[:, a, b] = outer[:, b, a] = np.add.reduceat(local[:, a:a + 1] * local[:, b:b + 1], starts, axis=0)[:, 0]
    outer /= n[:, None, None]
    covariance = outer - mean[:, :, None] * mean[:, None, :]
    values, vectors = np.linalg.eigh(covariance)  # ascending
    values = np.maximum(values, 0.0)
    normals = vectors[:, :, 0]
    few = counts < MIN_PLANE_POINTS
    if few.any():
        seen = np.add.reduceat(directions, starts, axis=0)[few]
        seen /= np.maximum(np.linalg.norm(seen, axis=1, keepdims=True), 1e-12)
        normals[few] = seen
    # Flatness is judged about the returns' own plane, before rounding.
    keep = (counts >= min_returns) if flat is None else (
        (np.sqrt(values[:, 0]) <= flat) & (counts >= max(MIN_FLAT_POINTS, min_returns)))
    corner = corner[keep]
    world_mean = corner + mean[keep]
    world_outer = covariance[keep] + world_mean[:, :, None] * world_mean[:, None, :]
    refs, plane_codes, plane_points = merge_planes(cells[keep], counts[keep], world_mean, world_outer, normals[keep],
                                                   shape)
    quantised = normal_of(plane_codes)
    middle = corner + 0.5 * resolution
    explicit = refs == 0
    offsets = np.where(explicit, np.clip(np.round(np.sum((plane_points - middle) * quantised, axis=1)
                                                  / resolution * OFFSET_STEPS) + 128, 1, 255), 0).astype(np.uint8)
    codes = PatchCodes(cells[keep].astype(np.int64), refs, np.where(explicit, plane_codes, 0).astype(np.uint8),
                       offsets, np.zeros(int(keep.sum()), dtype=np.uint8),
                       np.full(int(keep.sum()), 255, dtype=np.uint8))
    # Half-thickness: the RMS distance of the returns from the stored plane (one sigma, not
    # two: on seed 0's split of the bench, free points just before a return then rank lower).
    g = geometry(codes, lo, shape, resolution)
    kept_counts = counts[keep]
    taken = np.zeros(returns.shape[0], dtype=bool)
    taken[order] = np.repeat(keep, counts)
    mine = points[np.repeat(keep, counts)]
    depth = np.sum((mine - np.repeat(g.centres, kept_counts, axis=0)) * np.repeat(g.normals, kept_counts, axis=0),
                   axis=1)
    kept_starts = np.r_[0, np.cumsum(kept_counts)[:-1]] if kept_counts.size else np.zeros(0, dtype=np.int64)
    few_kept = kept_counts < MIN_PLANE_POINTS
    if kept_counts.size:
        rms = np.sqrt(np.add.reduceat(depth * depth, kept_starts) / kept_counts)
        thickness = np.maximum(np.where(few_kept, np.abs(np.add.reduceat(depth, kept_starts) / kept_counts), rms),
                               MIN_THICKNESS)
        table = np.asarray(THICKNESS_MM)
        codes.thickness = table[np.minimum(np.searchsorted(table, thickness * 1000.0), table.size - 1)].astype(np.uint8)
    return codes, taken, kept_counts.astype(np.int64)


def fewest_returns(returns: FloatArray, resolution: float) -> int:
    """The fewest returns a finest-level cell needs for a patch (:data:`MIN_RETURNS_SHARE`)."""
    if not returns.shape[0]:
        return MIN_RETURNS[0]
    cells = sorted_unique(index_keys(np.floor(returns / resolution).astype(np.int64) - np.floor(
        returns.min(axis=0) / resolution).astype(np.int64), np.zeros(3, dtype=np.int64), (1 << 20, 1 << 20, 1 << 20)))
    mean = returns.shape[0] / max(cells.size, 1)
    return int(np.clip(math.ceil(MIN_RETURNS_SHARE * mean), *MIN_RETURNS))


def merge_planes(cells: NDArray[np.int64], counts: NDArray[np.int64], means: FloatArray, outers: FloatArray,
                 normals: FloatArray, shape: tuple[int, int, int]
                 ) -> tuple[NDArray[np.uint8], NDArray[np.uint8], FloatArray]:
    """One plane over neighbouring cells whose returns lie on it: each cell's reference code
    (:func:`ref_steps`; 0 where it keeps its own plane), each cell's plane's direction code
    and a point on that plane.

    Face neighbours whose own planes have the same direction code and lie within
    :data:`MERGE_DISTANCE` of each other are joined; each group's plane is fitted to all its
    returns (their summed second moments); a cell whose mean lies farther than
    :data:`MERGE_DISTANCE` from it keeps its own. A grouped cell refers to a grouped neighbour
    before it in key order where it has one, so that its plane costs the file a few bits.
    """
    size = cells.size
    if size == 0:
        return np.zeros(0, dtype=np.uint8), np.zeros(0, dtype=np.uint8), np.zeros((0, 3))
    own = normal_codes(normals)
    own_normal = normal_of(own)
    label = np.arange(size)
    steps = ref_steps(shape)
    wrap = [np.zeros(size, dtype=bool), cells % shape[2] == 0, (cells // shape[2]) % shape[1] == 0,
            cells // (shape[1] * shape[2]) == 0]
    before = np.full((4, size), -1, dtype=np.int64)
    for ref in (1, 2, 3):
        at = np.clip(np.searchsorted(cells, cells - steps[ref]), 0, max(size - 1, 0))
        there = (~wrap[ref]) & (cells[at] == cells - steps[ref]) if size else np.zeros(0, dtype=bool)
        near = there & (np.abs(np.sum(normals * normals[at], axis=1)) >= MERGE_COSINE) & (
            np.abs(np.sum((means - means[at]) * own_normal, axis=1)) <= MERGE_DISTANCE)
        before[ref] = np.where(near, at, -1)
    pairs = [(np.flatnonzero(before[ref] >= 0), before[ref][before[ref] >= 0]) for ref in (1, 2, 3)]
    a = np.concatenate([p for p, _ in pairs]) if size else np.zeros(0, dtype=np.int64)
    b = np.concatenate([q for _, q in pairs]) if size else np.zeros(0, dtype=np.int64)
    while a.size:  # connected groups: the smallest index of each, spread along the links
        lowest = np.minimum(label[a], label[b])
        changed = (label[a] != lowest) | (label[b] != lowest)
        if not changed.any():
            break
        np.minimum.at(label, a, lowest)
        np.minimum.at(label, b, lowest)
        label = label[label]
    group_size = np.bincount(label, minlength=size)
    n = counts.astype(np.float64)
    total = np.bincount(label, weights=n, minlength=size)
    weight = np.maximum(total, 1.0)
    centroid = np.column_stack([np.bincount(label, weights=n * means[:, k], minlength=size) / weight
                                for k in range(3)])
    second = np.stack([np.column_stack([np.bincount(label, weights=n * outers[:, r, c], minlength=size) / weight
                                        for c in range(3)]) for r in range(3)], axis=1)
    grouped = group_size[label] > 1
    codes, points = own.copy(), means.copy()
    if grouped.any():
        roots = np.unique(label[grouped])
        _, vectors = np.linalg.eigh(second[roots] - centroid[roots][:, :, None] * centroid[roots][:, None, :])
        group_code = np.zeros(size, dtype=np.uint8)
        group_code[roots] = normal_codes(vectors[:, :, 0])
        normal = normal_of(group_code[label])
        fits = grouped & (np.abs(np.sum((means - centroid[label]) * normal, axis=1)) <= MERGE_DISTANCE)
        codes = np.where(fits, group_code[label], own).astype(np.uint8)
        points = np.where(fits[:, None], centroid[label], means)
        grouped = fits
    refs = np.zeros(size, dtype=np.uint8)
    for ref in (3, 2, 1):  # the last written wins: z before y before x
        at = before[ref]
        ok = grouped & (at >= 0) & grouped[np.maximum(at, 0)] & (label[np.maximum(at, 0)] == label)
        refs[ok] = ref
    return refs, codes.astype(np.uint8), points


def concatenate(parts: list[PatchGeometry]) -> PatchGeometry:
    """One :class:`PatchGeometry` of several, in order."""
    return PatchGeometry(*(np.concatenate([getattr(p, name) for p in parts]) for name in
                           ("centres", "normals", "u", "v", "extents", "thickness", "trust")))


def _snap(fraction: FloatArray, levels: int, closed: bool = False) -> NDArray[np.uint8]:
    """Byte codes of fractions of a range on ``levels`` steps (``closed``: both ends are
    values, else the range wraps round)."""
    if closed:
        return np.round(np.round(np.clip(fraction, 0.0, 1.0) * (levels - 1)) * (255.0 / (levels - 1))).astype(np.uint8)
    return ((np.round(fraction * levels).astype(np.int64) % levels) * (256 // levels)).astype(np.uint8)


def trust_codes(trust: FloatArray) -> NDArray[np.uint8]:
    """Byte codes of trusts in [0, 1] on :data:`TRUST_LEVELS` steps, never 0."""
    step = 255 // (TRUST_LEVELS - 1)
    return np.clip(np.round(trust * (TRUST_LEVELS - 1)) * step, step, 255).astype(np.uint8)


def sorted_unique(keys: NDArray[np.int64]) -> NDArray[np.int64]:
    """``np.unique(keys)`` by a sort: numpy 2's hashing unique is 10-15 times slower on the
    millions of cell keys a run's rays cross."""
    ordered = np.sort(keys)
    return ordered[np.r_[True, ordered[1:] != ordered[:-1]]] if ordered.size else ordered


def counted_unique(keys: NDArray[np.int64], weights: NDArray[np.int64] | None = None
                   ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The distinct keys, sorted, and how many times (or the summed ``weights``) each occurs
    (by a sort, as :func:`sorted_unique`)."""
    if weights is None:  # a plain sort is several times faster than an argsort
        ordered = np.sort(keys)
        starts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]]) if ordered.size else ordered[:0]
        return ordered[starts], np.diff(np.r_[starts, ordered.size]).astype(np.int64)
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    if not ordered.size:
        return ordered, np.zeros(0, dtype=np.int64)
    starts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])
    return ordered[starts], np.add.reduceat(weights[order], starts)


def _walk(origins: FloatArray, direction: FloatArray, free_length: FloatArray,
          step: float) -> Iterator[tuple[NDArray[np.int64], FloatArray, tuple[FloatArray, FloatArray, FloatArray]]]:
    """Chunks of ``(ray, distance, (x, y, z))``: points every ``step`` along each ray's free
    part (the last within half a step of its end), one coordinate an array (a point is
    ``origin + distance * direction``, ``direction`` the rays' unit vectors: the same numbers
    as a ``(K, 3)`` array's)."""
    count = np.maximum(np.floor(free_length / step + 0.5).astype(np.int64), 0)
    total = np.cumsum(count)
    begin = 0
    while begin < count.size:
        reach = int(np.searchsorted(total, (total[begin - 1] if begin else 0) + CHUNK_SAMPLES, side="right"))
        end = max(reach, begin + 1)
        c = count[begin:end]
        # The chunk's rays' columns only (a copy of the run's would be 48 bytes a ray).
        local = np.repeat(np.arange(end - begin), c)
        k = np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c)
        t = (k + 0.5) * step
        x, y, z = (np.take(np.ascontiguousarray(origins[begin:end, a]), local)
                   + t * np.take(np.ascontiguousarray(direction[begin:end, a]), local) for a in range(3))
        yield local + begin, t, (x, y, z)
        begin = end


#: Boxes of at most this many cells find the patch cells a point lies in by a table, larger
#: ones by a search; those of at most ``DENSE_COUNTS`` chunks count the walk's points in a
#: dense array (a bincount a chunk), larger ones by sorting each chunk's keys.
DENSE_CELLS = 1 << 22
DENSE_COUNTS = 4


@dataclass
class _PatchCells:
    """Which patch of each level covers a cell of the finest box: the sorted fine keys any
    patch covers, and ``(len(keys), levels)`` the patch's index there per level (-1: none);
    ``dense`` (boxes of at most :data:`DENSE_CELLS`) the row of every fine key (-1: none)."""

    keys: NDArray[np.int64]
    index: NDArray[np.int64]
    dense: NDArray[np.int32] | None

    def rows(self, keys: NDArray[np.int64]) -> NDArray[np.int64]:
        """The row of each fine key, -1 where no patch covers it."""
        if self.dense is not None:
            return self.dense[keys].astype(np.int64)
        if not self.keys.size:
            return np.full(keys.shape, -1, dtype=np.int64)
        at = np.minimum(np.searchsorted(self.keys, keys), self.keys.size - 1)
        return np.where(self.keys[at] == keys, at, -1)


def _patch_cells(levels: list[PatchCodes], shapes: list[PatchGeometry], lo: NDArray[np.int64],
                 shape: tuple[int, int, int], resolution: float, reach: float) -> _PatchCells:
    """The fine cells each level's patches cover (a level-``l`` cell is ``8 ** l`` fine ones;
    those outside the fine box hold no walk point and are left out), and of a coarser level's
    only those whose middle lies within ``reach`` and half a fine cell's diagonal of the
    patch's plane: no point of the others is within ``reach`` of it."""
    fine_keys, level_of, patch_of = [], [], []
    for level, (codes, g) in enumerate(zip(levels, shapes)):
        if not len(codes):
            continue
        low, box = level_box(lo, shape, level)
        i, rest = np.divmod(codes.keys, box[1] * box[2])
        j, k = np.divmod(rest, box[2])
        corner = (np.column_stack([i, j, k]) + low) << level
        side = np.arange(1 << level)
        offsets = np.stack(np.meshgrid(side, side, side, indexing="ij"), axis=-1).reshape(-1, 3)
        fine = (corner[:, None, :] + offsets[None, :, :]).reshape(-1, 3)
        keys = index_keys(fine, lo, shape)
        patch = np.repeat(np.arange(len(codes)), offsets.shape[0])
        inside = keys >= 0
        if level:
            middle = (fine + 0.5) * resolution
            apart = np.abs(np.sum((middle - g.centres[patch]) * g.normals[patch], axis=1))
            inside &= apart <= (0.5 * math.sqrt(3.0) * resolution + reach) * (1.0 + 1e-6) + 1e-9
        fine_keys.append(keys[inside])
        level_of.append(np.full(int(inside.sum()), level, dtype=np.int64))
        patch_of.append(patch[inside])
    cells = int(shape[0]) * int(shape[1]) * int(shape[2])
    if not fine_keys:
        empty = np.zeros(0, dtype=np.int64)
        return _PatchCells(empty, np.zeros((0, len(levels)), dtype=np.int64),
                           np.full(cells, -1, dtype=np.int32) if cells <= DENSE_CELLS else None)
    every = np.concatenate(fine_keys)
    keys, row = np.unique(every, return_inverse=True)
    index = np.full((keys.size, len(levels)), -1, dtype=np.int64)
    index[row, np.concatenate(level_of)] = np.concatenate(patch_of)
    dense = None
    if cells <= DENSE_CELLS:
        dense = np.full(cells, -1, dtype=np.int32)
        dense[keys] = np.arange(keys.size, dtype=np.int32)
    return _PatchCells(keys, index, dense)


#: The walk's per-chunk cell counts are merged once they hold this many cells (or twice the
#: merged ones): memory of the cells crossed, a sort of them every so often.
MERGE_COUNTS = 1 << 22


def _merged(parts: list[tuple[NDArray[np.int64], NDArray[np.int64]]]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``(keys, counts)`` pairs as one: the distinct keys, sorted, and their summed counts."""
    if len(parts) == 1:
        return parts[0]
    return counted_unique(np.concatenate([k for k, _ in parts]), np.concatenate([c for _, c in parts]))


def free_cells_and_crossings(origins: FloatArray, direction: FloatArray, length: FloatArray, hits: NDArray[np.bool_],
                             levels: list[PatchCodes], lo: NDArray[np.int64], shape: tuple[int, int, int],
                             resolution: float, margin: float, extent: float = EXTENT
                             ) -> tuple[NDArray[np.int64], NDArray[np.int64], list[NDArray[np.int64]]]:
    """The sorted keys of the cells the rays crossed (a return's ray stops ``margin`` short of
    it; a free-only ray is free to its end), how many of the walk's points (every half cell
    along the rays) fell in each, and, per level and patch, how many rays went through its
    slab (level ``l``'s cells are ``2 ** l`` times the resolution).

    A ray goes through a slab where a walk point lies in the patch's cell, the next point
    (a step on, still short of the ray's return) lies on the other side of its plane, and
    the segment between them meets the plane within the patch's extent. Only the points in
    a patch's cell are looked at for that (found once for every level, :func:`_patch_cells`).
    The rays are their ``origins``, unit ``direction`` and ``length`` (as the build holds
    them: a run's rays are not copied again).
    """
    step = 0.5 * resolution
    free_length = np.where(hits, length - margin, length)
    boxes = [level_box(lo, shape, level) for level in range(len(levels))]
    shapes = [geometry(codes, box[0], box[1], resolution * (1 << level), extent)
              for level, (codes, box) in enumerate(zip(levels, boxes))]
    crossings = [np.zeros(len(codes), dtype=np.int64) for codes in levels]
    reach = step * (1.0 + 1e-6) + 1e-9
    centres = [[np.ascontiguousarray(g.centres[:, a]) for a in range(3)] for g in shapes]
    normals = [[np.ascontiguousarray(g.normals[:, a]) for a in range(3)] for g in shapes]
    covered = _patch_cells(levels, shapes, lo, shape, resolution, reach)
    cells = int(shape[0]) * int(shape[1]) * int(shape[2])
    dense = np.zeros(cells, dtype=np.int64) if cells <= min(DENSE_CELLS, DENSE_COUNTS * CHUNK_SAMPLES) else None
    free: list[tuple[NDArray[np.int64], NDArray[np.int64]]] = []
    pending = 0  # cells counted in the chunks since the last merge
    for ray, t, (x, y, z) in _walk(origins, direction, free_length, step):
        i = np.floor(x / resolution).astype(np.int64) - lo[0]
        j = np.floor(y / resolution).astype(np.int64) - lo[1]
        k = np.floor(z / resolution).astype(np.int64) - lo[2]
        keys = (i * shape[1] + j) * shape[2] + k
        if not (0 <= i.min() and i.max() < shape[0] and 0 <= j.min() and j.max() < shape[1]
                and 0 <= k.min() and k.max() < shape[2]):  # rounding at the box's edge
            inside = (i >= 0) & (i < shape[0]) & (j >= 0) & (j < shape[1]) & (k >= 0) & (k < shape[2])
            keys = np.where(inside, keys, -1)
        valid = keys if keys.min() >= 0 else keys[keys >= 0]
        if dense is not None:
            dense += np.bincount(valid, minlength=cells)
        else:
            free.append(counted_unique(valid))
            pending += free[-1][0].size
            if pending > max(MERGE_COUNTS, 2 * free[0][0].size):
                # Merged as they come, so that the cells held are about those crossed, not a
                # chunk's worth each (Seosan's 0.4 m walk: 470 chunks, 750 MB unmerged).
                free = [_merged(free)]
                pending = 0
        if not covered.keys.size:
            continue
        # A crossing is counted only where the next point is still short of the ray's return.
        rows = covered.rows(np.maximum(keys, 0))
        near = np.flatnonzero((rows >= 0) & (keys >= 0))
        near = near[t[near] + step <= free_length[ray[near]]]
        # One coordinate an array (the sums below in the order of a (K, 3) row's: x, y, z).
        point = (x[near], y[near], z[near])
        heading = list(direction[ray[near]].T)
        index = covered.index[rows[near]]
        for level, (codes, g, centre, normal) in enumerate(zip(levels, shapes, centres, normals)):
            if not len(codes):
                continue
            here = np.flatnonzero(index[:, level] >= 0)
            p = index[here, level]
            d0 = sum(((a[here] - np.take(c, p)) * np.take(m, p) for a, c, m in zip(point, centre, normal)),
                     start=np.zeros(here.size))
            # The next point is a step on: a point farther than that from the plane does not
            # cross it (the bound has room for rounding), and the rest need not be looked at.
            close = np.abs(d0) <= reach
            here, d0, p = here[close], d0[close], p[close]
            at = [a[here] for a in point]
            after = [a + step * d[here] for a, d in zip(at, heading)]
            d1 = sum(((a - np.take(c, p)) * np.take(m, p) for a, c, m in zip(after, centre, normal)),
                     start=np.zeros(here.size))
            through = (d0 * d1 < 0.0) & (np.minimum(np.abs(d0), np.abs(d1)) > 0.0)
            s = d0[through] / (d0[through] - d1[through])
            q = p[through]
            x0 = np.column_stack([a[through] for a in at])
            xs = x0 + s[:, None] * (np.column_stack([a[through] for a in after]) - x0) - g.centres[q]
            inside = ((np.abs(np.sum(xs * g.u[q], axis=1)) <= g.extents[q, 0])
                      & (np.abs(np.sum(xs * g.v[q], axis=1)) <= g.extents[q, 1]))
            crossings[level] += np.bincount(q[inside], minlength=len(codes))
    if dense is not None:
        keys = np.flatnonzero(dense)
        return keys.astype(np.int64), dense[keys], crossings
    if not free:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), crossings
    keys, counts = _merged(free)
    return keys, counts, crossings


__all__ = ["LEVELS", "fewest_returns", "PatchCodes", "PatchGeometry", "cell_keys", "concatenate", "fit_patches",
           "free_cells_and_crossings", "geometry", "index_keys", "key_corners", "level_box", "trust_codes"]
