"""The OctoMap baseline, through the optional ``pyoctomap`` bindings (``occtool[octomap]``).

The features are inserted as point clouds from the sensor origin, as OctoMap's
``insertPointCloud`` does for a scan: every cell a ray crosses gets one miss update, the
cell holding its end point one hit update (OctoMap has no per-point evidence, so the
evidence values are not used, except that a feature with evidence 0 is a free ray). Floor
features and free rays follow the sensor model's handling (:func:`occtool.grid.ray_plan`),
as for the dense grid. The robot's footprint gets the same free prior as the
parametric model and the dense grid. :meth:`OctoMapModel.inverse_range` casts horizontal
rays with OctoMap's own ``castRay`` so the same navigation extraction applies; it reads
unobserved space (no node in the tree: ``search`` finds none) as free or, with
``unknown="occupied"``, as the dense grid does (:mod:`occtool.grid`): the ray also ends at
the first column with no node between the band's heights.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError, MissingDependencyError
from occtool.features import Features
from occtool.grid._build import floor_reach, footprint_cells, ray_plan
from occtool.grid._logodds import OCTOMAP_DEFAULTS, LogOddsParams, logit
from occtool.grid._traverse import traverse
from occtool.grid._unknown import band_layers, check_unknown, first_unobserved
from occtool.robot import Robot
from occtool.sensor import SensorModel

FloatArray = NDArray[np.float64]


def require_pyoctomap() -> Any:
    """The ``pyoctomap`` module, imported (it is optional: the ``octomap`` extra);
    :class:`~occtool.errors.MissingDependencyError` without it."""
    try:
        import pyoctomap
    except ImportError:
        raise MissingDependencyError("pyoctomap", "octomap", "The OctoMap baseline (octomap=True)") from None
    return pyoctomap


def octomap_available() -> bool:
    """Whether the optional ``pyoctomap`` bindings can be imported."""
    try:
        require_pyoctomap()
    except MissingDependencyError:
        return False
    return True


@dataclass(eq=False)
class OctoMapModel:
    """An OctoMap ``OcTree`` built from range features, with the queries occtool needs.

    Parameters
    ----------
    tree
        The ``pyoctomap.OcTree``.
    resolution
        Leaf edge length, metres.
    footprint
        Radius of the robot footprint the prior set free, metres (0: no prior); with
        ``unknown="occupied"`` the robot's disk counts as observed.
    """

    tree: Any
    resolution: float
    footprint: float = 0.0

    @property
    def memory_bytes(self) -> int:
        """OctoMap's own estimate of the tree's memory, ``memoryUsage()``, bytes."""
        return int(self.tree.memoryUsage())

    @property
    def leaf_count(self) -> int:
        return int(self.tree.getNumLeafNodes())

    def file_bytes(self) -> int:
        """Size of the tree saved in OctoMap's full ``.ot`` format (with log-odds), bytes.

        The compact ``.bt`` format is not used: ``writeBinary`` first turns the tree into a
        maximum-likelihood map in place, losing the probabilities the comparison queries.
        """
        fd, name = tempfile.mkstemp(suffix=".ot")
        os.close(fd)
        try:
            self.tree.write(name)
            return os.path.getsize(name)
        finally:
            os.unlink(name)

    def occupancy(self, points: ArrayLike) -> FloatArray:
        """Occupancy probability at ``(N, 3)`` points; 0.5 where OctoMap knows nothing.

        OctoMap offers only a per-point ``search``, so this loops over the points; it is
        used to score held-out data, not in a hot path.
        """
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        out = np.full(pts.shape[0], 0.5)
        search = self.tree.search
        for i, p in enumerate(pts):
            node = search(p)
            if node is not None:
                out[i] = node.getOccupancy()
        return out

    def observed_columns(
        self, band: tuple[float, float] | None = None, reach: float | None = None
    ) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
        """Which columns hold a node of the tree (an observed cell) between a band's heights.

        Parameters
        ----------
        band
            ``(low, high)`` sensor-frame heights, metres; the layers whose cells overlap it
            count (:func:`occtool.grid.band_layers`). Default: the tree's height extent.
        reach
            Half the edge of the square around the sensor axis to look in, metres
            (default: the tree's horizontal extent).

        Returns
        -------
        observed, offset
            ``(nx, ny)`` booleans and the lattice index ``(i, j)`` of ``observed[0, 0]``
            (OctoMap's keys less its centre key: cell ``i`` spans ``[i, i + 1) * resolution``).
        """
        res = self.resolution
        tree_min, tree_max = np.asarray(self.tree.getMetricMin()), np.asarray(self.tree.getMetricMax())
        if band is None:
            band = (float(tree_min[2]), float(tree_max[2]))
        k_lo, k_hi = band_layers(band, res)
        if reach is None:
            reach = float(np.abs(np.concatenate([tree_min[:2], tree_max[:2]])).max()) + res
        n = int(np.ceil(reach / res)) + 1
        offset = np.array([-n, -n], dtype=np.int64)
        observed = np.zeros((2 * n, 2 * n), dtype=bool)
        # Just inside the corner cells: OctoMap turns the box into keys by flooring.
        eps = 1e-6 * res
        lower = np.array([-n * res + eps, -n * res + eps, k_lo * res + eps])
        upper = np.array([n * res - eps, n * res - eps, (k_hi + 1) * res - eps])
        leaves = [(*leaf.getCoordinate(), leaf.getSize()) for leaf in self.tree.begin_leafs_bbx(lower, upper)]
        if not leaves:
            return observed, offset
        table = np.asarray(leaves, dtype=np.float64).reshape(-1, 4)
        half = 0.5 * table[:, 3:]
        # A leaf is a cube of 2^d cells (d > 0 where OctoMap pruned): the cells it spans.
        first = np.rint((table[:, :3] - half) / res).astype(np.int64)
        last = np.rint((table[:, :3] + half) / res).astype(np.int64) - 1
        keep = (last[:, 2] >= k_lo) & (first[:, 2] <= k_hi)
        first, last = first[keep, :2] - offset, last[keep, :2] - offset + 1
        single = ((last - first) == 1).all(axis=1)
        inside = single & ((first >= 0) & (first < observed.shape)).all(axis=1)
        observed[first[inside, 0], first[inside, 1]] = True
        for (i0, j0), (i1, j1) in zip(np.maximum(first[~single], 0), np.minimum(last[~single], observed.shape)):
            observed[i0:i1, j0:j1] = True
        return observed, offset

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

        Same contract as :meth:`occtool.grid.OccupancyGrid.inverse_range`: the 3D distance
        ``r`` to where the ray at ``(alpha, h)`` enters the first occupied leaf, ``inf`` when
        there is none within ``max_range`` (horizontal; by default the farthest corner of
        the tree's extent). With ``unknown="free"`` unknown space counts as free (OctoMap's
        ``castRay`` ignoring unknown cells), as the grid does for levels above 0.5.

        Parameters
        ----------
        alpha, h
            Pan angles (radians) and heights (metres), broadcast together.
        level
            Occupancy level in (0, 1).
        max_range
            Horizontal distance to search up to, metres.
        unknown
            ``"free"`` or ``"occupied"``: the ray also ends where it enters a column with no
            node of the tree between the ``band``'s heights (:meth:`observed_columns`), at
            every height ``h``, as for the dense grid; the robot's :attr:`footprint` counts
            as observed.
        band
            ``(low, high)`` sensor-frame heights whose nodes make a column observed, with
            ``unknown="occupied"``; default the tree's height extent.

        Returns
        -------
        numpy.ndarray
            ``r`` with the broadcast shape of ``alpha`` and ``h``.
        """
        if max_range is None:
            corners = np.abs(np.stack([self.tree.getMetricMin()[:2], self.tree.getMetricMax()[:2]]))
            max_range = float(np.hypot(corners[:, 0].max(), corners[:, 1].max())) + self.resolution
        if not (np.isfinite(max_range) and max_range > 0):
            raise InputError(f"max range must be a finite number > 0, got {max_range}")
        check_unknown(unknown)
        alpha_b, h_b = np.broadcast_arrays(np.asarray(alpha, dtype=np.float64), np.asarray(h, dtype=np.float64))
        shape = alpha_b.shape
        a = alpha_b.reshape(-1)
        hh = h_b.reshape(-1)
        distance = np.full(a.shape[0], np.inf)
        tree = self.tree
        saved = tree.getOccupancyThres()
        tree.setOccupancyThres(float(level))
        half = 0.5 * self.resolution
        end = np.zeros(3)
        try:
            for i in range(a.shape[0]):
                origin = np.array([0.0, 0.0, hh[i]])
                direction = np.array([np.cos(a[i]), np.sin(a[i]), 0.0])
                if tree.castRay(origin, direction, end, True, float(max_range)):
                    distance[i] = _entry_distance(direction[:2], end[:2], half)
        finally:
            tree.setOccupancyThres(saved)
        if unknown == "occupied":
            observed, offset = self.observed_columns(band, reach=float(max_range) + self.resolution)
            angles, angle_of = np.unique(a, return_inverse=True)
            unseen = first_unobserved(observed, offset, angles, float(max_range), self.resolution, self.footprint)
            distance = np.minimum(distance, unseen[angle_of.reshape(-1)])
        return np.sqrt(distance**2 + hh**2).reshape(shape)


def _entry_distance(direction: FloatArray, centre: FloatArray, half: float) -> float:
    """Distance along a horizontal ray from the sensor axis to where it enters a cell (slab test)."""
    entries = []
    for d, c in zip(direction, centre):
        if abs(d) > 1e-12:
            t1 = (c - half) / d
            t2 = (c + half) / d
            entries.append(min(t1, t2))
    return max(0.0, max(entries)) if entries else 0.0


def build_octomap(
    features: Features,
    *,
    resolution: float = 0.05,
    robot: Robot | None = None,
    params: LogOddsParams = OCTOMAP_DEFAULTS,
    footprint_prior: bool = True,
    scans: int = 1,
    sensor: SensorModel | None = None,
) -> OctoMapModel:
    """Insert features into an OctoMap ``OcTree`` from the sensor origin.

    Parameters
    ----------
    features
        Range features in the sensor-centred robot frame.
    resolution
        Leaf edge length, metres.
    robot
        The robot, for the footprint prior.
    params
        Hit/miss probabilities and clamping thresholds (OctoMap's defaults).
    footprint_prior
        Set the robot's footprint cylinder free (lower clamping threshold).
    scans
        Insert the features as this many scans, consecutive runs of features in the
        given (acquisition) order. OctoMap updates a cell at most once per scan, a hit
        winning over misses, so in one scan of noisy data a single outlier marks its
        cell occupied; a stereo sweep is really many views.
    sensor
        Its floor handling is applied as for the dense grid: with ``floor="free"`` the
        floor features clear the space in front of them (up to the last near sample)
        without marking a hit, inserted as extra scans grouped by that distance (OctoMap's
        ``max_range`` stops a ray short without a hit); ``"drop"`` leaves them out.
        ``None`` inserts every feature as a hit, as plain OctoMap does.

    Returns
    -------
    OctoMapModel

    Raises
    ------
    MissingDependencyError
        If ``pyoctomap`` is not installed.
    InputError
        If the resolution is not positive or there are no features.
    """
    pyoctomap = require_pyoctomap()
    if not (np.isfinite(resolution) and resolution > 0):
        raise InputError(f"OctoMap resolution must be a positive number of metres, got {resolution}")
    if len(features) == 0:
        raise InputError("cannot build an OctoMap from no features")
    robot = robot or Robot()
    tree = _new_tree(pyoctomap, resolution, params)
    for points, max_range in _insertions(features, robot, sensor, scans, resolution):
        tree.insertPointCloud(np.ascontiguousarray(points), np.zeros(3), max_range=max_range, lazy_eval=True)
    tree.updateInnerOccupancy()
    if footprint_prior:
        centres = (footprint_cells(robot, resolution) + 0.5) * resolution
        # A log-odds step far below the lower clamp: OctoMap clamps it to the free limit.
        free = float(logit(params.clamping_thres_min)) * 10.0
        tree.updateNodes(centres, free, lazy_eval=True)
        tree.updateInnerOccupancy()
    return OctoMapModel(
        tree=tree, resolution=float(resolution), footprint=float(robot.radius) if footprint_prior else 0.0
    )


def _new_tree(pyoctomap: Any, resolution: float, params: LogOddsParams) -> Any:
    tree = pyoctomap.OcTree(float(resolution))
    tree.setProbHit(params.prob_hit)
    tree.setProbMiss(params.prob_miss)
    tree.setClampingThresMin(params.clamping_thres_min)
    tree.setClampingThresMax(params.clamping_thres_max)
    tree.setOccupancyThres(params.occupancy_thres)
    return tree


def build_world_octomap(scans: Sequence[tuple[ArrayLike, ArrayLike, ArrayLike]], *, resolution: float = 0.05,
                        params: LogOddsParams = OCTOMAP_DEFAULTS) -> OctoMapModel:
    """An OctoMap of a run in the world frame: each scan inserted from its own sensor origin.

    ``scans`` holds, per scan, its sensor origin ``(3,)`` and its world end points
    ``(N, 3)`` with their evidence ``(N,)``. Returns (evidence > 0) are one
    ``insertPointCloud`` each scan (a miss on every cell its rays cross, a hit where they
    end); free rays (evidence 0, a beam that returned nothing) are a second one, cut one
    cell short of their end so they clear without a hit. No footprint prior.

    Raises
    ------
    MissingDependencyError
        If ``pyoctomap`` is not installed.
    InputError
        If the resolution is not positive.
    """
    pyoctomap = require_pyoctomap()
    if not (np.isfinite(resolution) and resolution > 0):
        raise InputError(f"OctoMap resolution must be a positive number of metres, got {resolution}")
    tree = _new_tree(pyoctomap, resolution, params)
    for origin, points, evidence in scans:
        origin = np.asarray(origin, dtype=np.float64).reshape(3)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        hit = np.asarray(evidence, dtype=np.float64).reshape(-1) > 0
        if hit.any():
            tree.insertPointCloud(np.ascontiguousarray(points[hit]), origin, max_range=-1.0, lazy_eval=True)
        if (~hit).any():
            free = points[~hit]
            # OctoMap cuts rays longer than max_range without a hit: one cut per scan, at its
            # shortest free ray less a cell (a laser's free rays share their length).
            length = float(np.linalg.norm(free - origin, axis=1).min()) - resolution
            if length > 0:
                tree.insertPointCloud(np.ascontiguousarray(free), origin, max_range=length, lazy_eval=True)
    tree.updateInnerOccupancy()
    return OctoMapModel(tree=tree, resolution=float(resolution), footprint=0.0)


def _insertions(
    features: Features, robot: Robot, sensor: SensorModel | None, scans: int, resolution: float
) -> list[tuple[FloatArray, float]]:
    """The ``(points, max_range)`` point clouds to insert, in order (``-1``: whole rays)."""
    if int(scans) != scans or scans < 1:
        raise InputError(f"the number of OctoMap scans must be a whole number >= 1, got {scans}")
    use, full = ray_plan(features, robot, sensor)
    points = features.points
    hits = points[use & full]
    # Only free rays (all floor, or beams that returned nothing): nothing to split.
    inserts = (
        [(part, -1.0) for part in np.array_split(hits, min(int(scans), len(hits))) if len(part)] if len(hits) else []
    )
    floor = points[use & ~full]
    if len(floor):
        r = np.sqrt(np.einsum("ij,ij->i", floor, floor))
        # Free up to the reach rounded down to whole cells, so no ray clears past it.
        steps = np.floor(r * floor_reach(sensor) / resolution).astype(np.int64)
        for step in np.unique(steps[steps > 0]):
            reach = float(step * resolution)
            chosen = steps == step
            beyond = floor[chosen] / r[chosen, None] * (reach + 2.0 * resolution)
            inserts.append((beyond, reach))
    return inserts


def octomap_updates(
    features: Features,
    resolution: float,
    scans: int = 1,
    *,
    robot: Robot | None = None,
    sensor: SensorModel | None = None,
) -> int:
    """Number of cell updates OctoMap makes for :func:`build_octomap` with the same arguments.

    ``insertPointCloud`` updates every distinct cell on a scan's rays once (a hit where
    an end point lies, a miss elsewhere). OctoMap does not report the count, so it is
    recounted here on the same lattice with :func:`occtool.grid.traverse`.
    """
    total = 0
    for points, max_range in _insertions(features, robot or Robot(), sensor, scans, resolution):
        if max_range > 0:
            points = points / np.linalg.norm(points, axis=1)[:, None] * max_range
        cells = []
        step = max(1, 2_000_000 // (int(np.abs(points / resolution).sum(axis=1).mean()) + 2))
        for lo in range(0, points.shape[0], step):
            seg = traverse(np.zeros(3), points[lo : lo + step], resolution)
            cells.append(np.unique(_cell_keys(seg.cell)))
        total += np.unique(np.concatenate(cells)).shape[0]
    return int(total)


def _cell_keys(cells: NDArray[np.int64]) -> NDArray[np.int64]:
    # One integer per cell (21 bits per index, as OctoMap's 16-bit keys fit): np.unique on
    # rows is much slower than on integers.
    offset = 1 << 20
    return ((cells[:, 0] + offset) << 42) | ((cells[:, 1] + offset) << 21) | (cells[:, 2] + offset)


__all__ = ["OctoMapModel", "build_octomap", "build_world_octomap", "octomap_available", "octomap_updates",
           "require_pyoctomap"]
