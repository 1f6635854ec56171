"""Fitting the min/max tree: the :class:`OccupancyRegressor` estimator.

The tree has a fixed two-level shape, ``F = MAX over groups (MIN over the group's
pieces)``. Its inverse is ``r = MIN over groups (MAX over pieces)``: the free range in a
direction is the nearest of the groups' ranges, and each group's range is a convex
function of the pan angle (a MAX of linear ones) - the shape of a wall or a box face
seen from the sensor. A group covers one angular segment: a *centre* piece models the
obstacle, two *side* pieces rise steeply (within the bound ``a_max``) outside the
segment and so switch the group off there. Errors at segment edges therefore make the
model more occupied, never less: a MAX can only add occupancy.

The fit (see ``docs/method.md`` for the reasons and the measurements):

1. Samples from the :class:`~occtool.sensor.SensorModel`; with ``focus`` only those a
   function increasing in ``r`` can honour (in front of the first obstacle per pan
   angle, in the body's height band), plus occupied *frontier* samples where the
   observed free space ends.
2. A robust first-obstacle profile over the pan angle (clusters of hits, so that single
   mismatches do not count); its near runs are cut into segments by dynamic programming,
   one group per segment.
3. ``construction="profile"`` (default): each centre piece's level crossing is placed by
   a small linear programme as far out as the segment's first obstacles allow, at every
   height of the body band; its slope in ``r`` comes from a robust fit to the samples.
   ``construction="regression"``: centre pieces by bounded least squares instead.
4. Optional refit sweeps: each piece is refitted by bounded, Huber-weighted least squares
   to the samples where it is active, accepted only if the total Huber loss goes down
   (plain alternation oscillates).

Every constraint (``c >= c_min``, ``|dF/dalpha| <= a_max``, ``|b| <= b_max``) holds exactly
for every piece at every step, since each candidate piece is projected onto them.
"""

from __future__ import annotations

import hashlib
import inspect
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool import guard as guard_module
from occtool.errors import InputError, NotFittedError
from occtool.limits import MAX_DISTANCE, MAX_PIECES, MAX_SWEEPS, MAX_WEIGHT
from occtool.features import Features
from occtool.guard import (
    GUARD_BINS, ReturnGuard, Support, build_guard, guard_candidates, is_planar_scan, ray_spacing, support_count,
)
from occtool.linear_program import solve_lp
from occtool.robot import Robot
from occtool.sensor import SAMPLE_KINDS, Samples, SensorModel
from occtool.tree import BASES, InverseTree, MinMaxTree, Op, design_matrix

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
ProgressCallback = Callable[[int, int], None]

DEFAULT_BASIS = "trig"
#: 64 pieces (16 groups) and a 4 m reach: with 32 and 2.5 m the fit gave the held-out
#: AUC away (0.83 on 4 scenes at 10k features, 0.84 per Intel position against the grid's
#: 0.95) to model the first 2.25 m only; 64 and 4 m reach 0.91 and 0.92 for the same map
#: IoU (0.80 against 0.81), in a model of about 13 KB.
DEFAULT_PIECES = 64
DEFAULT_FOCUS_RANGE = 4.0
#: How far (radians) each group's side pieces reach past its segment at the start.
SEGMENT_OVERLAP = 0.0
#: Share of ``focus_range`` beyond which pushing a crossing farther out gains nothing: with
#: the default 2.5 m, 2.25 m, the default 1.5 m max range of the navigation map plus
#: room for the shrink by the robot radius. A share, not a distance, so that the fit
#: scales with the scene (``focus_range``) as the paper's model does.
NAVIGATION_REACH_SHARE = 0.9
#: Where obstacles allow, centre crossings stay this far (m) outside the robot's radius.
BODY_CLEARANCE = 0.1
#: A centre's crossing stays above this share of the segment's nearest crossing.
FLAT_SHARE = 0.97
#: Pan-angle bins of the range profile that places the segments and centre pieces: the
#: finest resolution, used from :data:`PROFILE_FULL_DENSITY` features on; sparser data
#: gets coarser bins (down to a third), so each bin still holds enough hits.
PROFILE_BINS = 360
PROFILE_FULL_DENSITY = 9000
#: Heights of the body band at which a centre's crossing is kept in front of obstacles.
PROFILE_HEIGHTS = 9
#: Samples whose loss is summed at once.
LOSS_CHUNK = 1 << 16
#: Samples of a segment the slope of its crossing is estimated from, at most.
SLOPE_SAMPLES = 8192
#: Samples the reported loss and RMSE are computed over, at most (an even subsample).
LOSS_SAMPLES = 300_000


def features_digest(features: Features) -> str:
    """sha256 of the features' points and evidence (little-endian float64), hex."""
    digest = hashlib.sha256()
    digest.update(np.ascontiguousarray(features.points, dtype="<f8").tobytes())
    digest.update(np.ascontiguousarray(features.evidence, dtype="<f8").tobytes())
    return digest.hexdigest()


@dataclass(frozen=True)
class _Screen:
    """What the fit and the return guard know of the features before any sample is made."""

    obstacle: NDArray[np.bool_]
    origin: float
    planar: bool
    mismatch: NDArray[np.bool_]


def huber_loss(residual: FloatArray, delta: float) -> FloatArray:
    """Elementwise Huber loss: quadratic within ``delta``, linear beyond."""
    a = np.abs(residual)
    return np.where(a <= delta, 0.5 * residual * residual, delta * (a - 0.5 * delta))


class OccupancyRegressor:
    """Fits ``m = F(alpha, h, r)`` as a MAX of MINs of linear pieces to range features.

    Parameters
    ----------
    pieces
        Number of linear pieces ``L`` (the paper used 8 and "less than 32").
    basis
        ``"trig"`` (seam-free, ``a1 cos(alpha) + a2 sin(alpha) + b h + c r + d``, the
        default) or ``"linear"`` (the paper's ``a alpha + b h + c r + d``).
    c_min
        Lower bound of every piece's range weight ``c`` (per metre): F increases with r.
    a_max
        Upper bound of ``|dF/dalpha|`` of every piece (per radian): ``|a|`` for the linear
        basis, ``hypot(a1, a2)`` for the trig basis.
    b_max
        Upper bound of every piece's ``|b|`` (per metre of height).
    c_max
        Largest range weight the profile construction gives a centre piece (per metre):
        a steep crossing, but a bounded one, since the navigation map's safety margin
        grows with the steepest piece.
    c_floor
        Least range weight of a centre piece from the profile construction (per metre).
        The slope fitted to the samples is raised to it: a steep crossing moves little when
        the navigation map lowers its threshold by its safety margin.
    level
        The occupancy level at which the profile construction places each centre piece's
        crossing in front of the first obstacles (the extraction threshold).
    construction
        ``"profile"`` (the default): centre pieces placed by a linear programme just in
        front of the robust first-obstacle profile, their slopes fitted to the samples;
        ``"regression"``: centre pieces fitted by bounded least squares to the segment's
        samples.
    loss
        ``"huber"`` (robust to outliers, the default) or ``"squared"``.
    huber_delta
        Residual (in occupancy units) beyond which the Huber loss grows linearly.
    safety
        Weight factor of a hit sample where the fit under-predicts it (``F < m``): above 1
        the loss is asymmetric and the model errs towards occupied, the safe side.
    groups
        Number of angular segments (groups of pieces); ``None`` picks ``pieces // 4``.
    max_sweeps
        Refitting sweeps over all pieces after the construction (0: none). A sweep
        lowers the Huber loss over the samples, which does not always help the map.
    tol
        Stop when a sweep lowers the loss by less than this fraction.
    sensor
        The :class:`~occtool.sensor.SensorModel` producing the samples.
    robot
        The :class:`~occtool.robot.Robot` (sensor height, clearance, radius).
    seed
        Seed of the random parts (background samples); the fit is deterministic.
    focus
        Fit only what a function increasing in ``r`` can show and the navigation map
        uses (:func:`focus_samples`): samples in the robot's height band, in front of the
        first obstacle at their pan angle and height.
    focus_range
        With ``focus``: the farthest horizontal distance that is fitted, metres. The
        navigation map looks 1.5 m far by default; beyond this the model extrapolates
        (monotonically) and the initial segments are not spent on distant walls. Scale it
        with the max range of the maps you extract (``--focus-range``; about 2.5 x).
    guard
        Keep the position's returns (evidence at or above ``level``, in the body's height
        band, outside the robot's footprint, not seen through by other rays) as a
        :class:`~occtool.guard.ReturnGuard` that the navigation map keeps the robot's
        radius from (:meth:`guarded_returns` says which). The tree does not bend to
        single returns: that cost IoU (0.738 -> 0.715 at 10k features) for no safety the
        guard does not give.

    Attributes
    ----------
    tree_ : MinMaxTree
        The fitted tree; ``inverse_`` its inverse (:meth:`invert`).
    guard_ : ReturnGuard or None
        The return guard (``guard=True``).
    sensor_, robot_
        The sensor model and robot the fit used (the defaults where none was given).
    n_features_, n_samples_, sample_counts_
        Features fitted, samples made from them, and samples by kind.
    rmse_, loss_, loss_history_, n_sweeps_
        Weighted RMSE and loss of the tree at the samples (over an even subsample of at
        most :data:`LOSS_SAMPLES` of them), the loss after each sweep, and the sweeps run.
    slope_bounds_
        The pieces' actual weight extremes (:func:`slope_bounds`).
    features_digest_
        sha256 of the fitted features (:func:`features_digest`).
    fit_seconds_
        Wall time of :meth:`fit`, seconds (nan for a model read from a file).

    Examples
    --------
    >>> from occtool.simulate import simulate_scene
    >>> features, scene = simulate_scene("office", n_features=2000, seed=1)
    >>> model = OccupancyRegressor(pieces=16).fit(features)
    >>> r = model.inverse_range(0.0, -0.5, 0.6)
    """

    def __init__(
        self,
        *,
        pieces: int = DEFAULT_PIECES,
        basis: str = DEFAULT_BASIS,
        c_min: float = 0.25,
        a_max: float = 12.0,
        b_max: float = 8.0,
        c_max: float = 8.0,
        level: float = 0.6,
        c_floor: float = 8.0,
        construction: str = "profile",
        loss: str = "huber",
        huber_delta: float = 0.1,
        safety: float = 1.0,
        groups: int | None = None,
        max_sweeps: int = 0,
        tol: float = 1e-4,
        sensor: SensorModel | None = None,
        robot: Robot | None = None,
        seed: int = 0,
        focus: bool = True,
        focus_range: float = DEFAULT_FOCUS_RANGE,
        guard: bool = True,
    ) -> None:
        self.pieces = pieces
        self.basis = basis
        self.c_min = c_min
        self.a_max = a_max
        self.b_max = b_max
        self.c_max = c_max
        self.level = level
        self.c_floor = c_floor
        self.construction = construction
        self.loss = loss
        self.huber_delta = huber_delta
        self.safety = safety
        self.groups = groups
        self.max_sweeps = max_sweeps
        self.tol = tol
        self.sensor = sensor
        self.robot = robot
        self.seed = seed
        self.focus = focus
        self.focus_range = focus_range
        self.guard = guard

    # ------------------------------------------------------------------ parameters
    @classmethod
    def _get_param_names(cls) -> tuple[str, ...]:
        """The constructor's keyword names, in order: the one list of parameters."""
        return tuple(name for name in inspect.signature(cls.__init__).parameters if name != "self")

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor arguments (the scikit-learn estimator contract; ``deep`` adds
        ``name__key`` entries for parameters that have ``get_params`` themselves)."""
        params = {name: getattr(self, name) for name in self._get_param_names()}
        if deep:
            for name, value in list(params.items()):
                if hasattr(value, "get_params") and not isinstance(value, type):
                    params.update({f"{name}__{key}": item for key, item in value.get_params().items()})
        return params

    def set_params(self, **params: Any) -> OccupancyRegressor:
        """Set constructor arguments by name; returns ``self``."""
        names = self._get_param_names()
        for name, value in params.items():
            if name not in names:
                raise InputError(f"OccupancyRegressor has no parameter {name!r} (parameters: {', '.join(names)})")
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        defaults = {name: parameter.default
                    for name, parameter in inspect.signature(type(self).__init__).parameters.items() if name != "self"}
        changed = [f"{name}={value!r}" for name, value in self.get_params(deep=False).items()
                   if not _same_default(value, defaults[name])]
        return f"{type(self).__name__}({', '.join(changed)})"

    def _validate(self) -> None:
        if isinstance(self.pieces, bool) or int(self.pieces) != self.pieces or self.pieces < 1:
            raise InputError(f"pieces must be a whole number >= 1, got {self.pieces}")
        if self.pieces > MAX_PIECES:
            raise InputError(f"pieces must be at most {MAX_PIECES:,}, got {self.pieces:,}")
        if self.basis not in BASES:
            raise InputError(f"basis must be one of {', '.join(BASES)}, got {self.basis!r}")
        for name in ("c_min", "a_max", "b_max", "c_max", "c_floor", "huber_delta", "safety", "level"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError(f"{name.replace('_', ' ')} must be a positive number, got {value!r}")
            if value > MAX_WEIGHT:
                raise InputError(f"{name} must be at most {MAX_WEIGHT:g}, got {value!r}")
        if self.c_max < self.c_min:
            raise InputError(f"c max ({self.c_max}) must not be below c min ({self.c_min})")
        if self.construction not in ("profile", "regression"):
            raise InputError(f"construction must be 'profile' or 'regression', got {self.construction!r}")
        if self.loss not in ("huber", "squared"):
            raise InputError(f"loss must be 'huber' or 'squared', got {self.loss!r}")
        if self.groups is not None and (int(self.groups) != self.groups or not 1 <= self.groups <= self.pieces):
            raise InputError(f"groups must be between 1 and the number of pieces ({self.pieces}), got {self.groups}")
        if not (isinstance(self.focus_range, (int, float)) and math.isfinite(self.focus_range)
                and self.focus_range > 0):
            raise InputError(f"focus range must be a finite positive number of metres, got {self.focus_range!r}")
        if self.focus_range > MAX_DISTANCE:
            raise InputError(f"focus_range must be at most {MAX_DISTANCE:g} m, got {self.focus_range!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise InputError(f"seed must be a whole number >= 0, got {self.seed!r}")
        if int(self.max_sweeps) != self.max_sweeps or self.max_sweeps < 0:
            raise InputError(f"max sweeps must be a whole number >= 0, got {self.max_sweeps}")
        if self.max_sweeps > MAX_SWEEPS:
            raise InputError(f"max_sweeps must be at most {MAX_SWEEPS:,}, got {self.max_sweeps:,}")

    # ------------------------------------------------------------------ fitting
    def fit(self, features: Features, *, progress: ProgressCallback | None = None) -> OccupancyRegressor:
        """Fit the tree to the features of one robot position.

        Parameters
        ----------
        features
            Range features in the sensor-centred robot frame.
        progress
            Optional ``callback(done, total)`` called after each group is built and after
            each refit sweep.

        Returns
        -------
        OccupancyRegressor
            ``self``, fitted.

        Raises
        ------
        InputError
            If a parameter is invalid or there are no usable features.
        """
        started = time.perf_counter()
        self._validate()
        sensor = self.sensor if self.sensor is not None else SensorModel()
        robot = self.robot if self.robot is not None else Robot()
        rng = np.random.default_rng(self.seed)
        if len(features) == 0:
            raise InputError("no features to fit")
        screen = self._screen(features, sensor, robot)
        usable = features.select(~screen.mismatch) if screen.mismatch.any() else features
        guard = None
        if self.guard:
            mask, scale, spacing = self._guard_mask(features, screen, robot)
            points = features.points[mask]
            guard = build_guard(np.arctan2(points[:, 1], points[:, 0]),
                                np.hypot(points[:, 0], points[:, 1]) * scale[mask], self.level,
                                reach=guard_module.SPREAD_SHARE * spacing)
        origin = screen.origin
        samples = sensor.samples(usable, robot, rng)
        if samples.count("hit") + samples.count("near") + samples.count("floor") == 0:
            raise InputError("no features left to fit (every feature was dropped as floor)")

        turned = Samples(wrap_angle(samples.alpha - origin), samples.h, samples.r, samples.m, samples.weight,
                         samples.kind)
        if self.focus:
            frontier = frontier_samples(turned, robot, self.focus_range, planar=screen.planar)
            focused = focus_samples(turned, robot, self.focus_range, floor_is_obstacle=sensor.floor == "obstacle")
            turned = join_samples(focused, frontier)
        fitter = _Fitter(self, turned, robot, self._profile_returns(usable, sensor, robot, origin),
                         floor_is_obstacle=sensor.floor == "obstacle", depth_error=sensor.depth_error,
                         progress=progress)
        tree, loss_history = fitter.run()
        if origin:
            tree = fitter.turned_tree(tree, origin)
        log.debug(
            "fit: %d features -> %d samples, %d pieces in %d groups, pan origin %.3f rad",
            len(features), len(turned), tree.n_pieces, len(tree.root.children) if isinstance(tree.root, Op) else 1,
            origin,
        )
        # The tree turned back by ``origin``, at the samples turned back, is the fitted tree
        # at the fitted samples: its values are not computed twice (at a million features
        # one evaluation takes half a second).
        assert fitter.prediction is not None
        samples = turned
        rows = fitter.loss_rows
        residual = fitter.prediction - samples.m[rows]
        self._set_fitted(
            tree, sensor=sensor, robot=robot, guard=guard, n_features=len(features), n_samples=len(samples),
            sample_counts={kind: samples.count(kind) for kind in SAMPLE_KINDS},
            rmse=float(np.sqrt(np.average(residual**2, weights=samples.weight[rows]))),
            loss_history=[float(v) for v in loss_history], n_sweeps=len(loss_history) - 1,
            features_digest=features_digest(features), seconds=time.perf_counter() - started,
        )
        return self

    def _set_fitted(self, tree: MinMaxTree, *, sensor: SensorModel, robot: Robot, guard: ReturnGuard | None,
                    n_features: int, n_samples: int, sample_counts: dict[str, int], rmse: float,
                    loss_history: list[float], n_sweeps: int, features_digest: str, seconds: float,
                    loss: float | None = None) -> None:
        """Every fitted attribute, from a fit or a model file (``loss`` defaults to the
        last of ``loss_history``)."""
        self.tree_ = tree
        self.sensor_ = sensor
        self.robot_ = robot
        self.n_features_ = n_features
        self.n_samples_ = n_samples
        self.sample_counts_ = sample_counts
        self.rmse_ = rmse
        self.loss_history_ = loss_history
        self.loss_ = float(loss_history[-1]) if loss is None else loss
        self.n_sweeps_ = n_sweeps
        self.features_digest_ = features_digest
        self.slope_bounds_ = slope_bounds(tree)
        self.inverse_ = tree.inverse()
        self.guard_ = guard
        self.fit_seconds_ = seconds
        #: A model file's run details (the model reader fills them in).
        self.run_: dict[str, Any] = {}

    def _profile_returns(self, features: Features, sensor: SensorModel, robot: Robot,
                         origin: float) -> tuple[FloatArray, FloatArray]:
        """Turned pan angle and horizontal distance of the returns the range profile is made of:
        the features that give hit samples, in the body band (from the floor up when the
        floor is an obstacle)."""
        low, high = robot.body_band
        if sensor.floor == "obstacle":
            low = -np.inf
        z = features.points[:, 2]
        chosen = sensor.is_obstacle(features, robot) & (z >= low) & (z <= high)
        points = features.points[chosen]
        return wrap_angle(np.arctan2(points[:, 1], points[:, 0]) - origin), np.hypot(points[:, 0], points[:, 1])

    def _screen(self, features: Features, sensor: SensorModel, robot: Robot) -> _Screen:
        """Which features are obstacles, which are mismatches, and the fit's pan origin."""
        # Mismatches a few centimetres apart can pass for a small obstacle; where other
        # rays in nearly the same direction see through them, they are dropped. Floor
        # features are not obstacles, and grazing rays see "through" them all the time.
        # The trig basis has no seam, so the angular bins can start anywhere: starting them
        # at the mean direction of the obstacle features makes the whole fit (the mismatch
        # test included) turn with the scene: rotating the features rotates the model
        # exactly, not up to a bin.
        obstacle = sensor.is_obstacle(features, robot) & ~sensor.is_floor(features.height, robot)
        origin = mean_direction(features.alpha[obstacle]) if self.basis == "trig" else 0.0
        # A planar scan (a 2D laser) has one beam per direction: a beam passing beside a
        # return says only that the object is narrower than the beam spacing, never that
        # the return is a mismatch (a chair leg is often hit by a single beam).
        planar = is_planar_scan(features.height[obstacle])
        mismatch = np.zeros(len(features), dtype=bool)
        if self.focus and not planar:
            # Only features the focus keeps can mislead the fit: test those alone.
            horizontal = np.hypot(features.points[:, 0], features.points[:, 1])
            candidates = obstacle & (horizontal <= self.focus_range)
            mismatch = contradicted_features(features, origin=origin, candidates=candidates)
        return _Screen(obstacle, origin, planar, mismatch)

    def guarded_returns(self, features: Features) -> NDArray[np.bool_]:
        """Which of ``features`` the return guard holds (:mod:`occtool.guard`): the returns
        every navigation map of a model fitted to them keeps the robot's radius from.

        A function of the features and the estimator's parameters alone (fitted or not).
        """
        self._validate()
        sensor = self.sensor if self.sensor is not None else SensorModel()
        robot = self.robot if self.robot is not None else Robot()
        return self._guard_mask(features, self._screen(features, sensor, robot), robot)[0]

    def _guard_mask(self, features: Features, screen: _Screen,
                    robot: Robot) -> tuple[NDArray[np.bool_], FloatArray, float]:
        """The guarded returns, the share of each feature's distance the guard keeps, and
        the ray spacing (radians; 0 for a planar scan, whose beams the guard's bins match)."""
        returns = screen.obstacle & guard_candidates(features, features.evidence, robot, self.level)
        if self.focus:
            # Only as far as the fit reaches: beyond it the model is an extrapolation anyway.
            returns &= np.hypot(features.points[:, 0], features.points[:, 1]) <= self.focus_range + robot.radius
        if screen.planar:
            # A planar scan has no mismatches of this kind: every return is guarded, as measured.
            return returns, np.ones(len(features)), 0.0
        # 3D data. A return is dropped as a mismatch only when rays clearly pass through it:
        # a stricter test than the fit's, which also drops the front edge of a thin seat or
        # table top that rays graze on their way to the floor beyond.
        strict = contradicted_features(features, origin=screen.origin, candidates=returns & screen.mismatch,
                                       tolerance=GUARD_SIGHT_TOLERANCE, ratio=GUARD_SIGHT_RATIO)
        returns &= ~strict
        spacing = ray_spacing(features.points)
        # A return alone may be a mismatch; one confirmed by returns on neighbouring rays at
        # nearly its range (at any height: a sign hanging into the band is confirmed by its
        # part above it) is a surface.
        index = np.flatnonzero(returns)
        candidates = features.points[index]
        distance = np.hypot(candidates[:, 0], candidates[:, 1])
        # Support from returns near enough (in reach and height) to confirm a candidate.
        x, y, z = features.points.T
        low, high = robot.body_band
        near = (np.hypot(x, y) <= 1.2 * float(distance.max(initial=0.0)) + 0.1) & (
            z >= low - SUPPORT_HEIGHT_REACH) & (z <= high + SUPPORT_HEIGHT_REACH)
        support = features.points[near & screen.obstacle & ~strict & (features.evidence >= self.level)]
        # Near the robot a surface spans a wide tilt range and many rays end on it, while
        # two mismatches there box the robot in: the count grows as 1 / distance, as the fit's.
        needed = support_count(len(features)) * np.maximum(1.0, NEAR_SUPPORT_DISTANCE / np.maximum(distance, 1e-9))
        # Only a guard bin's nearest confirmed return counts: test each bin's nearest
        # returns first, and farther ones only in bins where none was confirmed yet (a
        # million features: 0.9 s of the fit for the support test of every return).
        bins = np.mod(np.floor((np.arctan2(candidates[:, 1], candidates[:, 0]) + math.pi)
                               * (GUARD_BINS / (2.0 * math.pi))).astype(np.int64), GUARD_BINS)
        order = np.lexsort((distance, bins))
        starts = np.searchsorted(bins[order], np.arange(GUARD_BINS))
        rank = np.empty(order.size, dtype=np.int64)
        rank[order] = np.arange(order.size) - starts[bins[order]]
        confirmed = np.zeros(index.size, dtype=bool)
        settled = np.zeros(GUARD_BINS, dtype=bool)
        confirming = Support(support, spacing)
        low_rank, chunk = 0, GUARD_TEST_CHUNK
        while low_rank < max(int(rank.max(initial=-1)) + 1, 0):
            tested = (rank >= low_rank) & (rank < low_rank + chunk) & ~settled[bins]
            if not tested.any():
                break
            chosen = np.flatnonzero(tested)
            confirmed[chosen] = confirming.confirmed(candidates[chosen], needed[chosen])
            settled[bins[chosen[confirmed[chosen]]]] = True
            low_rank, chunk = low_rank + chunk, 2 * chunk
        returns[index[~confirmed]] = False
        # A surface seen from above is first hit up to a ray spacing or two behind its front
        # edge: its returns are taken that much nearer. A wall's or a leg's first return is
        # its front (at 1k features the blanket shrink cost 0.07 IoU).
        scale = np.ones(len(features))
        kept = np.flatnonzero(returns)
        tops = confirming.seen_from_above(features.points[kept])
        scale[kept[tops]] = max(0.0, 1.0 - guard_module.SPACING_FACTOR * spacing)
        return returns, scale, spacing

    # ------------------------------------------------------------------ using the fit
    def _check_fitted(self) -> None:
        if not hasattr(self, "tree_"):
            raise NotFittedError("this OccupancyRegressor is not fitted yet: call fit() or load a model file")

    def predict(self, alpha: ArrayLike, h: ArrayLike, r: ArrayLike) -> FloatArray:
        """Evaluate the occupancy ``F(alpha, h, r)`` (inputs broadcast together)."""
        self._check_fitted()
        return self.tree_.predict(alpha, h, r)

    def invert(self) -> InverseTree:
        """The inverse tree ``r = F^-1(alpha, h, m)``."""
        self._check_fitted()
        return self.inverse_

    def inverse_range(self, alpha: ArrayLike, h: ArrayLike, level: ArrayLike) -> FloatArray:
        """Distance ``r`` from the sensor at which ``F`` reaches ``level`` at ``(alpha, h)``.

        ``F`` increases strictly and without bound in ``r`` (every ``c >= c_min > 0``), so
        along ``r >= 0`` the level is crossed exactly once unless ``F`` is at or above it
        already at ``r = 0``; that gives 0. ``np.inf`` is returned only where the level is
        infinite. Inputs broadcast together.
        """
        self._check_fitted()
        r = self.inverse_.range(alpha, h, level)
        r = np.where(np.isnan(r), np.inf, r)
        return np.maximum(r, 0.0)

    def free_distance_bounds(self, alpha_low: ArrayLike, alpha_high: ArrayLike, h_edges: ArrayLike,
                             level: float) -> FloatArray:
        """Lower bounds of the free horizontal distance over boxes of pan angle x height at
        ``level``: ``(len(h_edges) - 1, len(alpha_low))``, see
        :meth:`occtool.tree.InverseTree.horizontal_lower_bound`. Pass it to
        :func:`occtool.navigation.navigation_map` as ``free_bounds``."""
        self._check_fitted()
        return self.inverse_.horizontal_lower_bound(alpha_low, alpha_high, h_edges, level)

    def navigation_map(self, **options: Any) -> Any:
        """This model's navigation map: :func:`occtool.navigation.navigation_map` with the
        model's inverse, its exact free-distance bounds, its return guard and (unless
        ``robot`` is given) the robot it was fitted for; ``options`` are the rest of that
        function's keywords (``threshold``, ``heights``, ``max_range``, ...)."""
        from occtool.navigation import navigation_map

        self._check_fitted()
        options.setdefault("robot", self.robot_)
        options.setdefault("free_bounds", self.free_distance_bounds)
        options.setdefault("guard", self.guard_)
        return navigation_map(self.inverse_range, **options)

    def training_summary(self) -> dict[str, Any]:
        """Features, samples, fit error and the input digest, as written to a model file."""
        self._check_fitted()
        return {
            "n_features": int(self.n_features_),
            "n_samples": int(self.n_samples_),
            "samples_by_kind": {k: int(v) for k, v in self.sample_counts_.items()},
            "rmse": float(self.rmse_),
            # null when unknown (a model file that recorded none): JSON has no NaN
            "loss": float(self.loss_) if np.isfinite(self.loss_) else None,
            "sweeps": int(self.n_sweeps_),
            "features_sha256": self.features_digest_,
        }


def _same_default(value: Any, default: Any) -> bool:
    """Whether a parameter still has its default (for the repr)."""
    try:
        return bool(value == default) and type(value) is type(default)
    except (TypeError, ValueError):
        return False


def slope_bounds(tree: MinMaxTree) -> dict[str, float]:
    """The actual extremes of the pieces' weights: ``a_max`` (largest ``|dF/dalpha|``),
    ``b_max`` (largest ``|b|``), ``c_min`` and ``c_max`` (smallest and largest ``c``)."""
    return {
        "a_max": float(tree.angle_weight.max()),
        "b_max": float(np.abs(tree.b).max()),
        "c_min": float(tree.c.min()),
        "c_max": float(tree.c.max()),
    }


# ====================================================================== solver parts
def box_qp(gram: FloatArray, rhs: FloatArray, lower: FloatArray, upper: FloatArray) -> FloatArray:
    """Minimise ``x'Gx/2 - rhs'x`` subject to ``lower <= x <= upper`` (small, dense G).

    An active-set method: solve for the free variables, clamp those outside their box,
    free a clamped one whose multiplier has the wrong sign, repeat. The result lies in the
    box exactly (clamped values are the bounds themselves).
    """
    k = rhs.shape[0]
    x = np.clip(np.zeros(k), lower, upper)
    free = np.ones(k, dtype=bool)
    for _ in range(4 * k + 4):
        if free.any():
            fixed = ~free
            sub_rhs = rhs[free] - gram[np.ix_(free, fixed)] @ x[fixed]
            try:
                x[free] = np.linalg.solve(gram[np.ix_(free, free)], sub_rhs)
            except np.linalg.LinAlgError:
                x[free] = np.linalg.lstsq(gram[np.ix_(free, free)], sub_rhs, rcond=None)[0]
        outside = free & ((x < lower) | (x > upper))
        if outside.any():
            x = np.clip(x, lower, upper)
            free &= ~outside
            continue
        grad = gram @ x - rhs
        wrong = ~free & (((x <= lower) & (grad < 0)) | ((x >= upper) & (grad > 0)))
        if not wrong.any():
            break
        free[int(np.argmax(np.where(wrong, np.abs(grad), -1.0)))] = True
    return np.clip(x, lower, upper)


class _Fitter:
    """One fit: holds the samples, the design matrix and the evolving pieces."""

    def __init__(self, params: OccupancyRegressor, samples: Samples, robot: Robot,
                 returns: tuple[FloatArray, FloatArray], *,
                 floor_is_obstacle: bool = False, depth_error: float = 0.0,
                 progress: ProgressCallback | None = None) -> None:
        self.p = params
        self.progress = progress
        #: Pan angle (turned) and horizontal distance of the obstacle returns in the body band.
        self.returns = returns
        self.depth_error = depth_error
        self.floor_is_obstacle = floor_is_obstacle
        self.samples = samples
        self.robot = robot
        self.basis = params.basis
        self.k_angle = 1 if self.basis == "linear" else 2
        # Angle terms, h, r and the offset.
        self.n_terms = self.k_angle + 3
        self.m = samples.m
        self.w = samples.weight
        self.hit = samples.kind == SAMPLE_KINDS["hit"]
        self.on_rays = self.hit | (samples.kind == SAMPLE_KINDS["near"])
        self.w_safe = self.w * params.safety
        self.w_total = float(self.w.sum())
        k = self.n_terms
        inf = np.inf
        self.lower = np.full(k, -inf)
        self.upper = np.full(k, inf)
        self.lower[: self.k_angle] = -params.a_max
        self.upper[: self.k_angle] = params.a_max
        self.lower[self.k_angle] = -params.b_max
        self.upper[self.k_angle] = params.b_max
        self.lower[self.k_angle + 1] = params.c_min
        self.delta = params.huber_delta if params.loss == "huber" else np.inf
        #: The final tree's values at the samples, set by :meth:`alternate`.
        self.prediction: FloatArray | None = None
        #: The samples ``prediction`` is at.
        self.loss_rows = slice(None)
        # Hit and near samples grouped by profile bin, and the bins' bounds (built on first use).
        self._ray_groups: tuple[NDArray[np.intp], NDArray[np.intp]] | None = None

    @cached_property
    def X(self) -> FloatArray:
        """The ``(samples, terms)`` design matrix: only least squares and sweeps need it,
        and at a million features it is 100 MB."""
        return design_matrix(self.basis, self.samples.alpha, self.samples.h, self.samples.r)

    def turned_tree(self, tree: MinMaxTree, origin: float) -> MinMaxTree:
        """The tree fitted in pan angles measured from ``origin``, in the robot's angles.

        ``cos(alpha - o)`` and ``sin(alpha - o)`` are a rotation of ``cos(alpha)``,
        ``sin(alpha)``, so the pan weights turn by ``o`` and keep their length.
        """
        W = tree.coefficients.copy()
        co, so = math.cos(origin), math.sin(origin)
        a1, a2 = W[:, 0].copy(), W[:, 1].copy()
        W[:, 0] = a1 * co - a2 * so
        W[:, 1] = a1 * so + a2 * co
        W = np.array([self.project(row) for row in W])
        return MinMaxTree(tree.basis, W, tree.root)

    # ---------------------------------------------------------------- constraints
    def project(self, piece: FloatArray) -> FloatArray:
        """Move a piece onto the constraint set (box, and the disc for trig angle terms)."""
        piece = np.clip(piece, self.lower, self.upper)
        if self.k_angle == 2:
            norm = pan_weight(piece[0], piece[1])
            if norm > self.p.a_max:
                piece[:2] *= self.p.a_max / norm
                # hypot after scaling can exceed a_max by an ulp; shave it off exactly.
                while pan_weight(piece[0], piece[1]) > self.p.a_max:
                    piece[:2] = np.nextafter(piece[:2], 0.0)
        return piece

    def solve_piece(self, rows: NDArray[np.intp] | NDArray[np.bool_], weights: FloatArray) -> FloatArray | None:
        """Bounded weighted least squares of one piece on the given samples."""
        X = self.X[rows]
        if X.shape[0] < X.shape[1]:
            return None
        Xw = X * weights[:, None]
        gram = Xw.T @ X
        rhs = Xw.T @ self.m[rows]
        gram[np.diag_indices_from(gram)] += 1e-9 * (np.trace(gram) + 1.0)
        piece = box_qp(gram, rhs, self.lower, self.upper)
        if self.k_angle == 2 and pan_weight(piece[0], piece[1]) > self.p.a_max:
            # The disc constraint is not a box: keep the direction of the angle weights,
            # fix their length at the bound and re-solve the remaining weights.
            angle = piece[:2] * (self.p.a_max / pan_weight(piece[0], piece[1]))
            rest = slice(2, None)
            sub_rhs = rhs[rest] - gram[rest, :2] @ angle
            piece = np.concatenate([angle, box_qp(gram[rest, rest], sub_rhs, self.lower[rest], self.upper[rest])])
        return self.project(piece)

    def irls_weights(self, residual: FloatArray, weights: FloatArray, hit: NDArray[np.bool_]) -> FloatArray:
        """Weights of one reweighted least-squares step: ``w min(1, delta/|res|)``, times
        ``safety`` where a hit is under-predicted."""
        weights = np.where(hit & (residual < 0), weights * self.p.safety, weights)
        if not np.isfinite(self.delta):
            return weights
        a = np.abs(residual)
        return weights * np.minimum(1.0, self.delta / np.maximum(a, 1e-300))

    def total_loss(self, prediction: FloatArray, rows: slice = slice(None)) -> float:
        """The weighted loss of ``prediction`` at the samples ``rows``, per unit weight."""
        m, w, w_safe = self.m[rows], self.w[rows], self.w_safe[rows]
        hit = self.hit[rows]
        # In chunks: at 2M samples whole-array temporaries (16 MB each, fresh pages every
        # time) made this 0.23 s, 160x its cost at 200k samples.
        total = 0.0
        for first in range(0, prediction.size, LOSS_CHUNK):
            part = slice(first, first + LOSS_CHUNK)
            residual = prediction[part] - m[part]
            weights = np.where(hit[part] & (residual < 0), w_safe[part], w[part])
            total += float(np.dot(weights, huber_loss(residual, self.delta)))
        return total / (self.w_total if rows == slice(None) else float(w.sum()))

    # ---------------------------------------------------------------- initial tree
    def range_profile(self, n_bins: int) -> FloatArray:
        """Horizontal distance of the first obstacle per pan-angle bin, outliers ignored."""
        s = self.samples
        support, _ = adaptive_support(s.count("robot"))
        # From the returns themselves (the surface is where they are, not their hit samples
        # at r (1 -+ depth error)), a feature for every two hit samples of the support. The
        # front is the cluster's last return of that support, not its nearest: the nearest
        # of many noisy returns lies farther in front of the surface the more there are
        # (about 2.5 sigma of range noise at 80 returns a bin, 2 at 30; the map lost
        # 0.02-0.04 IoU from 10k to 30k features), but no more than the depth error beyond
        # the cluster's return half way there, so a table top seen from above keeps its
        # front edge (first_obstacle_distance).
        alpha, distance = self.returns
        keep = support // 2
        profile = first_obstacle_distance(alpha, distance, n_bins, keep, front=keep - 1, cap=1.0 + self.depth_error)
        frontier = s.kind == SAMPLE_KINDS["frontier"]
        if frontier.any():
            reach = np.sqrt(np.maximum(s.r[frontier] ** 2 - s.h[frontier] ** 2, 0.0))
            np.minimum.at(profile, angle_bins(s.alpha[frontier], n_bins), reach)
        cap = self.p.focus_range if self.p.focus else (distance.max() if distance.size else 1.0)
        return np.minimum(profile, cap)

    def initial_groups(self, n_groups: int, range_profile: FloatArray) -> list[tuple[int, int]]:
        """Segments ``(first_bin, end_bin)`` of the profile's bins (end exclusive, may exceed
        the bin count: wraps).

        Bins whose first obstacle lies beyond the navigation reach need no group (where
        no group is on, the neighbours' sides recede and the space reads free), so only
        the near runs are cut into at most ``n_groups`` segments.
        """
        n_bins = range_profile.shape[0]
        if n_groups == 1:
            return [(0, n_bins)]
        reach = NAVIGATION_REACH_SHARE * self.p.focus_range
        profile = np.minimum(range_profile, reach)
        far = profile >= reach
        if far.all():
            return [(0, n_bins)]
        shift = 0
        if self.basis == "trig":
            if far.any():
                # Start where a far run starts, so no segment wraps around the cut.
                starts = np.flatnonzero(far & ~np.roll(far, 1))
                shift = int(starts[0]) if starts.size else int(np.flatnonzero(far)[0])
            else:
                # Start the linear DP where the profile jumps most: a natural segment edge.
                shift = int(np.argmax(np.abs(profile - np.roll(profile, 1))))
        rolled = np.roll(profile, -shift)
        # A group's sides can only switch it off outside a segment narrower than pi.
        max_length = min(n_bins // 2 - 1, 2 * int(math.ceil(n_bins / n_groups)))
        segments = segment_near_runs(rolled, np.roll(far, -shift), n_groups, max_length)
        return [(a + shift, b + shift) for a, b in segments]

    def run(self) -> tuple[MinMaxTree, list[float]]:
        p = self.p
        L = int(p.pieces)
        # Four pieces a group by default: two centres (low and high part of the body band)
        # and two sides.
        n_groups = int(p.groups) if p.groups is not None else max(1, L // 4)
        if n_groups > 1 and L < 3 * n_groups:
            n_groups = max(1, L // 3)
        n_bins = profile_bins(self.samples.count("robot"))
        profile = self.range_profile(n_bins)
        segments = self.initial_groups(n_groups, profile)
        width = 2.0 * np.pi / n_bins
        sample_bin = angle_bins(self.samples.alpha, n_bins)

        pieces: list[FloatArray] = []
        members: list[list[int]] = []
        centres_per_group = [1] * len(segments)
        extra = L - (3 * len(segments) if len(segments) > 1 else 1)
        # Extra centres go to the segments whose profile a single line fits worst.
        seg_cost = [segment_cost(profile, first, end) for first, end in segments]
        order = np.argsort(-np.asarray(seg_cost), kind="stable")
        for i in range(extra):
            centres_per_group[int(order[i % len(order)])] += 1

        for g, (first, end) in enumerate(segments):
            group: list[int] = []
            if p.construction == "profile":
                centres = self.profile_centres(profile, first, end, centres_per_group[g], sample_bin)
            else:
                mask = np.isin(sample_bin, np.arange(first, end) % n_bins)
                centres = self.initial_centres(mask, centres_per_group[g], first * width - np.pi, end * width - np.pi)
            for piece in centres:
                group.append(len(pieces))
                pieces.append(piece)
            if len(segments) > 1:
                # Side pieces start a little outside the segment: where neighbouring groups
                # overlap, the MAX keeps the nearer obstacle, the safe side.
                start_angle = first * width - np.pi - SEGMENT_OVERLAP
                end_angle = end * width - np.pi + SEGMENT_OVERLAP
                base = centres[0]
                for side in (self.side_piece(base, start_angle, +1), self.side_piece(base, end_angle, -1)):
                    group.append(len(pieces))
                    pieces.append(side)
            members.append(group)
            if self.progress is not None:
                self.progress(g + 1, len(segments) + int(p.max_sweeps))
        W = np.array(pieces)
        self.progress_offset = len(segments)
        return self.alternate(W, members)

    def profile_centres(self, profile: FloatArray, first: int, end: int, count: int,
                        sample_bin: NDArray[np.intp]) -> list[FloatArray]:
        """Centre pieces whose level crossing lies just in front of the segment's first obstacles.

        In range terms a piece crosses ``level`` at ``r* = p0 + p_angle . angle_terms + p_h h``.
        A linear programme pushes ``r*`` as far out as it may go while staying at or below
        ``sqrt(D(alpha)^2 + h^2)`` (the first obstacle at horizontal distance ``D``) at the
        edges of every bin of the segment, its overlap and every height of the body band.
        The slope ``c`` through the crossing comes from a robust least-squares fit to the
        segment's samples, so the sensor model decides how sharp the crossing is.
        """
        n_bins = profile.shape[0]
        width = 2.0 * np.pi / n_bins
        # The crossing must stay in front of the obstacles over the segment's own bins only:
        # where a group reaches past its segment, the MAX over groups keeps the nearer one.
        bins = np.arange(first, end)
        D_bins = profile[np.mod(bins, n_bins)]
        # Between two bins the obstacle may be as near as in either of them.
        left = np.where(bins > first, np.minimum(D_bins, profile[np.mod(bins - 1, n_bins)]), D_bins)
        right = np.where(bins < end - 1, np.minimum(D_bins, profile[np.mod(bins + 1, n_bins)]), D_bins)
        # The right edge of one bin is the left edge of the next, with the same bound:
        # keep each edge once (the nearer bound), halving the programmes' rows.
        edge_index, first_of = np.unique(np.concatenate([bins, bins + 1]), return_inverse=True)
        D_edges = np.full(edge_index.size, np.inf)
        np.minimum.at(D_edges, first_of, np.concatenate([left, right]))
        edges = edge_index * width - np.pi
        # From the floor up: the map's lowest cut may lie a little under the clearance.
        low, high = self.robot.floor_h, self.robot.body_band[1]
        heights = np.linspace(low, max(high, 0.0), PROFILE_HEIGHTS)
        if self.k_angle == 1:
            # The paper's basis is discontinuous at +-pi: keep the overlap on this side.
            keep = (edges >= -np.pi) & (edges <= np.pi)
            edges, D_edges = edges[keep], D_edges[keep]
        A, H = np.meshgrid(edges, heights, indexing="ij")
        D = np.repeat(D_edges, PROFILE_HEIGHTS).reshape(A.shape)
        target = np.sqrt(D**2 + H**2).ravel()
        cap = np.sqrt(np.minimum(D, NAVIGATION_REACH_SHARE * self.p.focus_range) ** 2 + H**2).ravel()
        body = np.sqrt((self.robot.radius + BODY_CLEARANCE) ** 2 + H**2).ravel()
        keep_off = np.minimum(body, target - 1e-6)
        nearest = np.sqrt(np.min(D, axis=0) ** 2 + heights**2)
        floor_flat = np.minimum((FLAT_SHARE * nearest)[None, :].repeat(A.shape[0], axis=0).ravel(), target - 1e-6)
        # The crossing line in local angle terms about the segment's middle, where they are
        # well conditioned: 1, cos(da) - 1, sin(da), h (linear basis: 1, da, h).
        middle = (first + end) / 2.0 * width - np.pi
        delta = A.ravel() - middle
        local = [delta] if self.k_angle == 1 else [np.cos(delta) - 1.0, np.sin(delta)]
        rows = np.column_stack([np.ones(target.size), *local, H.ravel()])

        c = self.crossing_slope(self.segment_ray_samples(first, end, sample_bin, n_bins), float(np.median(D_bins)))
        # Half the pan-weight budget is left to the side pieces that switch the group off.
        bound_angle = 0.5 * self.p.a_max / c / (math.sqrt(2.0) if self.k_angle == 2 else 1.0)
        bound_h = self.p.b_max / c
        # The offset is free.
        if self.k_angle == 1:
            lower = np.array([-np.inf, -bound_angle, -bound_h])
            upper = np.array([np.inf, bound_angle, bound_h])
        else:
            # The crossing may only curve away from the robot off the middle (cos - 1 <= 0 with a
            # weight <= 0): far from its segment a group then recedes, and its sides can
            # switch it off.
            lower = np.array([-np.inf, -bound_angle, -bound_angle, -bound_h])
            upper = np.array([np.inf, 0.0, bound_angle, bound_h])
        centres = []
        heights_of_rows = H.ravel()
        for j in range(count):
            # Several centres split the height band: the crossing sqrt(D^2 + h^2) is convex
            # in h, and the group's crossing (the farthest of its pieces') follows it with one
            # tangent line per part.
            part_lo = low + (max(high, 0.0) - low) * j / count
            part_hi = low + (max(high, 0.0) - low) * (j + 1) / count
            emphasis = (heights_of_rows >= part_lo - 1e-9) & (heights_of_rows <= part_hi + 1e-9)
            n_rows, k = rows.shape
            chosen = np.flatnonzero(emphasis)
            # Maximise the emphasised crossings, but only up to the range the map looks at
            # (t_i <= min(r*_i, cap_i)): pushing out far walls must not tilt the line into a
            # near obstacle. Relative gains: a centimetre near the robot counts more. (Maximising
            # the linearised horizontal distance per bin edge instead measured 0.01-0.02 worse.)
            # A programme in the line's own k unknowns: the crossings are capped at the
            # range the map looks at (r*_i <= cap_i) as constraints. (An auxiliary variable
            # per row, t_i <= min(r*_i, cap_i), gave the same maps on 4 scenes x 3 seeds at
            # 2k and 10k features, and took twice as long: 19 programmes of ~400 variables were most of the fit's time.)
            objective = -(rows[chosen] / cap[chosen, None] ** 2).sum(axis=0)
            # r*_i <= target_i everywhere and r*_i <= cap_i on the emphasised rows: one row
            # each, bounded by the smaller.
            A_ub = rows
            b_ub = np.where(emphasis, np.minimum(target, cap), target)
            # Keep the crossing off the robot's body wherever the obstacle allows: at the
            # floor, a crossing a few centimetres too near in r is a body in collision.
            # Only this centre's part of the band: the group's crossing is the farthest of its
            # centres', so each needs to keep off the body where it is the one that counts.
            # Nor may it dip below (nearly) the segment's nearest obstacle at that height, which
            # a flat crossing would keep: a tilt that gains far away must not cost near by.
            # Each floor is dropped again if it makes the programme infeasible.
            floors = [np.maximum(keep_off, floor_flat)[chosen], keep_off[chosen], None]
            for floor in floors:
                if floor is None:
                    result = solve_lp(objective, A_ub, b_ub, lower, upper)
                else:
                    result = solve_lp(objective, np.vstack([A_ub, -rows[chosen]]),
                                      np.concatenate([b_ub, -np.minimum(floor, cap[chosen])]), lower, upper)
                if result.status == 0:
                    break
            if result.status == 0:
                q = result.x[:k]  # type: ignore[index]  # status 0: solved, x is set
            else:
                q = np.zeros(rows.shape[1])
                q[0] = float(target.min())
            # Back to the global basis: the crossing r* = p0 + p_angle . angle terms + p_h h.
            if self.k_angle == 1:
                p_angle = np.array([q[1]])
                p0 = q[0] - q[1] * middle
            else:
                cm, sm = math.cos(middle), math.sin(middle)
                p_angle = np.array([q[1] * cm - q[2] * sm, q[1] * sm + q[2] * cm])
                p0 = q[0] - q[1]
            # F = level + c (r - r*): angle and height weights -c p, offset level - c p0.
            piece = np.empty(self.n_terms)
            piece[: self.k_angle] = -c * p_angle
            piece[self.k_angle] = -c * q[-1]
            piece[self.k_angle + 1] = c
            piece[-1] = self.p.level - c * p0
            centres.append(self.project(piece))
        return centres

    def segment_ray_samples(self, first: int, end: int, sample_bin: NDArray[np.intp], n_bins: int) -> NDArray[np.intp]:
        """Indices of the hit and near samples in bins ``first`` to ``end`` - 1 (wrapping).

        Only the samples on rays near their feature say how sharp a crossing is; the robot
        and footprint samples would pull ``c`` down to ``level / distance``. The samples
        are grouped by bin once per fit, so each segment takes slices instead of a pass
        over every sample (8 passes over 2M samples were 0.2 s at 1M features).
        """
        if self._ray_groups is None or self._ray_groups[1].size != n_bins + 1:
            rays = np.flatnonzero(self.on_rays)
            order, bounds = group_by_bin(sample_bin[rays], n_bins)
            self._ray_groups = (rays[order], bounds)
        grouped, bounds = self._ray_groups
        start, length = first % n_bins, end - first
        if start + length <= n_bins:
            return grouped[bounds[start]:bounds[start + length]]
        return np.concatenate([grouped[bounds[start]:], grouped[:bounds[start + length - n_bins]]])

    def crossing_slope(self, rows: NDArray[np.intp], distance: float) -> float:
        """Robust estimate of ``c`` in ``F = level + c (r - r*)`` from a segment's samples
        (an even subsample of at most :data:`SLOPE_SAMPLES` of them: one number needs no
        more, and at a million features the full segments took 1.3 s of a 6 s fit)."""
        rows = rows[:: max(1, -(-rows.size // SLOPE_SAMPLES))]
        s = self.samples
        r_star = np.sqrt(distance**2 + s.h[rows] ** 2)
        x = s.r[rows] - r_star
        y = s.m[rows] - self.p.level
        w = self.w[rows]
        c = 1.0
        for _ in range(4):
            denominator = float(np.dot(w, x * x))
            if denominator <= 0:
                break
            c = float(np.dot(w, x * y)) / denominator
            w = self.irls_weights(c * x - y, self.w[rows], self.hit[rows])
        return float(np.clip(max(c, self.p.c_floor), self.p.c_min, self.p.c_max))

    def initial_centres(self, mask: NDArray[np.bool_], count: int, start: float, end: float) -> list[FloatArray]:
        """``count`` centre pieces fitted to consecutive parts of a segment's samples."""
        alpha = self.samples.alpha
        offset = np.mod(alpha - start, 2.0 * np.pi)
        span = max(end - start, 1e-9)
        centres = []
        fallback = self.solve_piece(np.ones_like(mask), self.w)
        for j in range(count):
            part = mask & (offset >= span * j / count) & (offset <= span * (j + 1) / count) if count > 1 else mask
            piece = self.huber_fit(part) if part.sum() >= 8 else None
            if piece is None:
                piece = self.huber_fit(mask) if mask.sum() >= 8 else None
            if piece is None:
                piece = fallback if fallback is not None else self.project(np.array([0.0] * (self.n_terms - 2) + [1.0, 0.0]))
            centres.append(piece)
        return centres

    def huber_fit(self, rows: NDArray[np.bool_], iterations: int = 3) -> FloatArray | None:
        weights = self.w[rows]
        piece = None
        for _ in range(iterations):
            piece = self.solve_piece(rows, weights)
            if piece is None:
                return None
            weights = self.irls_weights(self.X[rows] @ piece - self.m[rows], self.w[rows], self.hit[rows])
        return piece

    def side_piece(self, centre: FloatArray, angle: float, direction: int) -> FloatArray:
        """A piece that lets the centre's group recede steeply in range beyond ``angle``.

        The side crosses ``level`` where the centre does at ``angle``, with the least slope
        in ``r`` (``c_min``) and the full pan weight left within ``a_max``: its crossing then
        moves away from the robot at ``(a_max - |a_centre|) / c_min`` metres per radian
        outside the segment, and inside it stays nearer than the centre's crossing, so the
        group (a MIN: its crossing is the farthest of its pieces') keeps the centre's there.
        ``direction`` +1: the side rises for pan angles above ``angle`` (segment start);
        -1: below it (segment end).
        """
        scale = min(1.0, self.p.c_min / centre[self.k_angle + 1])
        level = self.p.level
        piece = centre * scale
        piece[-1] = centre[-1] * scale + level * (1.0 - scale)
        A = self.p.a_max
        if self.k_angle == 1:
            a = piece[0]
            gain = (A - a) if direction > 0 else (A + a)
            piece[0] = a + direction * gain
            piece[-1] -= direction * gain * angle
        else:
            # direction * sin(alpha - angle) = direction * (cos(angle) sin(alpha) - sin(angle) cos(alpha))
            u = direction * np.array([-math.sin(angle), math.cos(angle)])
            v = piece[:2].copy()
            vu = float(v @ u)
            gain = -vu + math.sqrt(max(vu * vu - float(v @ v) + A * A, 0.0))
            piece[:2] = v + gain * u
        return self.project(piece)

    # ---------------------------------------------------------------- alternation
    def alternate(self, W: FloatArray, members: list[list[int]]) -> tuple[MinMaxTree, list[float]]:
        root = Op("max", tuple(Op("min", tuple(g)) if len(g) > 1 else g[0] for g in members))
        if len(members) == 1:
            root = root.children[0]  # type: ignore[assignment]  # one group: its min (or lone piece)
        if not self.p.max_sweeps:
            # No sweeps (the default): only the loss is wanted, from the tree's own
            # evaluation (rows per piece), not the (samples x pieces) matrix the sweeps need.
            # Over an even subsample of at most LOSS_SAMPLES samples: the loss and RMSE are
            # reported, not optimised (at a million features all 2.5M samples took 1.4 s).
            tree = MinMaxTree(self.basis, W, root)
            self.loss_rows = slice(None, None, max(1, -(-self.samples.r.size // LOSS_SAMPLES)))
            s = self.samples
            self.prediction = tree.predict(s.alpha[self.loss_rows], s.h[self.loss_rows], s.r[self.loss_rows])
            return tree, [self.total_loss(self.prediction, self.loss_rows)]
        X, m = self.X, self.m
        n = X.shape[0]
        V = X @ W.T
        G = np.column_stack([V[:, g].min(axis=1) for g in members])
        F = G.max(axis=1)
        loss = self.total_loss(F)
        history = [loss]
        group_of = {piece: gi for gi, g in enumerate(members) for piece in g}
        n_groups = len(members)
        for sweep in range(int(self.p.max_sweeps)):
            before = loss
            for piece in range(W.shape[0]):
                gi = group_of[piece]
                others = [q for q in members[gi] if q != piece]
                in_group = V[:, others].min(axis=1) if others else np.full(n, np.inf)
                if n_groups > 1:
                    other_groups = np.delete(G, gi, axis=1).max(axis=1)
                else:
                    other_groups = np.full(n, -np.inf)
                current = V[:, piece]
                active = (current <= in_group) & (current >= other_groups)
                if active.sum() < X.shape[1]:
                    continue
                rows = np.flatnonzero(active)
                candidate = self.solve_piece(rows, self.irls_weights(F[rows] - m[rows], self.w[rows], self.hit[rows]))
                if candidate is None or np.array_equal(candidate, W[piece]):
                    continue
                for step in (1.0, 0.5):
                    trial = candidate if step == 1.0 else self.project(W[piece] + step * (candidate - W[piece]))
                    values = X @ trial
                    group_value = np.minimum(in_group, values)
                    F_new = np.maximum(other_groups, group_value)
                    new_loss = self.total_loss(F_new)
                    if new_loss < loss:
                        W[piece] = trial
                        V[:, piece] = values
                        G[:, gi] = group_value
                        F = F_new
                        loss = new_loss
                        break
            history.append(loss)
            if self.progress is not None:
                offset = getattr(self, "progress_offset", 0)
                self.progress(offset + sweep + 1, offset + int(self.p.max_sweeps))
            if before - loss <= self.p.tol * max(before, 1e-12):
                break
        self.prediction = F
        return MinMaxTree(self.basis, W, root), history


# ====================================================================== helpers
def pan_weight(a1: float, a2: float) -> float:
    """``hypot(a1, a2)``, computed as :attr:`MinMaxTree.angle_weight` computes it.

    The constraint ``|dF/dalpha| <= a_max`` is checked (by the loader and the slope
    bounds) with numpy's ``hypot``, which can be an ulp above ``math.hypot`` for the same
    pair; a piece projected with the other function could then load as breaking it.
    """
    return float(np.hypot(a1, a2))


#: Pan-angle bins of :func:`focus_samples`.
FOCUS_ANGLE_BINS = 120
#: An obstacle is where at least this many hit samples (two per feature) lie within a
#: short stretch of distance: three features.
FOCUS_SUPPORT = 6
#: The stretch: this fraction of the distance plus :data:`FOCUS_WINDOW_ABS` metres.
FOCUS_WINDOW = 0.1
FOCUS_WINDOW_ABS = 0.05
#: Samples up to this fraction (and the window) beyond the first obstacle are kept.
FOCUS_MARGIN = 0.1


def adaptive_support(n_rays: int) -> tuple[int, int]:
    """Hit samples that make an obstacle, and the frontier's rank, for ``n_rays`` features.

    Sparse data has fewer features per obstacle, and fewer mismatches per bin to guard
    against: three features (six hit samples) and the sixth-farthest ray end at 10k
    features, two features and the second-farthest ray end around 2k, 14 features and
    the 60th-farthest ray end at 100k.
    """
    per_bin = n_rays / FOCUS_ANGLE_BINS
    # Both keep growing with the density beyond 10k features: mismatches grow with it, and
    # a fixed three-feature cluster made of them stood in front of every surface at 100k
    # features (IoU 0.29 instead of 0.69 in office). The support grows slowly, though: a
    # horizontal surface (a table top) spreads its hits over a metre of distance, so a
    # short window holds few of them (per_bin / 30 lost the table at 100k features).
    support = 2 * max(int(np.clip(round(per_bin / 30.0), 2, 3)), round(per_bin / 60.0))
    rank = max(2, round(per_bin / 14.0))
    return support, rank


#: Within this horizontal distance (m) of the sensor an obstacle needs proportionally more
#: hits: ``support * NEAR_SUPPORT_DISTANCE / distance``. Two mismatches 0.33 m away (corridor,
#: 2k features, seed 5) had boxed the robot in. 0.6 m fixed that, moved no other map of
#: 4 scenes x 8 seeds at 1k-10k features by more than a few hundredths of IoU (most not
#: at all) and added no collision; 1.0 m let two office maps collide (0.97 %).
NEAR_SUPPORT_DISTANCE = 0.6

#: The return guard's line-of-sight test (:meth:`OccupancyRegressor._return_guard`): rays
#: must pass within 1 cm (+ 1 % of the distance) of a return's height, three of them and
#: three times as many as end near it, to drop it.
GUARD_SIGHT_TOLERANCE = (0.01, 0.01)
GUARD_SIGHT_RATIO = 3
#: Returns of each guard bin tested for support at first, nearest first (then twice as
#: many more, and so on, in the bins where none was confirmed).
GUARD_TEST_CHUNK = 16
#: Returns this far (m) above or below the body band still confirm a guarded return (a
#: sign hanging into the band is confirmed by its part above it).
SUPPORT_HEIGHT_REACH = 0.5
#: Pan-angle bins of the line-of-sight test (:func:`contradicted_features`).
SIGHT_BINS = 120
#: A ray passes "through" a feature when it crosses the feature's horizontal distance
#: within this many metres of the feature's height, plus this share of the distance. Tight,
#: because rays grazing a horizontal surface (a table top seen from above) end on it a
#: little farther on: 5 cm + 10 % counted those as passing through the nearer part.
SIGHT_HEIGHT_TOLERANCE = 0.02
SIGHT_HEIGHT_SHARE = 0.02
#: Rays per bin tested against each feature at most (an even subsample beyond that), so
#: the test stays linear in the number of features.
SIGHT_MAX_RAYS = 128
#: Features of the line-of-sight test evaluated at once.
SIGHT_BLOCK = 1 << 16


def contradicted_features(features: Features, origin: float = 0.0,
                          candidates: NDArray[np.bool_] | None = None, *,
                          tolerance: tuple[float, float] = (SIGHT_HEIGHT_TOLERANCE, SIGHT_HEIGHT_SHARE),
                          ratio: int = 2) -> NDArray[np.bool_]:
    """Features that other rays in nearly the same direction pass through.

    A real surface stops the rays that meet it. A mismatch registered at a wrong, shorter
    range sits in space that other rays of its pan-angle bin cross on their way to
    something farther. A feature is contradicted when at least two rays of its bin
    (:data:`SIGHT_BINS`), and at least twice as many as end near it (itself included),
    pass within :data:`SIGHT_HEIGHT_TOLERANCE` (+ :data:`SIGHT_HEIGHT_SHARE` of the
    distance) of its height at its horizontal distance
    and end beyond the focus window (:data:`FOCUS_WINDOW`, :data:`FOCUS_WINDOW_ABS`).
    Near the robot the height tolerance spans a wide tilt range, so isolated mismatches
    there, which would box the robot in, are the ones most surely caught. The bins start
    at the pan angle ``origin``; only the ``candidates`` (default: all) are tested, every
    feature counts as a ray.
    """
    alpha, h, r = features.polar()
    contradicted = np.zeros(r.size, dtype=bool)
    if r.size == 0:
        return contradicted
    distance = np.sqrt(np.maximum(r**2 - h**2, 0.0))
    bins = angle_bins(alpha - origin, SIGHT_BINS)
    order = np.argsort(bins, kind="stable")
    counts = np.bincount(bins, minlength=SIGHT_BINS)
    starts = np.cumsum(counts) - counts
    # Each bin's rays: all its features, or an even subsample of them.
    step = np.maximum(1, counts // SIGHT_MAX_RAYS)
    n_rays = np.where(counts > 0, -(-counts // step), 0)
    ray_bin = np.repeat(np.arange(SIGHT_BINS), n_rays)
    slot = np.arange(ray_bin.size) - np.repeat(np.cumsum(n_rays) - n_rays, n_rays)
    rays = order[starts[ray_bin] + slot * step[ray_bin]]
    tested = np.flatnonzero(counts[bins] >= 3)
    if candidates is not None:
        tested = tested[candidates[tested]]
    if tested.size == 0:
        return contradicted
    # A ray passes a feature when it ends beyond it (d > D + window) and its height at the
    # feature's distance, z D / d, lies within `within` of the feature's: an interval of
    # the ray's elevation z / d. With the rays sorted by bin, then elevation (as an angle,
    # so the key is bounded), each feature's candidate rays are one run; the exact test is
    # made on those pairs alone (trying every ray of the bin: 2.3x the time at 10k and
    # 100k features, the same answer). Rays ending near the feature, which can save it,
    # are a run of the rays sorted by bin, then distance.
    d_ray, z_ray = distance[rays], h[rays]
    ahead = d_ray > 0
    elevation_key = 4.0 * ray_bin[ahead] + np.arctan2(z_ray[ahead], d_ray[ahead])
    order = np.argsort(elevation_key, kind="stable")
    by_elevation = (elevation_key[order], rays[ahead][order])
    lane = 2.0 * float(distance.max()) + 1.0
    order = np.lexsort((d_ray, ray_bin))
    by_distance = (ray_bin[order] * lane + d_ray[order], rays[order])
    for first in range(0, tested.size, SIGHT_BLOCK):  # blocks of features bound the pairs' memory
        block = tested[first:first + SIGHT_BLOCK]
        D, H = distance[block], h[block]
        window = D * FOCUS_WINDOW + FOCUS_WINDOW_ABS
        within = tolerance[0] + tolerance[1] * D
        D_safe = np.maximum(D, 1e-12)
        owner, pair_ray = _runs(*by_elevation, 4.0 * bins[block] + np.arctan((H - within) / D_safe) - 1e-9,
                                4.0 * bins[block] + np.arctan((H + within) / D_safe) + 1e-9)
        d, z, D_pair = distance[pair_ray], h[pair_ray], D[owner]
        with np.errstate(divide="ignore", invalid="ignore"):
            passes = (d > D_pair + window[owner]) & (np.abs(z * D_pair / d - H[owner]) < within[owner])
        beyond = np.bincount(owner, weights=passes, minlength=block.size)
        maybe = np.flatnonzero(beyond >= ratio)
        if maybe.size == 0:
            continue
        D, H, window, within, beyond = D[maybe], H[maybe], window[maybe], within[maybe], beyond[maybe]
        owner, pair_ray = _runs(*by_distance, bins[block[maybe]] * lane + (D - window) - 1e-9,
                                bins[block[maybe]] * lane + (D + window) + 1e-9)
        ends_near = (np.abs(distance[pair_ray] - D[owner]) <= window[owner]) & (
            np.abs(h[pair_ray] - H[owner]) < within[owner])
        near = np.maximum(np.bincount(owner, weights=ends_near, minlength=maybe.size), 1)
        contradicted[block[maybe]] = beyond >= np.maximum(ratio, ratio * near)
    return contradicted


def _runs(keys: FloatArray, items: NDArray[np.intp], low: NDArray[np.floating[Any]],
          high: NDArray[np.floating[Any]]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Every pair (query ``i``, item) whose key lies in ``[low[i], high[i]]``, for ``keys``
    sorted ascending: the query's index and the item, one row per pair."""
    first = np.searchsorted(keys, low, side="left")
    span = np.maximum(np.searchsorted(keys, high, side="right") - first, 0)
    owner = np.repeat(np.arange(span.size), span)
    return owner, items[np.repeat(first - np.cumsum(span) + span, span) + np.arange(owner.size)]


def first_obstacle_distance(alpha: FloatArray, distance: FloatArray, n_bins: int,
                            support: int = FOCUS_SUPPORT, *, front: int = 0, cap: float = np.inf) -> FloatArray:
    """Per pan-angle bin, the horizontal distance of the nearest cluster of hits.

    Isolated outliers (mismatches at a random range) must not count as an obstacle, so
    the first obstacle is the nearest hit followed by at least ``support`` - 1
    more hits within :data:`FOCUS_WINDOW` of its distance (``support`` times
    :data:`NEAR_SUPPORT_DISTANCE` / distance nearer than that distance). Its distance is
    that of the cluster's hit ``front`` places on from its nearest (within its window),
    but at most ``cap`` times the hit ``front // 2`` places on: ``front > 0`` takes a low quantile of the
    cluster, which stays at a surface however many noisy returns there are, and ``cap``
    keeps a surface seen at a grazing angle (a table top, hits spread over its depth) at
    its front edge. ``inf`` where there is none.
    """
    distance, bounds = sorted_within_bins(angle_bins(alpha, n_bins), distance, n_bins)
    bins = np.repeat(np.arange(n_bins), np.diff(bounds))
    # One sortable key: bin number, then distance (distances are far below 1e6 m).
    key = bins * 1e6 + distance
    reach = np.searchsorted(key, key + distance * FOCUS_WINDOW + FOCUS_WINDOW_ABS, side="right")
    # Near the robot a real surface spans a wide tilt range and many rays end on it, while
    # two mismatches there box the robot in: within NEAR_SUPPORT_DISTANCE the support grows
    # as 1 / distance.
    needed = support * np.maximum(1.0, NEAR_SUPPORT_DISTANCE / np.maximum(distance, 1e-9))
    supported = (reach - np.arange(key.size)) >= needed
    index = np.flatnonzero(supported)
    ahead = np.minimum(index + front, reach[index] - 1)
    # The cap counts from half way to the front, not from the nearest return:
    # at 100k features a mismatch a few centimetres in front of a dense wall starts a
    # cluster whose window reaches the wall, and capping from it held the crossing 12-15 cm
    # short of the wall.
    anchor = np.minimum(index + front // 2, reach[index] - 1)
    first = np.full(n_bins, np.inf)
    np.minimum.at(first, bins[index], np.minimum(distance[ahead], cap * distance[anchor]))
    return first


def group_by_bin(bins: NDArray[np.intp], n_bins: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The order that groups ``bins`` by bin (stable: ascending index within a bin) and the
    ``n_bins + 1`` bounds of the bins' runs in it. A radix sort of small integers."""
    small = np.int16 if n_bins <= np.iinfo(np.int16).max else np.int32
    order = np.argsort(bins.astype(small), kind="stable")
    bounds = np.zeros(n_bins + 1, dtype=np.intp)
    np.cumsum(np.bincount(bins, minlength=n_bins), out=bounds[1:])
    return order, bounds


def sorted_within_bins(bins: NDArray[np.intp], values: FloatArray,
                       n_bins: int) -> tuple[FloatArray, NDArray[np.intp]]:
    """``values`` grouped by bin (bin 0 first), ascending within each bin.

    Returns the grouped values and the ``n_bins + 1`` bounds of the bins' runs. Grouping
    is a stable radix sort of small integers and only the runs are sorted, several times
    faster than a two-key ``lexsort`` at a million samples, with the same result.
    """
    order, bounds = group_by_bin(bins, n_bins)
    grouped = values[order]
    for first, end in zip(bounds[:-1], bounds[1:]):  # a loop over bins; each run sorts in place
        grouped[first:end].sort()
    return grouped, bounds


def focus_samples(samples: Samples, robot: Robot, focus_range: float = np.inf, *,
                  floor_is_obstacle: bool = False) -> Samples:
    """Keep the samples a monotone occupancy function can honour and navigation needs.

    ``F`` increases with ``r``, and the navigation polygon is cut by the nearest obstacle
    at any height of the robot's body. Behind that obstacle the samples (the wall above a
    low box, the free rays over it) can only pull the fit away from the box, so per
    pan-angle bin the samples farther (horizontally) than the first obstacle in the body's
    height band (:func:`first_obstacle_distance`, plus a margin) are dropped, as are samples
    outside the height band: the navigation map never looks there, and samples farther
    than ``focus_range`` (horizontally).
    """
    low = robot.floor_h - 0.05
    high = max(robot.body_band[1], 0.0) + 0.1
    in_band = (samples.h >= low) & (samples.h <= high)
    distance = np.sqrt(np.maximum(samples.r**2 - samples.h**2, 0.0))
    band_low, band_high = robot.body_band
    if floor_is_obstacle:
        band_low = -np.inf
    hit = (samples.kind == SAMPLE_KINDS["hit"]) & (samples.h >= band_low) & (samples.h <= band_high)
    support, _ = adaptive_support(samples.count("robot"))
    first = first_obstacle_distance(samples.alpha[hit], distance[hit], FOCUS_ANGLE_BINS, support)
    limit = first * (1.0 + FOCUS_WINDOW + FOCUS_MARGIN) + FOCUS_WINDOW_ABS
    limit = np.minimum(limit, focus_range)
    in_front = distance <= limit[angle_bins(samples.alpha, FOCUS_ANGLE_BINS)]
    always = np.isin(samples.kind, [SAMPLE_KINDS["robot"], SAMPLE_KINDS["footprint"], SAMPLE_KINDS["frontier"]])
    return samples.select(always | (in_band & in_front))


#: Heights of the body band that get a frontier sample.
FRONTIER_HEIGHTS = 4
#: The frontier stands this share beyond the observed extent, no farther: an untextured
#: wall may stand right behind the last floor seen (10 % + 5 cm let the robot touch the
#: open scene's white wall at 3k features with the wider default reach).
FRONTIER_MARGIN = 0.03
FRONTIER_ABS = 0.0
#: Unseen space this close to the body (m) is taken as free: what the robot swept to get
#: there. (Before the frontier's own margin shrank, it was 0.1 m plus that margin.)
UNSEEN_CLEARANCE = 0.185


def frontier_samples(samples: Samples, robot: Robot, focus_range: float, *, planar: bool = False) -> Samples:
    """Occupied samples where the observed free space ends short of ``focus_range``.

    A ray is evidence of free space up to its end; beyond the farthest ray ends of a
    pan-angle bin nothing has been seen, an untextured wall may stand there, and linear
    pieces would extrapolate the free space into it. A bin's observed extent is the
    distance of its k-th farthest ray end (k from :func:`adaptive_support`), so that a few
    mismatches registered beyond a surface do not open it up; a bin shorter than both its
    neighbours takes the nearer neighbour's extent. One occupied sample (value 1) per
    height of the body band is placed just beyond the bin's observed extent.
    """
    # The ray ends are the hit samples and the free samples of floor features.
    kind = samples.kind
    rays = (kind == SAMPLE_KINDS["hit"]) | (kind == SAMPLE_KINDS["near"]) | (kind == SAMPLE_KINDS["floor"])
    distance = np.sqrt(np.maximum(samples.r[rays] ** 2 - samples.h[rays] ** 2, 0.0))
    order, bounds = group_by_bin(angle_bins(samples.alpha[rays], FOCUS_ANGLE_BINS), FOCUS_ANGLE_BINS)
    distance = distance[order]
    # A planar scan has one beam a direction and no mismatches: its farthest end is seen.
    rank = 1 if planar else adaptive_support(samples.count("robot"))[1]
    extent = np.zeros(FOCUS_ANGLE_BINS)
    for b, (first, end) in enumerate(zip(bounds[:-1], bounds[1:])):  # a loop over bins
        if end - first >= rank:
            # The rank-th farthest ray end: a partition, not a sort, of the bin's ends.
            extent[b] = np.partition(distance[first:end], end - first - rank)[end - first - rank]
    # A bin short of both its neighbours is a gap between sparse rays, not an edge of the
    # seen space: it takes the nearer neighbour's extent. (At 2k features one such bin in
    # the office doorway, 6 floor features ending at 1.7 m, closed the doorway in two of
    # three seeds; an edge, like the end of the open scene's untextured wall, keeps its
    # extent, since one neighbour is as short.)
    extent = np.maximum(extent, np.minimum(np.roll(extent, 1), np.roll(extent, -1)))
    short = np.flatnonzero(extent < focus_range)
    width = 2.0 * np.pi / FOCUS_ANGLE_BINS
    low, high = robot.body_band
    heights = np.linspace(low, high, FRONTIER_HEIGHTS)
    A, H = np.meshgrid(-np.pi + (short + 0.5) * width, heights, indexing="ij")
    # The body itself is known free (footprint samples): an unseen direction is closed
    # UNSEEN_CLEARANCE outside it, not inside it, so the robot is never in collision where
    # it stands and can turn and back off a little where it cannot see (behind a laser).
    reach = np.maximum(extent[short] * (1.0 + FRONTIER_MARGIN) + FRONTIER_ABS, robot.radius + UNSEEN_CLEARANCE)
    D = np.repeat(reach, FRONTIER_HEIGHTS).reshape(A.shape)
    A, H, D = A.ravel(), H.ravel(), D.ravel()
    return Samples(A, H, np.hypot(D, H), np.ones_like(A), np.ones_like(A),
                   np.full(A.shape, SAMPLE_KINDS["frontier"], dtype=np.int8))


def join_samples(*parts: Samples) -> Samples:
    """Concatenate sample sets."""
    return Samples(*(np.concatenate([getattr(p, name) for p in parts])
                     for name in ("alpha", "h", "r", "m", "weight", "kind")))


def profile_bins(n_rays: int) -> int:
    """Pan-angle bins of the range profile for ``n_rays`` features (120, 240 or 360)."""
    thirds = int(np.clip(round(3 * n_rays / PROFILE_FULL_DENSITY), 1, 3))
    return PROFILE_BINS * thirds // 3


def wrap_angle(alpha: FloatArray) -> FloatArray:
    """Angles wrapped into [-pi, pi)."""
    return np.mod(np.asarray(alpha) + np.pi, 2.0 * np.pi) - np.pi


def mean_direction(alpha: FloatArray) -> float:
    """The direction of the mean unit vector of pan angles ``alpha`` (0 if there are none)."""
    if alpha.size == 0:
        return 0.0
    x, y = float(np.cos(alpha).sum()), float(np.sin(alpha).sum())
    return math.atan2(y, x) if math.hypot(x, y) > 1e-9 * alpha.size else 0.0


def angle_bins(alpha: FloatArray, n_bins: int) -> NDArray[np.intp]:
    """Index of the angular bin (of ``n_bins`` over [-pi, pi)) holding each angle."""
    index = np.floor((np.asarray(alpha) + np.pi) * (n_bins / (2.0 * np.pi))).astype(np.intp)
    return np.mod(index, n_bins)


def segment_near_runs(profile: FloatArray, far: NDArray[np.bool_], n_segments: int,
                      max_length: int) -> list[tuple[int, int]]:
    """Cover the near bins of a profile with at most ``n_segments`` runs.

    Dynamic programming over cut positions: a run costs the area between the profile
    and the run's nearest value (what a conservative piece gives away), a stretch of far
    bins may be skipped for free. Returns ``(first, end)`` pairs, ``end`` exclusive.
    """
    n = profile.shape[0]
    y = profile.astype(np.float64)
    far = np.asarray(far, dtype=bool)
    sums = np.concatenate([[0.0], np.cumsum(y)])
    # Runs by their end j (0..n) and length l, longest first, so that the first least
    # cost found is the one with the earliest start, as a scan over starts would find.
    longest = max(1, min(int(max_length), n))
    lengths = np.arange(longest, 0, -1)
    ends = np.arange(n + 1)
    starts = ends[:, None] - lengths[None, :]
    valid = starts >= 0
    starts = np.maximum(starts, 0)
    # min(y[j - l:j]) for l = 1..longest: a running minimum back from each end.
    back = np.where(valid[:, ::-1], y[np.maximum(ends[:, None] - lengths[None, ::-1], 0)], np.inf)
    run_min = np.minimum.accumulate(back, axis=1)[:, ::-1]
    area = sums[ends][:, None] - sums[starts] - run_min * lengths
    cost = np.where(valid, np.maximum(area, 0.0) + 1e-9 * lengths**2, np.inf)
    # Far runs [a, b): from any cut in [a, b) a skip reaches any later cut up to b.
    edges = np.flatnonzero(np.diff(np.concatenate([[0], far.astype(np.int8), [0]])))
    far_runs = list(zip(edges[::2].tolist(), edges[1::2].tolist()))
    leading = far_runs[0][1] if far_runs and far_runs[0][0] == 0 else 0
    # best[g][j]: least cost covering bins [0, j) with g runs; a skip may follow a run.
    best = np.full(n + 1, np.inf)
    best[: leading + 1] = 0.0
    layers = [best]
    # Layer 0 has no runs to trace back.
    run_from = [np.zeros(0, dtype=np.intp)]
    skip_from = [np.zeros(0, dtype=np.intp)]
    rows = np.arange(n + 1)
    for _ in range(n_segments):
        total = layers[-1][starts] + cost
        pick = np.argmin(total, axis=1)
        after_run = total[rows, pick]
        from_run = rows - lengths[pick]
        after_skip = np.full(n + 1, np.inf)
        from_skip = np.zeros(n + 1, dtype=np.intp)
        for a, b in far_runs:  # a loop over far runs, not bins
            values = after_run[a:b]
            running = np.minimum.accumulate(values)
            better = values < np.concatenate([[np.inf], running[:-1]])
            first = np.maximum.accumulate(np.where(better, np.arange(b - a), 0))
            after_skip[a + 1: b + 1] = running
            from_skip[a + 1: b + 1] = a + first
        use_skip = after_skip < after_run
        layers.append(np.where(use_skip, after_skip, after_run))
        run_from.append(from_run)
        skip_from.append(np.where(use_skip, from_skip, -1))
    finals = [layer[n] for layer in layers]
    g = int(np.argmin(finals))
    if not np.isfinite(finals[g]) or g == 0:
        return [(0, n)]
    segments = []
    position = n
    while g > 0:
        source = int(skip_from[g][position])
        if source >= 0:
            position = source
        start = int(run_from[g][position])
        segments.append((start, position))
        position = start
        g -= 1
    return segments[::-1]


def segment_cost(profile: FloatArray, first: int, end: int) -> float:
    """Squared error of the best line through a (circular) run of the profile."""
    y = profile[np.mod(np.arange(first, end), profile.shape[0])]
    if y.size < 3:
        return 0.0
    x = np.arange(y.size, dtype=np.float64)
    coefficients = np.polyfit(x, y, 1)
    return float(np.sum((np.polyval(coefficients, x) - y) ** 2))


__all__ = ["DEFAULT_BASIS", "OccupancyRegressor", "box_qp", "features_digest", "huber_loss", "slope_bounds"]
