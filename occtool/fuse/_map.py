"""The fused map itself: local trees, poses, reaches and returns, and its queries (its raster
is the world map's: :meth:`occtool.fuse.WorldMap.rasterise`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.features import Pose
from occtool.fuse._combine import COMBINATIONS, DEFAULT_COMBINATION, RETURN_KERNEL, Evidence, _Sums
from occtool.observation import NO_OBSTACLE, OFFSET_STEPS, REACH_UNIT
from occtool.robot import Robot

FloatArray = NDArray[np.float64]

#: A model's occupied reading more than this in front of its first obstacle (its crossing
#: placed short of the wall, a coarse piece) is not an observation: the model is silent there.
FRONT_MARGIN = 0.05


def _nodes(node: Any) -> int:
    return 1 if isinstance(node, (int, np.integer)) else 1 + sum(_nodes(c) for c in node.children)


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
        each position's nearest return per pan bin (its return guard): :meth:`predict`
        joins them, and the world map (:func:`build_world_map`, which needs them) fits its
        walls to them and draws its raster. :func:`fuse_log` keeps each bin's own nearest
        return instead (:func:`nearest_returns`), with ``return_offsets``.
    return_offsets
        ``(len(trees), guard bins)`` uint8: each return's pan angle within its bin, in
        :data:`OFFSET_STEPS` steps (:func:`nearest_returns`); without, the returns lie at
        the bins' centres (half a bin off at most).
    scanning_laser
        The positions are a scanning laser's (:func:`occtool.fuse.is_scanning_laser`): the
        world map's walls seen from one side fall steeply on that side.
    return_reach
        Returns farther than this from their position (metres; :func:`fuse_log`: the fit's
        focus range plus the robot's radius, the return guard's reach) lend no occupancy to
        :meth:`predict`: a far return's angle and its pose's error place it less surely (the
        world map's walls take them up to its own ``reach``).

    The trees' coefficients are kept as float32 (half the bytes; an occupancy moves by
    under 1e-6) and each tree is rebuilt in float64 for a query.
    """

    def __init__(self, trees: Sequence[Any], poses: Sequence[Pose], reaches: ArrayLike, robot: Robot, *,
                 combination: str = DEFAULT_COMBINATION, threshold: float = 0.6,
                 stamps: Sequence[float | None] | None = None, front_margin: float = FRONT_MARGIN,
                 returns: ArrayLike | None = None, return_offsets: ArrayLike | None = None,
                 return_reach: float = math.inf, scanning_laser: bool = False) -> None:
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
        if return_offsets is not None:
            return_offsets = np.asarray(return_offsets, dtype=np.uint8)
            if returns is None or return_offsets.shape != returns.shape:
                raise InputError(f"return offsets need returns of the same shape, got {return_offsets.shape}")
        self.returns = returns
        self.return_offsets = return_offsets
        if not return_reach > 0:
            raise InputError(f"return_reach must be a positive number of metres, got {return_reach}")
        self.return_reach = float(return_reach)
        self.scanning_laser = bool(scanning_laser)
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
        a node, as :func:`occtool.compare.tree_bytes` counts it), poses, reaches, returns and
        their offsets."""
        structure = sum(8 * _nodes(root) for root in self._roots)
        return int(sum(c.nbytes for c in self._coefficients) + structure + self._pose_array.nbytes
                   + self.reaches.nbytes + (self.returns.nbytes if self.returns is not None else 0)
                   + (self.return_offsets.nbytes if self.return_offsets is not None else 0))

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
            world = [self.return_points(k, within=self.return_reach) for k in range(len(self))]
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

    def return_points(self, k: int, within: float = math.inf) -> FloatArray:
        """World ``(M, 2)`` x, y of position ``k``'s nearest returns no farther than ``within``
        from it (at their own pan angles with :attr:`return_offsets`, else at the bins' centres)."""
        assert self.returns is not None
        millimetres = self.returns[k]
        bins = millimetres.size
        held = np.flatnonzero((millimetres != NO_OBSTACLE) & (millimetres.astype(np.float64) / 1000.0 <= within))
        within = (self.return_offsets[k, held] / OFFSET_STEPS if self.return_offsets is not None else 0.5)
        alpha = -math.pi + (held + within) * (2.0 * math.pi / bins)
        distance = millimetres[held].astype(np.float64) / 1000.0
        return self.poses[k].to_world(np.column_stack([distance * np.cos(alpha), distance * np.sin(alpha)]))
