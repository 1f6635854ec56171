"""The sensor model: how one range feature becomes regression samples.

Each feature registered at ``(alpha, h, r)`` with evidence ``m`` says two things: the
point itself is occupied with evidence ``m`` (up to the depth error), and the ray from
the sensor to it is free. Following the paper, a feature induces five samples on its
ray (points on the ray keep ``alpha`` and scale ``h`` and ``r`` by the same factor):

* two *hit* samples at ``r (1 - depth_error)`` and ``r (1 + depth_error)`` with value ``m``;
* two *near* samples at ``near_positions`` (fractions of ``r``) with ``near_values``
  (fractions of ``m``), because occupancy decreases towards the robot;
* one *robot* sample at the sensor (``r = 0``) with value 0.

Three further kinds of sample are occtool's own choices (see ``docs/method.md``):

* *floor* features (lower than the robot's ground clearance) are not obstacles: they keep
  their free near and robot samples but lose their hit samples (``floor="free"``); they can
  also be dropped altogether (``"drop"``) or treated as obstacles (``"obstacle"``);
* features with evidence exactly 0 are *free rays* whatever the floor handling: a laser
  beam that returned nothing within its range, written at that range, says its ray is free
  and nothing about an obstacle. Like floor features they keep only their near and robot
  samples (all of value 0), kind ``"floor"`` (free-ray samples);
* *footprint* samples with value 0 fill the robot's own body, which the sensor cannot see
  (the blind cone under its lowest tilt), so the fit cannot place an obstacle there;
* optional *background* samples with value 0 spread over the space with a small weight,
  the paper's remedy for featureless directions.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool._floor import lowest_layer
from occtool._stats import median
from occtool.errors import InputError
from occtool.features import FeatureGeometry, Features, wrap_angle
from occtool.limits import MAX_BODY_SAMPLES, MAX_DISTANCE
from occtool.robot import Robot

FloatArray = NDArray[np.float64]

#: Codes of :attr:`Samples.kind`.
#: alpha, h, r, m, weight and the sample kind (one for the block, or one per sample).
_SampleBlock = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, "int | NDArray[np.int64]"]
SAMPLE_KINDS: dict[str, int] = {"hit": 0, "near": 1, "robot": 2, "floor": 3, "footprint": 4, "background": 5, "frontier": 6}

FLOOR_MODES = ("free", "drop", "obstacle")


class SampleBlock:
    """Samples of one origin (:meth:`SensorModel._sample_blocks`): pan angle, height and
    range per sample; value, weight and kind per sample or one for the whole block."""

    # A plain class, not a dataclass: each dataclass made was about 1 ms of a fresh
    # process's import, for a record only the fit builds and reads.
    __slots__ = ("alpha", "h", "r", "m", "weight", "kind")

    def __init__(self, alpha: FloatArray, h: FloatArray, r: FloatArray, m: FloatArray | float,
                 weight: FloatArray | float, kind: NDArray[np.integer[Any]] | int) -> None:
        self.alpha, self.h, self.r, self.m, self.weight, self.kind = alpha, h, r, m, weight, kind

    def __len__(self) -> int:
        return int(self.alpha.shape[0])

    def count(self, code: int) -> int:
        """Samples of the kind ``code`` (:data:`SAMPLE_KINDS`)."""
        if np.ndim(self.kind) == 0:
            return len(self) if int(self.kind) == code else 0
        return int(np.count_nonzero(self.kind == code))

    def columns(self) -> tuple[Any, ...]:
        """``alpha, h, r, m, weight, kind``, each an array or one value for the block."""
        return self.alpha, self.h, self.r, self.m, self.weight, self.kind


@dataclass(frozen=True, eq=False)
class Samples:
    """Regression samples ``m = F(alpha, h, r)`` produced by a :class:`SensorModel`.

    Attributes
    ----------
    alpha, h, r, m
        Pan angle (rad), sensor-frame height (m), distance from the sensor (m) and target
        occupancy value, all ``(n,)``.
    weight
        ``(n,)`` regression weight of each sample.
    kind
        ``(n,)`` integer code of the sample's origin, see :data:`SAMPLE_KINDS`.
    """

    alpha: FloatArray
    h: FloatArray
    r: FloatArray
    m: FloatArray
    weight: FloatArray
    kind: NDArray[np.int8]

    def __len__(self) -> int:
        return int(self.m.shape[0])

    def select(self, mask: ArrayLike) -> Samples:
        """The samples where ``mask`` is true."""
        index = np.asarray(mask)
        return Samples(
            self.alpha[index], self.h[index], self.r[index], self.m[index], self.weight[index], self.kind[index]
        )

    def count(self, kind: str) -> int:
        """Number of samples of one kind (``"hit"``, ``"near"``, ...)."""
        return int(np.count_nonzero(self.kind == SAMPLE_KINDS[kind]))

    @classmethod
    def of_blocks(cls, blocks: list[SampleBlock]) -> Samples:
        """The samples of ``blocks`` one after another."""
        total = sum(len(block) for block in blocks)
        # Each block is written into its slice of the columns: concatenating the blocks
        # took a third of the samples' time at a million features (2.5 GB of copies).
        alpha, h, r, m, weight = (np.empty(total) for _ in range(5))
        kind = np.empty(total, dtype=np.int8)
        columns: tuple[NDArray[Any], ...] = (alpha, h, r, m, weight, kind)
        start = 0
        for block in blocks:
            part = slice(start, start + len(block))
            for column, values in zip(columns, block.columns()):
                column[part] = values
            start = part.stop
        return cls(alpha, h, r, m, weight, kind)


@dataclass(frozen=True)
class SensorModel:
    """Parameters turning features into samples (the paper's "sensor model").

    The defaults were chosen by measurement on the synthetic scenes (``docs/method.md``).

    Parameters
    ----------
    depth_error
        Relative depth error: the two hit samples lie at ``r (1 -+ depth_error)``.
    near_positions
        Positions of the two near samples as fractions of the feature's range, in (0, 1).
        Closer to 1 lets the model show more free space in front of obstacles.
    near_values
        Values of the near samples as fractions of the feature's evidence, in [0, 1).
        Below the extraction threshold, so the space in front of a feature reads free.
    floor
        How floor features (lower than the robot's ground clearance) are used: ``"free"``
        keeps only their free-space samples, ``"drop"`` ignores them, ``"obstacle"`` treats
        them like any other feature (the floor then shrinks the navigation area). Features
        with evidence 0 are free rays in every mode (:meth:`is_free_ray`).
    footprint_samples
        Number of zero-value samples filling the robot's body cylinder (0: none).
    footprint_weight
        Weight of each footprint sample.
    background_samples
        Number of zero-value background samples spread uniformly over pan angle, the body's
        height band and range up to ``background_range`` (0: none, the default).
    background_weight
        Weight of each background sample; small, so features always win.
    background_range
        Largest range of the background samples, metres.
    """

    depth_error: float = 0.03
    near_positions: tuple[float, float] = (0.8, 0.9)
    near_values: tuple[float, float] = (0.2, 0.4)
    floor: str = "free"
    footprint_samples: int = 512
    footprint_weight: float = 1.0
    background_samples: int = 0
    background_weight: float = 0.05
    background_range: float = 3.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "near_positions", tuple(float(v) for v in self.near_positions))
        object.__setattr__(self, "near_values", tuple(float(v) for v in self.near_values))
        if not (np.isfinite(self.depth_error) and 0.0 <= self.depth_error < 0.5):
            raise InputError(f"depth error must lie in [0, 0.5), got {self.depth_error}")
        if len(self.near_positions) != 2 or len(self.near_values) != 2:
            raise InputError("the sensor model has exactly two near positions and two near values")
        for p in self.near_positions:
            if not (np.isfinite(p) and 0.0 < p < 1.0 - self.depth_error):
                raise InputError(
                    f"near positions must lie in (0, 1 - depth error) = (0, {1.0 - self.depth_error:g}), got {p}"
                )
        for v in self.near_values:
            if not (np.isfinite(v) and 0.0 <= v < 1.0):
                raise InputError(f"near values must lie in [0, 1) (fractions of the evidence), got {v}")
        if self.near_positions[0] > self.near_positions[1] or self.near_values[0] > self.near_values[1]:
            raise InputError("near positions and near values must be given in increasing order")
        if self.floor not in FLOOR_MODES:
            raise InputError(f"floor handling must be one of {', '.join(FLOOR_MODES)}, got {self.floor!r}")
        for name in ("footprint_samples", "background_samples"):
            value = getattr(self, name)
            if int(value) != value or value < 0:
                raise InputError(f"{name.replace('_', ' ')} must be a whole number >= 0, got {value}")
            if value > MAX_BODY_SAMPLES:
                raise InputError(f"{name} must be at most {MAX_BODY_SAMPLES:,}, got {value:,}")
            object.__setattr__(self, name, int(value))
        for name in ("footprint_weight", "background_weight", "background_range"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0.0):
                raise InputError(f"{name.replace('_', ' ')} must be a positive number, got {value}")
            if name == "background_range" and value > MAX_DISTANCE:
                raise InputError(f"background_range must be at most {MAX_DISTANCE:g} m, got {value}")
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict:
        """The parameters as a JSON-ready dict."""
        data = asdict(self)
        data["near_positions"] = list(self.near_positions)
        data["near_values"] = list(self.near_values)
        return data

    @classmethod
    def from_dict(cls, data: dict) -> SensorModel:
        """Rebuild from :meth:`to_dict`; unknown keys are an :class:`InputError`."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise InputError(f"unknown sensor model settings: {', '.join(unknown)}")
        return cls(**data)

    # ------------------------------------------------------------------ the model
    def ray_profile(self, r_feature: ArrayLike, m: ArrayLike, s: ArrayLike) -> FloatArray:
        """The sensor model's value at distance ``s`` along the ray of a feature.

        The profile runs linearly through the samples a feature induces: 0 at the sensor,
        the near values at the near positions, ``m`` from ``r (1 - depth_error)`` to
        ``r (1 + depth_error)``. Beyond that the ray says nothing, and the value is NaN.

        Parameters
        ----------
        r_feature
            Range of the feature, metres (> 0).
        m
            Evidence of the feature.
        s
            Distance along the ray from the sensor, metres. All three broadcast together.

        Returns
        -------
        numpy.ndarray
            The profile value, broadcast shape of the inputs.

        Examples
        --------
        >>> SensorModel().ray_profile(2.0, 1.0, [0.0, 1.0, 2.0, 3.0])
        array([0.   , 0.125, 1.   ,   nan])
        """
        r_feature, m, s = np.broadcast_arrays(
            np.asarray(r_feature, dtype=np.float64), np.asarray(m, dtype=np.float64), np.asarray(s, dtype=np.float64)
        )
        t = np.divide(s, r_feature, out=np.full(s.shape, np.inf), where=r_feature > 0)
        (p1, p2), (v1, v2) = self.near_positions, self.near_values
        knots = np.array([0.0, p1, p2, 1.0 - self.depth_error, 1.0 + self.depth_error])
        fractions = np.array([0.0, v1, v2, 1.0, 1.0])
        value = np.interp(np.clip(t, 0.0, knots[-1]), knots, fractions) * m
        return np.where((t > knots[-1]) | (s < 0), np.nan, value)

    def samples(self, features: Features, robot: Robot | None = None, rng: np.random.Generator | None = None) -> Samples:
        """The regression samples for a set of features.

        Parameters
        ----------
        features
            Features in the sensor-centred robot frame.
        robot
            The robot (sensor height, clearance, radius); ``Robot()`` if omitted.
        rng
            Random generator for the background samples; a fixed seed if omitted, so the
            samples are deterministic either way. Footprint samples are on a fixed lattice.

        Returns
        -------
        Samples
            Hit, near and robot samples per obstacle feature, the free samples of floor
            features, footprint and background samples.
        """
        return self._samples(features, robot, rng)

    def _samples(self, features: Features, robot: Robot | None = None, rng: np.random.Generator | None = None,
                 turn: float | None = None, geometry: FeatureGeometry | None = None) -> Samples:
        """:meth:`samples`; with ``turn``, pan angles measured from ``turn``
        (``wrap_angle(alpha - turn)``), turned a feature at a time rather than a sample;
        ``geometry``: the features' :class:`~occtool.features.FeatureGeometry`, when a
        caller holds it already."""
        return Samples.of_blocks(self._sample_blocks(features, robot, rng, turn=turn, geometry=geometry))

    def _sample_blocks(self, features: Features, robot: Robot | None = None,
                       rng: np.random.Generator | None = None, *, turn: float | None = None,
                       geometry: FeatureGeometry | None = None) -> list[SampleBlock]:
        """The samples of :meth:`_samples` as blocks of one origin each, in the columns'
        order: hits at ``r (1 - depth_error)``, at ``r (1 + depth_error)``, the two near
        samples, the robot samples, footprint and background. A caller that keeps only
        some samples (the fit's focus) writes those alone, not every sample twice."""
        robot = Robot() if robot is None else robot
        geometry = FeatureGeometry.of(features) if geometry is None else geometry
        alpha, h, r = geometry.polar()
        if turn is not None:
            alpha = geometry.turned(turn)
        m = features.evidence
        on_floor = self.is_floor(h, robot)
        # A feature inside the robot's own body cylinder is the robot itself (a self-hit)
        # or a mismatch: no obstacle can stand there. Two such mismatches a few centimetres
        # apart once made the robot "in collision where it stands" (office, 7k features).
        on_robot = self.is_on_robot(features, robot, geometry=geometry)
        free_only = self.is_free_ray(features, robot, on_floor=on_floor) & ~on_robot
        obstacle = ~(on_floor & (self.floor == "drop")) & ~free_only & ~on_robot
        rays = obstacle | free_only

        e = self.depth_error
        # Indices once, then takes: a boolean index scans its mask again for every array.
        obstacle_index, ray_index = np.flatnonzero(obstacle), np.flatnonzero(rays)
        a_obs, h_obs, r_obs, m_obs = (v.take(obstacle_index) for v in (alpha, h, r, m))
        a_ray, h_ray, r_ray, m_ray = (v.take(ray_index) for v in (alpha, h, r, m))
        blocks = [SampleBlock(a_obs, h_obs * scale, r_obs * scale, m_obs, 1.0, SAMPLE_KINDS["hit"])
                  for scale in (1.0 - e, 1.0 + e)]
        near_kind = np.where(free_only.take(ray_index), SAMPLE_KINDS["floor"], SAMPLE_KINDS["near"]).astype(np.int8)
        blocks += [SampleBlock(a_ray, h_ray * position, r_ray * position, m_ray * value, 1.0, near_kind)
                   for position, value in zip(self.near_positions, self.near_values)]
        at_sensor = np.zeros(a_ray.size)
        blocks.append(SampleBlock(a_ray, at_sensor, at_sensor, 0.0, 1.0, SAMPLE_KINDS["robot"]))
        extra: list[_SampleBlock] = []
        if self.footprint_samples:
            extra.append(self._footprint(robot))
        if self.background_samples:
            extra.append(self._background(robot, np.random.default_rng(0) if rng is None else rng))
        if turn is not None:
            extra = [(wrap_angle(block[0] - turn), *block[1:]) for block in extra]
        blocks += [SampleBlock(*block) for block in extra]
        return blocks

    def is_on_robot(self, features: Features, robot: Robot, *,
                    geometry: FeatureGeometry | None = None) -> NDArray[np.bool_]:
        """Whether features lie inside the robot's body cylinder (radius, floor to top)
        (``geometry``: the features' :class:`~occtool.features.FeatureGeometry`, if held)."""
        horizontal = (geometry if geometry is not None else FeatureGeometry.of(features)).horizontal
        z = features.points[:, 2]
        return (horizontal < robot.radius) & (z >= robot.floor_h) & (z <= robot.body_band[1])

    def is_free_ray(self, features: Features, robot: Robot,
                    on_floor: NDArray[np.bool_] | None = None) -> NDArray[np.bool_]:
        """Features that only say their ray is free: evidence 0, and floor features with
        ``floor="free"``. They give free-space samples and no hit."""
        if on_floor is None:
            on_floor = self.is_floor(features.points[:, 2], robot)
        return (features.evidence == 0) | (on_floor & (self.floor == "free"))

    def is_obstacle(self, features: Features, robot: Robot, *,
                    geometry: FeatureGeometry | None = None) -> NDArray[np.bool_]:
        """Features that give hit samples: not free rays, not dropped floor, not self-hits
        (``geometry``: the features' :class:`~occtool.features.FeatureGeometry`, if held)."""
        on_floor = self.is_floor(features.points[:, 2], robot)
        dropped = on_floor & (self.floor == "drop")
        return ~dropped & ~self.is_free_ray(features, robot, on_floor=on_floor) & ~self.is_on_robot(
            features, robot, geometry=geometry)

    def is_floor(self, h: ArrayLike, robot: Robot) -> NDArray[np.bool_]:
        """Whether features at sensor-frame heights ``h`` lie below the ground clearance."""
        return np.asarray(h, dtype=np.float64) < robot.floor_h + robot.ground_clearance

    def _footprint(self, robot: Robot) -> _SampleBlock:
        # A fixed lattice over the body cylinder (angle x height x radius), so the
        # samples are identical for every run and the body is covered evenly.
        n = self.footprint_samples
        n_heights = 4
        n_radii = 2
        n_angles = max(1, -(-n // (n_heights * n_radii)))
        low, high = robot.body_band[0], max(robot.body_band[1], 0.0)
        angles = -np.pi + (np.arange(n_angles) + 0.5) * (2.0 * np.pi / n_angles)
        heights = np.linspace(low, high, n_heights)
        radii = robot.radius * np.array([0.5, 1.0])
        A, H, D = np.meshgrid(angles, heights, radii, indexing="ij")
        A, H, D = A.ravel()[:n], H.ravel()[:n], D.ravel()[:n]
        R = np.hypot(D, H)
        return (A, H, R, np.zeros_like(R), np.full_like(R, self.footprint_weight), SAMPLE_KINDS["footprint"])

    def _background(self, robot: Robot, rng: np.random.Generator) -> _SampleBlock:
        n = self.background_samples
        low, high = robot.body_band
        angles = rng.uniform(-np.pi, np.pi, n)
        heights = rng.uniform(low, high, n)
        horizontal = self.background_range * np.sqrt(rng.uniform(0.0, 1.0, n))
        R = np.hypot(horizontal, heights)
        return (angles, heights, R, np.zeros(n), np.full(n, self.background_weight), SAMPLE_KINDS["background"])


# --- does the data fit the robot's geometry? ----------------------------------------------

#: Returns within this height (metres) of the body band's edge count as "at the edge".
BAND_EDGE = 0.02
#: Share of returns that makes a layer or a region worth a warning.
FINDING_SHARE = 0.2
#: Returns this far (metres) below the floor that ``sensor_height`` puts are "below the floor".
BELOW_FLOOR = 0.1
#: A floor-like layer this far (metres) above the assumed floor is worth a warning.
FLOOR_OFFSET = 0.15
#: Returns in one plane within this height spread, metres (a 2D laser).
PLANAR_SPREAD = 0.01


def geometry_findings(features: Features, robot: Robot, *, floor_layer: bool = True) -> list[str]:
    """Ways in which the data and the robot's geometry disagree, as sentences (none: they agree).

    The fit keeps the robot's body band (``ground_clearance`` to ``body_height`` above the
    floor, the floor ``sensor_height`` below the sensor) clear of obstacles and takes what
    lies below the floor for floor. When the data cannot have been taken with that
    geometry the model is still fitted, but it maps nothing useful: a 2D laser's plane at
    the band's edge, no return inside the band, much of the data below the floor (the
    sensor sits higher than ``sensor_height``) or, unless ``floor_layer`` is false, the
    lowest large horizontal layer below the sensor (:func:`occtool._floor.lowest_layer`: the
    floor, not the most populated layer, which may be a table top) well above the floor (it
    sits lower). The fit itself does not change. A log's floor across its positions is
    :func:`occtool.modelset.estimator_for_log`'s (which passes ``floor_layer=False``).

    Parameters
    ----------
    features
        One position's features; free rays (evidence 0) are not returns and are ignored.
    robot
        The robot the model is fitted for.

    Returns
    -------
    list of str
        One sentence per finding, naming the keywords (``sensor_height`` ...) to check.
    """
    heights = features.points[features.evidence > 0.0, 2]
    if heights.size == 0:
        return []
    low, high = robot.body_band
    floor = robot.floor_h
    band = (f"the body band (h = {low:g} to {high:g} m: ground_clearance {robot.ground_clearance:g} m to "
            f"body_height {robot.body_height:g} m above the floor, sensor_height {robot.sensor_height:g} m)")
    findings = []
    planar = is_planar(features)
    inside = (heights > low + BAND_EDGE) & (heights < high - BAND_EDGE)
    if planar:
        plane = median(heights)
        if not inside.any():
            where = "at the edge of" if low - BAND_EDGE <= plane <= high + BAND_EDGE else "outside"
            findings.append(
                f"the returns lie in one plane at h = {plane:g} m (a 2D laser), {where} {band}: the map cannot "
                "keep the body clear of them; give the laser's sensor_height and the robot's body_height"
            )
        return findings
    if not inside.any():
        findings.append(f"none of the {heights.size:,} returns lies inside {band}: the map will show no obstacle")
    below = float(np.mean(heights < floor - BELOW_FLOOR))
    if below >= FINDING_SHARE:
        findings.append(
            f"{below:.0%} of the returns lie more than {BELOW_FLOOR:g} m below the floor (h = {floor:g} m) and are "
            f"taken for floor: is the sensor higher than sensor_height {robot.sensor_height:g} m?"
        )
    layer = lowest_layer(features.points[features.evidence > 0.0], top=0.0) if floor_layer else None
    if layer is not None and layer[0] > floor + FLOOR_OFFSET and layer[0] < 0.0:
        findings.append(
            f"{layer[1]:.0%} of the returns below the sensor lie in a horizontal layer at h = {layer[0]:.2f} m, "
            "likely the floor, "
            f"{layer[0] - floor:.2f} m above the floor sensor_height {robot.sensor_height:g} m puts at h = {floor:g} m: "
            "is the sensor lower than that?"
        )
    return findings


def is_planar(features: Features) -> bool:
    """Whether the returns (evidence > 0) all lie in one horizontal plane: a 2D laser's scan."""
    heights = features.points[features.evidence > 0.0, 2]
    return heights.size > 0 and float(heights.max() - heights.min()) <= PLANAR_SPREAD


__all__ = ["FLOOR_MODES", "SAMPLE_KINDS", "Samples", "SensorModel", "geometry_findings", "is_planar"]
