"""Building the grid from features: rays, samples under the sensor model, the footprint prior."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.features import Features
from occtool.grid._grid import OccupancyGrid
from occtool.grid._logodds import OCTOMAP_DEFAULTS, LogOddsParams, logit
from occtool.grid._traverse import _SEGMENTS_PER_CHUNK, RaySegments, traverse
from occtool.robot import Robot
from occtool.sensor import SensorModel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


#: Largest dense grid :func:`build_grid` allocates (bytes of the log-odds array).
MAX_GRID_BYTES = 4 * 1024**3


def observation_log_odds(
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
            f"({n_bytes / 1e9:.1f} GB): use a coarser resolution="
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
        seg_log_odds = observation_log_odds(
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
