"""The OctoMap baseline, through the optional ``pyoctomap`` bindings (``occtool[octomap]``).

The features are inserted as point clouds from the sensor origin, as OctoMap's
``insertPointCloud`` does for a scan: every cell a ray crosses gets one miss update, the
cell holding its end point one hit update (OctoMap has no per-point evidence, so the
evidence values are not used). Floor features follow the sensor model's floor handling,
as for the dense grid. The robot's footprint gets the same free prior as the
parametric model and the dense grid. :meth:`OctoMapModel.inverse_range` casts horizontal
rays with OctoMap's own ``castRay`` so the same navigation extraction applies.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError, MissingDependencyError
from occtool.features import Features
from occtool.grid import OCTOMAP_DEFAULTS, LogOddsParams, floor_reach, footprint_cells, logit, ray_plan, traverse
from occtool.robot import Robot
from occtool.sensor import SensorModel

FloatArray = NDArray[np.float64]


def _pyoctomap() -> Any:
    try:
        import pyoctomap
    except ImportError:
        raise MissingDependencyError("pyoctomap", "octomap", "The OctoMap baseline (--octomap)") from None
    return pyoctomap


def octomap_available() -> bool:
    """Whether the optional ``pyoctomap`` bindings can be imported."""
    try:
        _pyoctomap()
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
    """

    tree: Any
    resolution: float

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

    def inverse_range(
        self, alpha: ArrayLike, h: ArrayLike, level: float, max_range: float | None = None
    ) -> FloatArray:
        """Distance from the sensor to the first cell at or above ``level`` along horizontal rays.

        Same contract as :meth:`occtool.grid.OccupancyGrid.inverse_range`: the 3D distance
        ``r`` to where the ray at ``(alpha, h)`` enters the first occupied leaf, ``inf`` when
        there is none within ``max_range`` (horizontal; by default the farthest corner of
        the tree's extent). Unknown space counts as free (OctoMap's ``castRay`` ignoring
        unknown cells), as the grid does for levels above 0.5.

        Parameters
        ----------
        alpha, h
            Pan angles (radians) and heights (metres), broadcast together.
        level
            Occupancy level in (0, 1).
        max_range
            Horizontal distance to search up to, metres.

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
    pyoctomap = _pyoctomap()
    if not (np.isfinite(resolution) and resolution > 0):
        raise InputError(f"OctoMap resolution must be a positive number of metres, got {resolution}")
    if len(features) == 0:
        raise InputError("cannot build an OctoMap from no features")
    robot = robot or Robot()
    tree = pyoctomap.OcTree(float(resolution))
    tree.setProbHit(params.prob_hit)
    tree.setProbMiss(params.prob_miss)
    tree.setClampingThresMin(params.clamping_thres_min)
    tree.setClampingThresMax(params.clamping_thres_max)
    tree.setOccupancyThres(params.occupancy_thres)
    for points, max_range in _insertions(features, robot, sensor, scans, resolution):
        tree.insertPointCloud(np.ascontiguousarray(points), np.zeros(3), max_range=max_range, lazy_eval=True)
    tree.updateInnerOccupancy()
    if footprint_prior:
        centres = (footprint_cells(robot, resolution) + 0.5) * resolution
        # A log-odds step far below the lower clamp: OctoMap clamps it to the free limit.
        free = float(logit(params.clamping_thres_min)) * 10.0
        tree.updateNodes(centres, free, lazy_eval=True)
        tree.updateInnerOccupancy()
    return OctoMapModel(tree=tree, resolution=float(resolution))


def _insertions(
    features: Features, robot: Robot, sensor: SensorModel | None, scans: int, resolution: float
) -> list[tuple[FloatArray, float]]:
    """The ``(points, max_range)`` point clouds to insert, in order (``-1``: whole rays)."""
    if int(scans) != scans or scans < 1:
        raise InputError(f"the number of OctoMap scans must be a whole number >= 1, got {scans}")
    use, full = ray_plan(features, robot, sensor)
    points = features.points
    hits = points[use & full]
    inserts = [(part, -1.0) for part in np.array_split(hits, min(int(scans), len(hits))) if len(part)]
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
