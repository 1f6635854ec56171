"""One world-frame occupancy map from the local models of a whole log.

occtool fits one small model per robot position, in that position's sensor-centred
frame. A local model only *speaks* where its position observed: at pan angles its rays
covered, in front of the first obstacle at that angle (plus the obstacle's own depth
window; a function increasing in range says nothing true behind it) and no farther than
its rays reached or the fit's focus range. :func:`observed_reach` records that, per pan
bin, as a few hundred bytes next to the model.

:class:`FusedMap` is the list of local trees, their poses and reaches (nothing else: no
grid), and answers occupancy queries at world points by combining every position that
observed the point:

* ``"log_odds"``: the models' occupancies, clamped as OctoMap clamps, added as log-odds;
* ``"dempster_shafer"``: each model gives masses ``occupied = c F``, ``free = c (1 - F)``,
  ``unknown = 1 - c``; Dempster's conjunctive rule combines them (as products of
  commonalities), the conflict mass flags positions that contradict each other, and the
  probability reported is the pignistic one;
* ``"mean"``: the plain mean of the speaking models.

Where no model speaks the place is *unknown* (never free). Each position also keeps its
nearest returns (its return guard, 720 bytes): :meth:`FusedMap.predict` joins them to the
models' occupancy, and :meth:`FusedMap.rasterise` draws the map as a free / occupied /
unknown grid over the robot's body band with its walls where the returns fall.
:func:`fuse_log` fits only the log's keyframes (:mod:`occtool.keyframes`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.features import Features, Pose, RangeLog
from occtool.keyframes import KEYFRAME_NEW_SHARE, select_keyframes
from occtool.robot import Robot

FloatArray = NDArray[np.float64]

#: Pan-angle bins of a model's reach (the fit's own first-obstacle bins, 3 degrees).
REACH_BINS = 120
#: Reaches are kept in whole centimetres (uint16: up to 655 m).
REACH_UNIT = 0.01
#: A bin's first-obstacle value where it saw none.
NO_OBSTACLE = int(np.iinfo(np.uint16).max)
#: A model's occupied reading more than this in front of its first obstacle (its crossing
#: placed short of the wall, a coarse piece) is not an observation: the model is silent there.
FRONT_MARGIN = 0.05
COMBINATIONS = ("log_odds", "dempster_shafer", "mean")
#: Measured on Intel (docs/map.md): the combination ``FusedMap`` uses unless told.
DEFAULT_COMBINATION = "log_odds"
#: OctoMap's clamping of a single observation's probability before it becomes log-odds.
CLAMP = (0.12, 0.97)
#: Share of a model's mass committed to occupied/free in the Dempster-Shafer combination.
DS_CONFIDENCE = 0.9
#: Conflict mass above which positions are said to contradict each other at a point.
CONFLICT_FLAG = 0.3
#: A raster cell is occupied where the positions whose returns fall in it make at least this
#: share of those that returned from it or saw through it (docs/map.md: 0.5 put 96.5 % of
#: the Intel returns on occupied cells and kept 86.5 % of the beams clear).
RETURN_SHARE = 0.5
#: Occupancy a position's return lends a query point at its spot, and the width (metres) of
#: that kernel, ``amplitude * exp(-(d / width)**2)``, joined to the models' fused occupancy
#: as a noisy-or (docs/map.md: AUC 0.954 -> 0.982 on Intel's held-out blocks).
RETURN_KERNEL = (0.8, 0.05)
#: Nav2 pixel values (trinary mode).
FREE, OCCUPIED, UNKNOWN = 254, 0, 205


def observed_reach(features: Features, robot: Robot, focus_range: float = math.inf,
                   bins: int = REACH_BINS, window: tuple[float, float] | None = None) -> NDArray[np.uint16]:
    """Per pan bin, how far a position observed, and its first obstacle.

    Returns ``(2, bins)`` uint16 centimetres: row 0 the reach, row 1 the first obstacle
    (:data:`NO_OBSTACLE` where none). The reach is

    the least of: the first obstacle's distance widened by its cluster window (the fit's
    :func:`occtool.fit.first_obstacle_distance`, as
    :func:`occtool.compare.in_front_of_first_obstacle` scores it), the farthest feature in
    the body band at that angle (a free ray reaches its end), and ``focus_range``. 0 where
    the position saw nothing.
    """
    from occtool.fit import (
        FOCUS_WINDOW,
        FOCUS_WINDOW_ABS,
        adaptive_support,
        angle_bins,
        first_obstacle_distance,
    )

    low, high = robot.body_band
    x, y, z = features.points.T
    band = (z >= low) & (z <= high)
    alpha = np.arctan2(y[band], x[band])
    distance = np.hypot(x[band], y[band])
    seen = np.zeros(bins)
    np.maximum.at(seen, angle_bins(alpha, bins), distance)
    hits = features.evidence[band] > 0
    limit = np.full(bins, np.inf)
    first = np.full(bins, np.inf)
    if hits.any():
        support, _ = adaptive_support(len(features))
        first = first_obstacle_distance(np.repeat(alpha[hits], 2), np.repeat(distance[hits], 2), bins, support)
        relative, absolute = window if window is not None else (FOCUS_WINDOW, FOCUS_WINDOW_ABS)
        limit = first * (1.0 + relative) + absolute
    reach = np.minimum(np.minimum(seen, limit), focus_range)
    return np.vstack([_centimetres(reach), _centimetres(first)])


def _centimetres(distance: FloatArray) -> NDArray[np.uint16]:
    return np.round(np.minimum(distance / REACH_UNIT, NO_OBSTACLE)).astype(np.uint16)


def reach_from_guard(guard: Any, focus_range: float = math.inf, bins: int = REACH_BINS) -> NDArray[np.uint16]:
    """A model file's reach when its features are gone: the return guard's nearest return
    per bin (widened by the cluster window); 0 (unobserved) where the guard holds none."""
    from occtool.fit import FOCUS_WINDOW, FOCUS_WINDOW_ABS

    if guard is None:
        return np.vstack([np.zeros(bins, dtype=np.uint16), np.full(bins, NO_OBSTACLE, dtype=np.uint16)])
    per = guard.bins // bins if guard.bins % bins == 0 else None
    if per is None:
        raise InputError(f"a guard of {guard.bins} bins does not split into {bins} reach bins")
    nearest = guard.distance.reshape(bins, per).min(axis=1)
    reach = np.where(np.isfinite(nearest), nearest * (1.0 + FOCUS_WINDOW) + FOCUS_WINDOW_ABS, 0.0)
    reach = np.minimum(reach, focus_range)
    return np.vstack([_centimetres(reach), _centimetres(nearest)])


def returns_from_guard(guard: Any) -> NDArray[np.uint16]:
    """A model's nearest returns per pan bin (its return guard: ``guard.bins`` whole
    millimetres, :data:`NO_OBSTACLE` where none or beyond 65 m); all none without a guard."""
    from occtool.guard import GUARD_BINS

    if guard is None:
        return np.full(GUARD_BINS, NO_OBSTACLE, dtype=np.uint16)
    distance = np.asarray(guard.distance, dtype=np.float64)
    millimetres = np.where(np.isfinite(distance), np.floor(distance * 1000.0 + 1e-6), NO_OBSTACLE)
    return np.minimum(millimetres, NO_OBSTACLE).astype(np.uint16)


def _nodes(node: Any) -> int:
    return 1 if isinstance(node, (int, np.integer)) else 1 + sum(_nodes(c) for c in node.children)


@dataclass
class Evidence:
    """The fused evidence at some points (arrays of one value per point).

    ``count``: models that speak there (0: unknown); ``probability``: the fused occupancy
    (0.5 where unknown); ``belief_occupied``, ``belief_free``, ``unknown_mass`` and
    ``conflict``: the normalised Dempster-Shafer masses and the conflict before
    normalising (plausibility of occupied = 1 - belief_free).
    """

    count: NDArray[np.int32]
    probability: FloatArray
    belief_occupied: FloatArray
    belief_free: FloatArray
    unknown_mass: FloatArray
    conflict: FloatArray

    @property
    def observed(self) -> NDArray[np.bool_]:
        return self.count > 0

    @property
    def contradicted(self) -> NDArray[np.bool_]:
        return self.conflict > CONFLICT_FLAG


@dataclass
class _Sums:
    """Per-point running sums over the models that speak there."""

    n: int
    count: NDArray[np.int32] = field(init=False)
    logit: FloatArray = field(init=False)
    total: FloatArray = field(init=False)
    log_q_occ: FloatArray = field(init=False)
    log_q_free: FloatArray = field(init=False)
    #: Per point, the occupancy the nearest return lends it (:data:`RETURN_KERNEL`); None: none.
    return_kernel: FloatArray | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        self.count = np.zeros(self.n, dtype=np.int32)
        self.logit = np.zeros(self.n)
        self.total = np.zeros(self.n)
        self.log_q_occ = np.zeros(self.n)
        self.log_q_free = np.zeros(self.n)

    def add(self, index: NDArray[np.intp], occupancy: FloatArray) -> None:
        # ``index`` holds each point at most once per model, so plain fancy += is exact.
        p = np.clip(occupancy, 0.0, 1.0)
        clamped = np.clip(p, *CLAMP)
        self.count[index] += 1
        self.logit[index] += np.log(clamped) - np.log1p(-clamped)
        self.total[index] += p
        unknown = 1.0 - DS_CONFIDENCE
        self.log_q_occ[index] += np.log(DS_CONFIDENCE * p + unknown)
        self.log_q_free[index] += np.log(DS_CONFIDENCE * (1.0 - p) + unknown)

    def evidence(self, combination: str) -> Evidence:
        count = self.count
        seen = count > 0
        # Conjunctive rule through commonalities: Q(A) multiplies over sources.
        q_unknown = np.where(seen, (1.0 - DS_CONFIDENCE) ** count.astype(np.float64), 1.0)
        q_occ = np.where(seen, np.exp(self.log_q_occ), 1.0)
        q_free = np.where(seen, np.exp(self.log_q_free), 1.0)
        m_occ = q_occ - q_unknown
        m_free = q_free - q_unknown
        conflict = np.clip(1.0 - m_occ - m_free - q_unknown, 0.0, 1.0)
        norm = np.maximum(1.0 - conflict, 1e-300)
        belief_occ, belief_free, unknown_mass = m_occ / norm, m_free / norm, q_unknown / norm
        if combination == "log_odds":
            from scipy.special import expit

            probability = expit(self.logit)
        elif combination == "dempster_shafer":
            probability = belief_occ + 0.5 * unknown_mass
        else:
            probability = self.total / np.maximum(count, 1)
        probability = np.where(seen, probability, 0.5)
        if self.return_kernel is not None:
            # Noisy-or: occupied if the models say so or a return lies there.
            probability = 1.0 - (1.0 - probability) * (1.0 - self.return_kernel)
        return Evidence(count, probability, belief_occ, belief_free, unknown_mass, conflict)


@dataclass
class Raster:
    """A free / occupied / unknown grid in the world (map) frame.

    ``cells`` is ``(ny, nx)`` uint8 with :data:`FREE`, :data:`OCCUPIED`, :data:`UNKNOWN`,
    row 0 at ``origin[1]`` (the bottom: y grows with the row); cell ``(j, i)`` spans
    ``origin + (i, j) * resolution`` to one resolution more. ``conflict`` marks cells where
    positions contradicted each other; ``probability`` is the fused occupancy (0.5 unknown).
    """

    cells: NDArray[np.uint8]
    resolution: float
    origin: tuple[float, float]
    probability: NDArray[np.float32]
    conflict: NDArray[np.bool_]

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.cells.shape[0]), int(self.cells.shape[1]))

    def cell_of(self, xy: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
        """Row, column and inside-flag of world ``(K, 2)`` points."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        col = np.floor((xy[:, 0] - self.origin[0]) / self.resolution).astype(np.intp)
        row = np.floor((xy[:, 1] - self.origin[1]) / self.resolution).astype(np.intp)
        inside = (row >= 0) & (row < self.shape[0]) & (col >= 0) & (col < self.shape[1])
        return np.clip(row, 0, self.shape[0] - 1), np.clip(col, 0, self.shape[1] - 1), inside

    def counts(self) -> dict[str, int]:
        return {"free": int((self.cells == FREE).sum()), "occupied": int((self.cells == OCCUPIED).sum()),
                "unknown": int((self.cells == UNKNOWN).sum()), "conflict": int(self.conflict.sum())}


class FusedMap:
    """A world-frame occupancy map made of local models, their poses and reaches.

    Parameters
    ----------
    trees
        The fitted min/max trees (``OccupancyRegressor.tree_``), one per position.
    poses
        Each tree's world pose (its sensor-centred frame).
    reaches
        ``(len(trees), 2, bins)`` uint16 centimetres from :func:`observed_reach` or
        :func:`reach_from_guard`: each model's reach and first obstacle per pan bin.
    robot
        The robot the trees were fitted for (its body band bounds where they speak).
    combination
        One of :data:`COMBINATIONS`.
    threshold
        Fused occupancy at or above which a cell is occupied (the extraction threshold).
    stamps
        Time of each position, seconds, if known.
    front_margin
        A model is silent where it reads occupied more than this (metres) in front of the
        first obstacle it saw at that pan bin (``inf``: never).
    returns
        ``(len(trees), guard bins)`` uint16 millimetres from :func:`returns_from_guard`:
        each position's nearest return per pan bin (its return guard). With them the
        raster's occupied cells are where the positions' returns fall (see
        :meth:`rasterise`); without, where the fused occupancy reaches ``threshold``.

    The trees' coefficients are kept as float32 (half the bytes; an occupancy moves by
    under 1e-6) and each tree is rebuilt in float64 for a query.
    """

    def __init__(self, trees: Sequence[Any], poses: Sequence[Pose], reaches: ArrayLike, robot: Robot, *,
                 combination: str = DEFAULT_COMBINATION, threshold: float = 0.6,
                 stamps: Sequence[float | None] | None = None, front_margin: float = FRONT_MARGIN,
                 returns: ArrayLike | None = None) -> None:
        if combination not in COMBINATIONS:
            raise InputError(f"combination must be one of {', '.join(COMBINATIONS)}, got {combination!r}")
        if not 0.0 < threshold < 1.0:
            raise InputError(f"threshold must lie strictly between 0 and 1, got {threshold}")
        reaches = np.asarray(reaches, dtype=np.uint16)
        if len(trees) == 0:
            raise InputError("a fused map needs at least one local model")
        if len(poses) != len(trees) or reaches.ndim != 3 or reaches.shape[:2] != (len(trees), 2):
            raise InputError(f"{len(trees)} models need as many poses and (2, bins) reach rows, got {len(poses)} "
                             f"and {reaches.shape}")
        if any(p is None for p in poses):
            raise InputError("every position needs a pose to be fused into a world map")
        if returns is not None:
            returns = np.asarray(returns, dtype=np.uint16)
            if returns.ndim != 2 or returns.shape[0] != len(trees) or returns.shape[1] < 8:
                raise InputError(f"{len(trees)} models need as many rows of returns per pan bin, got {returns.shape}")
        self.returns = returns
        self._basis = [t.basis for t in trees]
        self._roots = [t.root for t in trees]
        self._coefficients = [np.asarray(t.coefficients, dtype=np.float32) for t in trees]
        self.poses = list(poses)
        self.reaches = reaches
        self.robot = robot
        self.combination = combination
        self.threshold = float(threshold)
        self.front_margin = float(front_margin)
        self.stamps = list(stamps) if stamps is not None else [None] * len(trees)
        self._tree_type = type(trees[0])
        #: A k-d tree over every return in the world, built at the first query that needs it.
        self._return_index: Any = None
        self._pose_array = np.array([[p.x, p.y, p.z, p.yaw] for p in poses], dtype=np.float64)
        self._radius = reaches[:, 0].max(axis=1).astype(np.float64) * REACH_UNIT

    # ------------------------------------------------------------------ size
    @property
    def nbytes(self) -> int:
        """Memory of the map's numbers: each tree's float32 coefficients and structure (8 bytes
        a node, as :func:`occtool.compare.tree_bytes` counts it), poses, reaches, returns."""
        structure = sum(8 * _nodes(root) for root in self._roots)
        return int(sum(c.nbytes for c in self._coefficients) + structure + self._pose_array.nbytes
                   + self.reaches.nbytes + (self.returns.nbytes if self.returns is not None else 0))

    def tree(self, k: int) -> Any:
        """Model ``k``'s min/max tree (float64, from the stored float32 coefficients)."""
        return self._tree_type(self._basis[k], self._coefficients[k].astype(np.float64), self._roots[k])

    @property
    def trees(self) -> list[Any]:
        return [self.tree(k) for k in range(len(self))]

    def __len__(self) -> int:
        return len(self._roots)

    @property
    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """World ``(x, y)`` lower and upper corners of everything any model speaks about."""
        xy = self._pose_array[:, :2]
        return (xy - self._radius[:, None]).min(axis=0), (xy + self._radius[:, None]).max(axis=0)

    # ------------------------------------------------------------------ queries
    def _speak(self, k: int, points: FloatArray) -> tuple[NDArray[np.bool_], FloatArray]:
        """Which of ``points`` (world, ``(K, 3)``) model ``k`` speaks about, and its occupancy there."""
        x, y, z, yaw = self._pose_array[k]
        dx, dy = points[:, 0] - x, points[:, 1] - y
        c, s = math.cos(yaw), math.sin(yaw)
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        h = points[:, 2] - z
        alpha = np.arctan2(ly, lx)
        distance = np.hypot(lx, ly)
        bins = self.reaches.shape[2]
        b = np.clip(np.floor((alpha + math.pi) / (2.0 * math.pi) * bins).astype(np.intp), 0, bins - 1)
        low, high = self.robot.body_band
        speaks = (distance <= self.reaches[k, 0, b] * REACH_UNIT) & (h >= low - 1e-9) & (h <= high + 1e-9)
        if not speaks.any():
            return speaks, np.empty(0)
        index = np.flatnonzero(speaks)
        occupancy = self.tree(k).predict(alpha[index], h[index], np.hypot(distance[index], h[index]))
        # Occupied well in front of the first obstacle this position saw is the crossing's
        # margin, not something observed: leave that place to the other positions.
        first = self.reaches[k, 1, b[index]].astype(np.float64) * REACH_UNIT
        margin = (occupancy >= self.threshold) & (distance[index] < first - self.front_margin)
        if margin.any():
            speaks[index[margin]] = False
            occupancy = occupancy[~margin]
        return speaks, occupancy

    def evidence(self, points_world: ArrayLike, *, combination: str | None = None) -> Evidence:
        """The fused evidence at world points ``(K, 3)`` (x, y, z; z in the poses' height datum,
        so a 2D laser's plane is z = the poses' z)."""
        combination = combination or self.combination
        if combination not in COMBINATIONS:
            raise InputError(f"combination must be one of {', '.join(COMBINATIONS)}, got {combination!r}")
        return self._sums(points_world).evidence(combination)

    def _sums(self, points_world: ArrayLike) -> _Sums:
        """Every speaking model's occupancy at the points, summed for each combination."""
        from scipy.spatial import cKDTree

        points = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        if not np.isfinite(points).all():
            raise InputError("query points must be finite numbers")
        sums = _Sums(points.shape[0])
        if points.shape[0]:
            tree = cKDTree(points[:, :2])
            # A loop over models (hundreds), each vectorised over the points it may see.
            for k in range(len(self)):
                if self._radius[k] <= 0:
                    continue
                near = np.asarray(tree.query_ball_point(self._pose_array[k, :2], self._radius[k]), dtype=np.intp)
                if near.size == 0:
                    continue
                speaks, occupancy = self._speak(k, points[near])
                if speaks.any():
                    sums.add(near[speaks], occupancy)
            if self.returns is not None:
                sums.return_kernel = self._return_kernel(points)
        return sums

    def _return_kernel(self, points: FloatArray) -> FloatArray:
        """:data:`RETURN_KERNEL` of each point's horizontal distance to the nearest return of
        any position; 0 outside the body band (relative to the poses' median height)."""
        from scipy.spatial import cKDTree

        if self._return_index is None:
            world = [self.return_points(k) for k in range(len(self))]
            self._return_index = cKDTree(np.concatenate(world) if world else np.zeros((0, 2)))
        amplitude, width = RETURN_KERNEL
        kernel = np.zeros(points.shape[0])
        if self._return_index.n == 0:
            return kernel
        low, high = self.robot.body_band
        h = points[:, 2] - float(np.median(self._pose_array[:, 2]))
        band = (h >= low - 1e-9) & (h <= high + 1e-9)
        distance, _ = self._return_index.query(points[band, :2], distance_upper_bound=5.0 * width)
        kernel[band] = amplitude * np.exp(-np.square(np.asarray(distance) / width))
        return kernel

    def predict(self, points_world: ArrayLike, *, combination: str | None = None) -> FloatArray:
        """Fused occupancy probability at world points ``(K, 3)``; 0.5 where no position observed.

        With :attr:`returns`, the models' fused occupancy is joined (noisy-or) with the
        occupancy the positions' nearest returns lend a point near them (:data:`RETURN_KERNEL`)."""
        return self.evidence(points_world, combination=combination).probability

    # ------------------------------------------------------------------ raster
    def rasterise(self, resolution: float = 0.05, *, heights: ArrayLike | None = None,
                  combination: str | None = None, max_cells: int = 50_000_000,
                  from_returns: bool | None = None) -> Raster:
        """Free / occupied / unknown cells over the body band, in the world frame.

        Each cell centre is queried at ``heights`` (sensor-frame, relative to the poses'
        z; default: the sensor's plane if it lies in the body band, else the band's
        midpoint). Free where some height was observed and the cell is not occupied,
        unknown where no position observed it. Occupied, ``from_returns`` (the default
        when the map holds :attr:`returns`): where the positions' nearest returns fall,
        unless more positions saw through the cell than returned from it
        (:data:`RETURN_SHARE`): walls where the returns are, not where the models' level
        crossing sits (in front of them, by design); a cell the models read occupied is
        free only where some position saw through it, else unknown. Otherwise: occupied
        where any height's fused occupancy reaches the threshold.
        """
        if from_returns is None:
            from_returns = self.returns is not None
        if from_returns and self.returns is None:
            raise InputError("this fused map keeps no returns: rasterise it with from_returns=False")
        if not (math.isfinite(resolution) and resolution > 0):
            raise InputError(f"resolution must be a positive number of metres, got {resolution}")
        combination = combination or self.combination
        low, high = self.robot.body_band
        if heights is None:
            heights = [0.0] if low <= 0.0 <= high else [0.5 * (low + high)]
        heights = np.asarray(heights, dtype=np.float64).reshape(-1)
        lower, upper = self.bounds
        origin = np.floor(lower / resolution) * resolution
        nx, ny = (np.ceil((upper - origin) / resolution).astype(np.int64) + 1).tolist()
        if nx * ny * max(1, heights.size) > max_cells:
            raise InputError(f"a {resolution} m raster of the map needs {nx}x{ny} cells x {heights.size} heights: "
                             "use a coarser resolution")
        occupied = np.zeros(ny * nx, dtype=bool)
        observed = np.zeros(ny * nx, dtype=bool)
        conflict = np.zeros(ny * nx, dtype=bool)
        best = np.full(ny * nx, np.nan)
        z0 = float(np.median(self._pose_array[:, 2]))
        for h in heights:
            sums = _Sums(ny * nx)
            for k in range(len(self)):
                r = self._radius[k]
                if r <= 0:
                    continue
                x, y = self._pose_array[k, :2]
                i0 = max(0, math.floor((x - r - origin[0]) / resolution))
                i1 = min(nx - 1, math.floor((x + r - origin[0]) / resolution))
                j0 = max(0, math.floor((y - r - origin[1]) / resolution))
                j1 = min(ny - 1, math.floor((y + r - origin[1]) / resolution))
                jj, ii = np.mgrid[j0:j1 + 1, i0:i1 + 1]
                ii, jj = ii.ravel(), jj.ravel()
                pts = np.column_stack([origin[0] + (ii + 0.5) * resolution, origin[1] + (jj + 0.5) * resolution,
                                       np.full(ii.size, z0 + h)])
                # Heights are relative to each pose: a robot whose z varies keeps its band.
                pts[:, 2] += self._pose_array[k, 2] - z0
                speaks, occupancy = self._speak(k, pts)
                if speaks.any():
                    sums.add((jj * nx + ii)[speaks], occupancy)
            ev = sums.evidence(combination)
            occupied |= ev.observed & (ev.probability >= self.threshold)
            observed |= ev.observed
            conflict |= ev.contradicted
            best = np.where(ev.observed, np.fmax(best, ev.probability), best)
        if from_returns:
            hits, through = self._return_counts(origin, nx, ny, resolution)
            # Free: observed, and read free by the models or seen through by some position
            # (the crossing's margin in front of a wall); what the models read occupied and
            # no position saw through (behind a wall, within the reach's window) stays unknown.
            observed = (observed & ~occupied) | (through > 0) | (hits > 0)
            occupied = (hits > 0) & (hits >= RETURN_SHARE * (hits + through))
        cells = np.full(ny * nx, UNKNOWN, dtype=np.uint8)
        cells[observed] = FREE
        cells[occupied] = OCCUPIED
        return Raster(cells.reshape(ny, nx), float(resolution), (float(origin[0]), float(origin[1])),
                      np.nan_to_num(best, nan=0.5).reshape(ny, nx).astype(np.float32), conflict.reshape(ny, nx))


    def return_points(self, k: int) -> FloatArray:
        """World ``(M, 2)`` x, y of position ``k``'s nearest returns (bin centres)."""
        assert self.returns is not None
        millimetres = self.returns[k]
        bins = millimetres.size
        held = np.flatnonzero(millimetres != NO_OBSTACLE)
        alpha = -math.pi + (held + 0.5) * (2.0 * math.pi / bins)
        distance = millimetres[held].astype(np.float64) / 1000.0
        return self.poses[k].to_world(np.column_stack([distance * np.cos(alpha), distance * np.sin(alpha)]))

    def _return_counts(self, origin: FloatArray, nx: int, ny: int,
                       resolution: float) -> tuple[NDArray[np.int32], NDArray[np.int32]]:
        """Per raster cell: positions whose returns fall in it, and positions that saw
        through it (its centre lies more than a cell in front of their return at that pan bin)."""
        assert self.returns is not None
        hits = np.zeros(ny * nx, dtype=np.int32)
        through = np.zeros(ny * nx, dtype=np.int32)
        bins = self.returns.shape[1]
        for k in range(len(self)):  # a loop over positions, each vectorised over its cells
            millimetres = self.returns[k]
            held = millimetres != NO_OBSTACLE
            if not held.any():
                continue
            world = self.return_points(k)
            col = np.floor((world[:, 0] - origin[0]) / resolution).astype(np.int64)
            row = np.floor((world[:, 1] - origin[1]) / resolution).astype(np.int64)
            inside = (row >= 0) & (row < ny) & (col >= 0) & (col < nx)
            hits[np.unique(row[inside] * nx + col[inside])] += 1
            distance = np.where(held, millimetres.astype(np.float64) / 1000.0, -np.inf)
            r = float(distance.max())
            x, y, _, yaw = self._pose_array[k]
            i0 = max(0, math.floor((x - r - origin[0]) / resolution))
            i1 = min(nx - 1, math.floor((x + r - origin[0]) / resolution))
            j0 = max(0, math.floor((y - r - origin[1]) / resolution))
            j1 = min(ny - 1, math.floor((y + r - origin[1]) / resolution))
            jj, ii = np.mgrid[j0:j1 + 1, i0:i1 + 1]
            ii, jj = ii.ravel(), jj.ravel()
            dx = origin[0] + (ii + 0.5) * resolution - x
            dy = origin[1] + (jj + 0.5) * resolution - y
            c, s = math.cos(yaw), math.sin(yaw)
            lx, ly = c * dx + s * dy, -s * dx + c * dy
            b = np.clip(np.floor((np.arctan2(ly, lx) + math.pi) / (2.0 * math.pi) * bins).astype(np.intp), 0, bins - 1)
            seen_through = np.hypot(lx, ly) < distance[b] - resolution
            through[(jj * nx + ii)[seen_through]] += 1
        return hits, through


# ---------------------------------------------------------------------- building
@dataclass
class FuseReport:
    """What building a fused map took."""

    positions: int
    skipped: list[tuple[int, str]]
    fit_seconds: float
    fuse_seconds: float
    notes: list[str] = field(default_factory=list)
    #: The position index of each fitted model, in the models' order.
    fitted: list[int] = field(default_factory=list)
    #: Positions left out before fitting because earlier keyframes covered what they saw.
    not_keyframes: list[int] = field(default_factory=list)


def fuse_log(log: RangeLog, template: Any, *, combination: str = DEFAULT_COMBINATION, threshold: float = 0.6,
             progress: Callable[[int, int], None] | None = None,
             keyframe_share: float = KEYFRAME_NEW_SHARE) -> tuple[FusedMap, list[Any], FuseReport]:
    """Fit the keyframe positions of ``log`` with copies of ``template`` (an unfitted
    :class:`occtool.fit.OccupancyRegressor`) and fuse them.

    Keyframes (:func:`select_keyframes`): a position is fitted when at least
    ``keyframe_share`` of the cells its returns fall in are new; 0 fits every position.

    Positions without a pose cannot be placed and raise, unless the log is a single
    position without one (its frame becomes the map's, noted in the report); positions
    whose fit fails for their data (no usable features) are skipped and reported.

    Returns
    -------
    fused, models, report
        The :class:`FusedMap`, the fitted regressors (for their navigation maps) and a
        :class:`FuseReport`.
    """
    from occtool.errors import OcctoolError
    from occtool.fit import OccupancyRegressor

    notes = []
    positions = list(log.positions)
    missing = [p.index for p in positions if p.pose is None]
    if missing and len(positions) == 1:
        # One position and no pose (a log without any): its own frame is the map.
        positions = [replace(positions[0], pose=Pose())]
        notes.append("the log has no poses: its single position is the map frame's origin")
    elif missing:
        raise InputError(f"{log.source or 'the log'}: position {missing[0]} has no pose; a world map needs poses")
    params = template.get_params()
    robot = params.get("robot") or Robot()
    keep = select_keyframes(positions, robot, new_share=keyframe_share)
    not_keyframes = sorted(set(p.index for p in positions) - {positions[k].index for k in keep})
    positions = [positions[k] for k in keep]
    focus_range = params.get("focus_range", math.inf) if params.get("focus", True) else math.inf
    started = time.perf_counter()
    models, poses, reaches, returns, stamps, skipped = [], [], [], [], [], []
    fitted_positions: list[int] = []
    for done, item in enumerate(positions, start=1):
        try:
            model = OccupancyRegressor(**params).fit(item.features)
        except OcctoolError as exc:
            skipped.append((item.index, str(exc)))
            continue
        fitted_positions.append(item.index)
        models.append(model)
        poses.append(item.pose)
        stamps.append(item.stamp)
        reaches.append(observed_reach(item.features, robot, focus_range))
        returns.append(returns_from_guard(getattr(model, "guard_", None)))
        if progress is not None:
            progress(done, len(positions))
    fitted = time.perf_counter()
    if not models:
        raise InputError(f"{log.source or 'the log'}: no position could be fitted ({skipped[0][1]})")
    fused = FusedMap([m.tree_ for m in models], poses, np.stack(reaches), robot, combination=combination,  # type: ignore[arg-type]  # poses checked above
                     threshold=threshold, stamps=stamps, returns=np.stack(returns))
    report = FuseReport(len(models), skipped, fitted - started, time.perf_counter() - fitted, notes, fitted_positions,
                        not_keyframes)
    return fused, models, report


def fuse_models(models: Sequence[Any], poses: Sequence[Pose], *, reaches: ArrayLike | None = None,
                combination: str = DEFAULT_COMBINATION, threshold: float = 0.6,
                stamps: Sequence[float | None] | None = None) -> FusedMap:
    """Fuse fitted regressors (e.g. a model set read back) placed at ``poses``.

    Without ``reaches`` each model's reach comes from its return guard
    (:func:`reach_from_guard`): a model file does not keep its features, so directions
    where it saw no return stay unknown.
    """
    if not models:
        raise InputError("a fused map needs at least one local model")
    robot = models[0].robot_
    if reaches is None:
        reaches = np.stack([reach_from_guard(getattr(m, "guard_", None),
                                              m.focus_range if m.focus else math.inf) for m in models])
    returns = np.stack([returns_from_guard(getattr(m, "guard_", None)) for m in models])
    return FusedMap([m.tree_ for m in models], poses, reaches, robot, combination=combination, threshold=threshold,
                    stamps=stamps, returns=returns)


__all__ = [
    "COMBINATIONS",
    "DEFAULT_COMBINATION",
    "FREE",
    "OCCUPIED",
    "REACH_BINS",
    "UNKNOWN",
    "Evidence",
    "FuseReport",
    "FusedMap",
    "Raster",
    "fuse_log",
    "fuse_models",
    "observed_reach",
    "reach_from_guard",
    "returns_from_guard",
    "select_keyframes",
]
