"""The dense 3D occupancy grid baseline.

The grid is built the way grid methods sample the sensor model (the paper's Figure 3a):
every cell that a feature's ray crosses between the sensor and the feature gets one
sample. The rays are traversed with a 3D DDA written in numpy (all rays of a chunk at
once, no loop per cell), and the samples are fused per cell in log-odds with OctoMap's
parameters and defaults (:class:`LogOddsParams`).

Each sample is the sensor model's value ``v`` at the sample's distance along the ray,
turned into an observation probability between OctoMap's miss and hit probabilities,
``p = prob_miss + (prob_hit - prob_miss) * v``. With no sensor model (``sensor=None``)
``v`` is 1 in the cell holding the feature and 0 before it, which is OctoMap's own
hit/miss model; with a sensor model and evidence 1 the endpoint cell still gets
``prob_hit``. Log-odds are summed per cell and then clamped to OctoMap's clamping
thresholds (OctoMap clamps after every update, which for one batch of rays only differs
in the order the updates are applied).

The columns under the robot are never seen by its own sensor, so the cells of the
robot's footprint cylinder (its radius, over the body's height band) get the same prior
as the parametric model: free, at the lower clamping threshold.

:meth:`OccupancyGrid.inverse_range` inverts the grid the way the parametric model is
inverted: along a horizontal ray at height ``h``, the distance from the sensor to the
first cell whose occupancy reaches the level. The same navigation extraction then
applies to both.

Unobserved space (cells no sample reached, log-odds 0, probability 0.5) is read one of
two ways (:data:`UNKNOWN_SPACE`, ``inverse_range(..., unknown=...)``):

* ``"free"`` (the default): at its prior probability 0.5, so it is free for every level
  above 0.5 and blocking at or below;
* ``"occupied"``: as a careful planner reads it, the ray also ends where it enters a
  cell whose *column* is unobserved, a column counting as observed when any of its cells
  between the heights of a band (the robot's body band, in the comparison) received a
  sample (:meth:`OccupancyGrid.observed_columns`). Per column rather than per cell,
  because a planar laser observes only its own plane: per cell every other height of the
  body would be unknown and the navigation polygon would collapse (docs/comparison.md).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.features import Features
from occtool.robot import Robot
from occtool.sensor import SensorModel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Largest dense grid :func:`build_grid` allocates (bytes of the log-odds array).
MAX_GRID_BYTES = 4 * 1024**3

# Rays are traversed in chunks so that the segment arrays of one chunk stay near this size.
_SEGMENTS_PER_CHUNK = 2_000_000

#: The readings of unobserved space ``inverse_range`` offers (see the module docstring).
UNKNOWN_SPACE = ("free", "occupied")


def check_unknown(unknown: str) -> str:
    """``unknown`` if it is one of :data:`UNKNOWN_SPACE`; an :class:`InputError` otherwise."""
    if unknown not in UNKNOWN_SPACE:
        raise InputError(f"unobserved space must be read as 'free' or 'occupied', got {unknown!r}")
    return unknown


def footprint_columns_reached(columns: ArrayLike, radius: float, resolution: float) -> NDArray[np.bool_]:
    """Which ``(N, 2)`` global column indices come within half a cell of the disk of ``radius``
    around the sensor axis (their nearest point lies closer than ``radius + resolution / 2``)."""
    ij = np.asarray(columns, dtype=np.int64)
    # Nearest point of cell [i, i + 1) * resolution to 0, per axis.
    nearest = np.maximum(np.maximum(ij * resolution, -(ij + 1) * resolution), 0.0)
    return np.hypot(nearest[:, 0], nearest[:, 1]) < radius + 0.5 * resolution


def band_layers(band: tuple[float, float], resolution: float) -> tuple[int, int]:
    """First and last global lattice layer (z index) of the cells a height band touches.

    ``band`` is ``(low, high)`` in sensor-frame metres; the layers are those whose cells
    overlap it, ``floor(low / resolution)`` to ``floor(high / resolution)``, as for the
    footprint prior.
    """
    low, high = (float(v) for v in band)
    if not (np.isfinite(low) and np.isfinite(high) and low <= high):
        raise InputError(f"the observation band must be two finite heights, low <= high, got {band}")
    return int(np.floor(low / resolution)), int(np.floor(high / resolution))


def first_unobserved(
    observed: NDArray[np.bool_],
    offset: ArrayLike,
    angles: ArrayLike,
    max_range: float,
    resolution: float,
    footprint: float = 0.0,
) -> FloatArray:
    """Horizontal distance along rays from the sensor axis to the first unobserved column.

    Parameters
    ----------
    observed
        ``(nx, ny)`` boolean mask of the observed columns; columns outside it are unobserved.
    offset
        Global lattice index ``(i, j)`` of ``observed[0, 0]``.
    angles
        Pan angles of the rays, radians.
    max_range
        Length of the rays, metres.
    resolution
        Cell edge, metres.
    footprint
        Radius of the robot's footprint, metres (0: none). The robot stands on it, so
        every column that comes within half a cell of its disk counts as observed
        (:func:`footprint_columns_reached`): the cells the prior sets free only
        approximate the disk, and those it clips must not put the robot in collision.

    Returns
    -------
    numpy.ndarray
        The distance where each ray enters its first unobserved column (the same 2D walk
        as :meth:`OccupancyGrid.inverse_range`), ``inf`` if there is none within ``max_range``.
    """
    angles = np.asarray(angles, dtype=np.float64).reshape(-1)
    offset = np.asarray(offset, dtype=np.int64).reshape(-1)[:2]
    columns = np.asarray(observed.shape[:2])
    distance = np.full(angles.shape[0], np.inf)
    cells_per_ray = 2 * int(max_range / resolution) + 2
    for lo, hi in _chunks(angles.shape[0], max(1, _SEGMENTS_PER_CHUNK // cells_per_ray)):
        ends = np.column_stack(
            [max_range * np.cos(angles[lo:hi]), max_range * np.sin(angles[lo:hi]), np.zeros(hi - lo)]
        )
        seg = traverse(np.zeros(3), ends, resolution)
        ij = seg.cell[:, :2] - offset
        inside = ((ij >= 0) & (ij < columns)).all(axis=1)
        ij = np.clip(ij, 0, columns - 1)
        unseen = ~(inside & observed[ij[:, 0], ij[:, 1]])
        if footprint > 0:
            unseen &= ~footprint_columns_reached(seg.cell[:, :2], footprint, resolution)
        entry = np.where(unseen, seg.t_enter, np.inf)
        starts = np.flatnonzero(np.r_[True, seg.ray[1:] != seg.ray[:-1]])
        distance[lo + seg.ray[starts]] = np.minimum.reduceat(entry, starts) * max_range
    return distance


def logit(p: ArrayLike) -> FloatArray:
    """Log-odds ``log(p / (1 - p))`` of a probability."""
    p = np.asarray(p, dtype=np.float64)
    return np.log(p) - np.log1p(-p)


def probability(log_odds: ArrayLike) -> FloatArray:
    """Probability from log-odds (the inverse of :func:`logit`)."""
    return 1.0 / (1.0 + np.exp(-np.asarray(log_odds, dtype=np.float64)))


@dataclass(frozen=True)
class LogOddsParams:
    """Log-odds fusion parameters, named and defaulted as in OctoMap.

    Parameters
    ----------
    prob_hit
        Probability an observation in the cell holding a feature stands for (0.7).
    prob_miss
        Probability an observation in a cell the ray crosses stands for (0.4).
    clamping_thres_min, clamping_thres_max
        The fused probability is clamped to this interval (0.1192, 0.971), so that a cell
        can change its state again after many observations.
    occupancy_thres
        Probability at and above which OctoMap calls a cell occupied (0.5); occtool's
        navigation uses its own ``--threshold`` instead.
    """

    prob_hit: float = 0.7
    prob_miss: float = 0.4
    clamping_thres_min: float = 0.1192
    clamping_thres_max: float = 0.971
    occupancy_thres: float = 0.5

    def __post_init__(self) -> None:
        for name in ("prob_hit", "prob_miss", "clamping_thres_min", "clamping_thres_max", "occupancy_thres"):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise InputError(f"{name} must lie strictly between 0 and 1, got {value}")
        if not self.clamping_thres_min < self.clamping_thres_max:
            raise InputError("clamping_thres_min must be below clamping_thres_max")
        if not self.prob_miss < self.prob_hit:
            raise InputError("prob_miss must be below prob_hit")

    @property
    def clamp_log_odds(self) -> tuple[float, float]:
        """The clamping thresholds in log-odds."""
        return float(logit(self.clamping_thres_min)), float(logit(self.clamping_thres_max))


OCTOMAP_DEFAULTS = LogOddsParams()


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


def _chunks(n: int, size: int) -> list[tuple[int, int]]:
    return [(i, min(n, i + size)) for i in range(0, n, size)] or [(0, 0)]


def _observation_log_odds(
    segments: RaySegments,
    ranges: FloatArray,
    evidence: FloatArray,
    full_ray: NDArray[np.bool_],
    sensor: SensorModel | None,
    params: LogOddsParams,
) -> FloatArray:
    """Log-odds of each (ray, cell) sample under the sensor model.

    ``full_ray`` tells which rays run all the way to their feature; the others (floor
    features, which only say the space in front of them is free) stop short.
    """
    r = ranges[segments.ray]
    at_feature = segments.last & full_ray[segments.ray]
    if sensor is None:
        value = at_feature.astype(np.float64)
    else:
        # Sample at the middle of the ray's piece in the cell; the feature's own cell is
        # sampled at the feature, as OctoMap puts its hit there. Segment fractions are of
        # the traversed ray, which for a full ray is the feature's range.
        length = np.where(full_ray, 1.0, floor_reach(sensor))[segments.ray] * r
        s = np.where(at_feature, r, 0.5 * (segments.t_enter + segments.t_exit) * length)
        value = np.clip(np.asarray(sensor.ray_profile(r, evidence[segments.ray], s), dtype=np.float64), 0.0, 1.0)
    p = params.prob_miss + (params.prob_hit - params.prob_miss) * value
    return logit(p)


def floor_reach(sensor: SensorModel | None) -> float:
    """How far along its ray a floor feature still says "free", as a fraction of its range."""
    return 1.0 if sensor is None else float(max(sensor.near_positions))


def ray_plan(
    features: Features, robot: Robot, sensor: SensorModel | None
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Which features cast a ray, and which of those run it to the feature (as a hit).

    The sensor model treats floor features as it does for the parametric fit: ``"free"``
    keeps only the free space in front of them (up to the last near sample), ``"drop"``
    ignores them, ``"obstacle"`` uses them like any other.
    Features with evidence 0 (a beam that returned nothing) are free rays in every mode.
    """
    n = len(features)
    use = np.ones(n, dtype=bool)
    full = np.ones(n, dtype=bool)
    if sensor is not None:
        on_floor = np.asarray(sensor.is_floor(features.height, robot), dtype=bool)
        free_ray = np.asarray(sensor.is_free_ray(features, robot, on_floor=on_floor), dtype=bool)
        if sensor.floor == "drop":
            use &= ~on_floor | free_ray
        full &= ~free_ray
    return use, full


def footprint_cells(robot: Robot, resolution: float) -> IntArray:
    """Global lattice indices of the cells whose centres lie in the robot's footprint cylinder.

    The cylinder has the robot's radius and spans its body band (from the ground clearance
    to the top of the body, in sensor-frame heights); the cell holding the sensor axis is
    always included.
    """
    lo_h, hi_h = robot.body_band
    reach = int(np.ceil(robot.radius / resolution)) + 1
    k_lo = int(np.floor(lo_h / resolution))
    k_hi = int(np.floor(max(hi_h, lo_h) / resolution))
    i = np.arange(-reach, reach)
    k = np.arange(k_lo, k_hi + 1)
    gi, gj, gk = np.meshgrid(i, i, k, indexing="ij")
    centre_x = (gi + 0.5) * resolution
    centre_y = (gj + 0.5) * resolution
    # The sensor axis runs along a corner of four cells (centres res/sqrt(2) away): they
    # hold the robot itself whatever its radius.
    inside = np.hypot(centre_x, centre_y) <= max(robot.radius, resolution * 0.7072)
    return np.column_stack([gi[inside], gj[inside], gk[inside]]).astype(np.int64)


def _accumulate(flat: NDArray[np.float32], index: IntArray, values: FloatArray) -> None:
    """``flat[index] += values`` with repeated indices summed."""
    np.add.at(flat, index, values.astype(flat.dtype))


def build_grid(
    features: Features,
    *,
    resolution: float = 0.05,
    robot: Robot | None = None,
    sensor: SensorModel | None = None,
    params: LogOddsParams = OCTOMAP_DEFAULTS,
    footprint_prior: bool = True,
    bounds: tuple[ArrayLike, ArrayLike] | None = None,
    max_bytes: int = MAX_GRID_BYTES,
) -> OccupancyGrid:
    """Build a dense occupancy grid from features by sampling every crossed cell.

    Parameters
    ----------
    features
        Range features in the sensor-centred robot frame; the sensor is at the origin.
    resolution
        Cell edge length, metres.
    robot
        The robot, for the footprint prior (default :class:`~occtool.robot.Robot()`).
    sensor
        The sensor model giving the value along each ray (its ``ray_profile``) and the
        handling of floor features; ``None`` for OctoMap's hit/miss model, which treats
        every feature as an obstacle.
    params
        Log-odds parameters (OctoMap's defaults).
    footprint_prior
        Mark the robot's footprint cylinder free, as the parametric model's prior does.
    bounds
        ``(lower, upper)`` corners of the box the grid covers, metres; samples outside it
        are not stored. Default: the extent of the features, the sensor and the footprint.
    max_bytes
        Refuse grids whose log-odds array would be larger than this.

    Returns
    -------
    OccupancyGrid

    Raises
    ------
    InputError
        If the resolution is not positive, there are no features or the grid would be too big.
    """
    if not (np.isfinite(resolution) and resolution > 0):
        raise InputError(f"grid resolution must be a positive number of metres, got {resolution}")
    if len(features) == 0:
        raise InputError("cannot build a grid from no features")
    robot = robot or Robot()
    points = features.points
    foot = footprint_cells(robot, resolution) if footprint_prior else np.zeros((0, 3), dtype=np.int64)
    point_cells = np.floor(points / resolution).astype(np.int64)
    if bounds is None:
        extremes = np.vstack([point_cells.min(axis=0), point_cells.max(axis=0), np.zeros(3, dtype=np.int64)])
        if foot.size:
            extremes = np.vstack([extremes, foot.min(axis=0), foot.max(axis=0)])
    else:
        lower, upper = (np.asarray(b, dtype=np.float64).reshape(3) for b in bounds)
        if not (np.isfinite(lower).all() and np.isfinite(upper).all() and (upper > lower).all()):
            raise InputError(f"grid bounds must be finite with lower < upper, got {lower} and {upper}")
        extremes = np.floor(np.vstack([lower, upper]) / resolution).astype(np.int64)
    offset = extremes.min(axis=0)
    shape = extremes.max(axis=0) - offset + 1
    n_bytes = int(np.prod(shape.astype(np.float64))) * 4
    if n_bytes > max_bytes:
        raise InputError(
            f"a {resolution} m grid over the features' extent needs {shape[0]}x{shape[1]}x{shape[2]} cells "
            f"({n_bytes / 1e9:.1f} GB): use a coarser --resolution"
        )
    # Summed in float32 like OctoMap's log-odds; the array becomes the grid in place.
    flat = np.zeros(int(np.prod(shape)), dtype=np.float32)
    use, full = ray_plan(features, robot, sensor)
    ranges = features.range[use]
    evidence = features.evidence[use]
    full = full[use]
    ray_ends = points[use] * np.where(full, 1.0, floor_reach(sensor))[:, None]
    # Chunks sized by the cells their rays cross keep the temporary arrays bounded.
    cells_per_ray = np.abs(point_cells[use]).sum(axis=1) + 1
    cuts = np.searchsorted(
        np.cumsum(cells_per_ray), np.arange(1, cells_per_ray.sum() // _SEGMENTS_PER_CHUNK + 1) * _SEGMENTS_PER_CHUNK
    )
    edges = np.unique(np.concatenate([[0], cuts, [ranges.shape[0]]]))
    grid_shape = shape.astype(np.int64)
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    samples = 0
    for lo_ray, hi_ray in zip(edges[:-1], edges[1:]):
        seg = traverse(np.zeros(3), ray_ends[lo_ray:hi_ray], resolution)
        seg_log_odds = _observation_log_odds(
            seg, ranges[lo_ray:hi_ray], evidence[lo_ray:hi_ray], full[lo_ray:hi_ray], sensor, params
        )
        index = seg.cell - offset
        if bounds is not None:
            inside = ((index >= 0) & (index < grid_shape)).all(axis=1)
            index, seg_log_odds = index[inside], seg_log_odds[inside]
        _accumulate(flat, index @ strides, seg_log_odds)
        samples += int(index.shape[0])
    clamp_lo, clamp_hi = params.clamp_log_odds
    np.clip(flat, clamp_lo, clamp_hi, out=flat)
    if foot.size:
        index = foot - offset
        index = index[((index >= 0) & (index < grid_shape)).all(axis=1)]
        flat[index @ strides] = clamp_lo
    return OccupancyGrid(
        log_odds=flat.reshape(tuple(int(v) for v in shape)),
        resolution=float(resolution),
        offset=offset.astype(np.int64),
        samples=samples,
        params=params,
        footprint=float(robot.radius) if footprint_prior else 0.0,
    )

