"""The estimator: :class:`OccupancyRegressor`, its parameters, fit and fitted state.

``fit`` screens the features (:mod:`occtool.fit._screen`), makes the sensor model's samples
and focuses them (:mod:`occtool.fit._focus`), then builds the tree
(:mod:`occtool.fit._construction`; its loss and refit sweeps in :mod:`occtool.fit._refit`).
The scikit-learn estimator contract holds: keyword-only parameters read from ``__init__``,
``get_params``/``set_params``, fitted attributes ending in ``_``.
"""

from __future__ import annotations

import hashlib
import inspect
import logging
import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError, NotFittedError
from occtool.features import FeatureGeometry, Features
from occtool.fit._construction import _Fitter
from occtool.fit._focus import focused_blocks
from occtool.fit._refit import ProgressCallback
from occtool.fit._screen import guarded_mask, profile_returns, screen_features
from occtool.guard import SPREAD_SHARE, ReturnGuard, build_guard, guard_candidates
from occtool.limits import MAX_DISTANCE, MAX_PIECES, MAX_SWEEPS, MAX_WEIGHT
from occtool.linear_program_batch import Steps, solved, solved_together
from occtool.robot import Robot
from occtool.sensor import SAMPLE_KINDS, Samples, SensorModel
from occtool.tree import BASES, InverseTree, MinMaxTree, Op

log = logging.getLogger("occtool.fit")

#: Bytes allocated and freed before a process's first fit (:func:`_prepare_allocator`).
ALLOCATOR_WARM_UP = 8 << 20
_allocator_ready = False


def _prepare_allocator() -> None:
    """Allocate and free :data:`ALLOCATOR_WARM_UP` bytes, once per process, untouched.

    glibc's malloc serves blocks above its mmap threshold (128 KB at first) with fresh
    pages from the kernel and returns them when freed, and raises the threshold to the
    size of such a block when it is freed. A fit's temporaries of a few hundred KB to
    4 MB were thus fresh pages, page-faulted in one by one, until ones as large had come
    and gone: the narrow aisle's first fit in a process (9k features) took 3,300 page
    faults, 1,750 after this, and the second 740 -> 20 (each a few microseconds on this
    project's machine). Elsewhere (another allocator) it is an untouched block freed.
    Blocks beyond the threshold's cap (32 MB: a million features' arrays) are unaffected.
    """
    global _allocator_ready
    if not _allocator_ready:
        _allocator_ready = True
        del_me = np.empty(ALLOCATOR_WARM_UP, dtype=np.uint8)
        del del_me

FloatArray = NDArray[np.float64]

DEFAULT_BASIS = "trig"
#: 64 pieces (16 groups) and a 4 m reach: with 32 and 2.5 m the fit gave the held-out
#: AUC away (0.83 on 4 scenes at 10k features, 0.84 per Intel position against the grid's
#: 0.95) to model the first 2.25 m only; 64 and 4 m reach 0.91 and 0.92 for the same map
#: IoU (0.80 against 0.81), in a model of about 13 KB.
DEFAULT_PIECES = 64
#: Beyond this many features a position gets more pieces by default (:func:`default_pieces`):
#: a 5 cm grid sharpens with every ray its cells gain, a fixed number of pieces does not.
#: 128 pieces instead of 64 at 100k features, seeds 0-1 (2026-12-03, fresh processes, the
#: careful grid's scoring): the narrow aisle's IoU 0.755 -> 0.806 and 0.770 -> 0.781, its
#: held-out AUC in front of the first obstacle 0.980 -> 0.990 and 0.981 -> 0.991, the
#: corridor's IoU 0.881 -> 0.900, the unseen rooms' narrow aisle 0.660 -> 0.762 and dense
#: clutter's front AUC 0.973 -> 0.980; no room lower by more than 0.001, no violation; the
#: fit of 1M features 0.43 -> 0.52 s. At 10k the fit costs 40 % more with 128 pieces,
#: which is why the count grows only beyond it.
MORE_PIECES_FROM = 10_000
#: The most pieces :func:`default_pieces` gives (from 40k features on).
MOST_DEFAULT_PIECES = 128
DEFAULT_FOCUS_RANGE = 4.0
#: A planar laser's focus range (:func:`occtool.modelset.estimator_for_log`): a laser's
#: returns hold their accuracy far beyond a stereo camera's 4 m. Per-position held-out
#: AUC against the 4 m default (every 25th position): Intel 0.929 -> 0.955, FR-079 0.926 ->
#: 0.942, ACES 0.918 -> 0.953, CSAIL 0.919 -> 0.937, Freiburg campus 0.837 -> 0.865, MIT
#: infinite corridor 0.915 -> 0.947; the mean polygon within 1.5 m about 3 % smaller (Intel
#: 1.47 -> 1.42 m2), none less safe. (The fused map keeps 4 m: docs/map.md.)
PLANAR_FOCUS_RANGE = 8.0
#: Features the pieces are placed from, at most (every ``ceil(n / FIT_FEATURES)``-th
#: beyond, less its mismatches; the return guard sees every feature). Measured at 1M
#: features, 7 scenes (seeds 0-2 for the office, 0-1 for the aisle): 250k instead of 1M
#: changed IoU by -0.013..+0.013 in about half the fit's time. (The office's collision
#: then depended on which quarter was drawn, 0-0.56 %, until the guard's subsampled
#: support was mended: docs/method.md, "Large positions".)
FIT_FEATURES = 250_000


def default_pieces(n_features: int) -> int:
    """The pieces a fit with ``pieces=None`` gives a position of ``n_features`` features:
    :data:`DEFAULT_PIECES` up to :data:`MORE_PIECES_FROM` features, then growing as the
    square root of the count (whole groups of four) up to :data:`MOST_DEFAULT_PIECES`.

    >>> default_pieces(5_000), default_pieces(20_000), default_pieces(100_000)
    (64, 88, 128)
    """
    if n_features <= MORE_PIECES_FROM:
        return DEFAULT_PIECES
    grown = DEFAULT_PIECES * math.sqrt(n_features / MORE_PIECES_FROM)
    return int(min(MOST_DEFAULT_PIECES, 4 * math.floor(grown / 4)))


def features_digest(features: Features) -> str:
    """sha256 of the features' points and evidence (little-endian float64), hex."""
    digest = hashlib.sha256()
    # The arrays' own buffers, not copies of them as bytes (a million features: 32 MB).
    digest.update(np.ascontiguousarray(features.points, dtype="<f8").data.cast("B"))
    digest.update(np.ascontiguousarray(features.evidence, dtype="<f8").data.cast("B"))
    return digest.hexdigest()



class OccupancyRegressor:
    """Fits ``m = F(alpha, h, r)`` as a MAX of MINs of linear pieces to range features.

    Parameters
    ----------
    pieces
        Number of linear pieces ``L`` (the paper used 8 and "less than 32"); ``None`` (the
        default) picks it from the features' count (:func:`default_pieces`: 64 up to 10,000
        features, up to 128 beyond).
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
        pieces: int | None = None,
        basis: str = DEFAULT_BASIS,
        c_min: float = 0.25,
        a_max: float = 12.0,
        b_max: float = 8.0,
        c_max: float = 8.0,
        level: float = 0.6,
        c_floor: float = 8.0,
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
        if self.pieces is not None:
            if (isinstance(self.pieces, bool) or not isinstance(self.pieces, (int, float, np.integer, np.floating))
                    or not math.isfinite(self.pieces) or int(self.pieces) != self.pieces or self.pieces < 1):
                raise InputError(f"pieces must be a whole number >= 1 or None, got {self.pieces!r}")
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
        if self.loss not in ("huber", "squared"):
            raise InputError(f"loss must be 'huber' or 'squared', got {self.loss!r}")
        if self.groups is not None and (int(self.groups) != self.groups or self.groups < 1
                                        or (self.pieces is not None and self.groups > self.pieces)):
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
        return solved(self.fit_steps(features, progress=progress))

    def fit_steps(self, features: Features, *, progress: ProgressCallback | None = None) -> Steps:
        """:meth:`fit` as steps: it yields the linear programmes that place the centre pieces,
        stacked, is sent their results, and returns ``self``, fitted. The fits of a few
        positions are run together this way (:func:`fit_together`), their programmes solved
        in one batch; a fit is the same however its programmes were solved."""
        started = time.perf_counter()
        _prepare_allocator()
        self._validate()
        sensor = self.sensor if self.sensor is not None else SensorModel()
        robot = self.robot if self.robot is not None else Robot()
        # Only background samples draw random numbers (numpy.random's first import is
        # 10-20 ms of a fresh process's first fit).
        rng = np.random.default_rng(self.seed) if sensor.background_samples else None
        if len(features) == 0:
            raise InputError("no features to fit")
        pieces = int(self.pieces) if self.pieces is not None else default_pieces(len(features))
        if self.groups is not None and self.groups > pieces:
            raise InputError(f"groups must be between 1 and the number of pieces ({pieces}), got {self.groups}")
        # Pan angles and distances of the features, computed once for the screen, the guard,
        # the samples and the range profile.
        geometry = FeatureGeometry.of(features)
        # The returns the guard may hold (computed once for the screen and the guard).
        may_hold = (guard_candidates(features, features.evidence, robot, self.level, horizontal=geometry.horizontal)
                    if self.guard else None)
        # A large position places its pieces from every `step`-th feature (FIT_FEATURES): only
        # those, and the returns the guard may hold, need the mismatch test.
        step = -(-len(features) // FIT_FEATURES)
        screened = None
        if step > 1:
            screened = np.zeros(len(features), dtype=bool)
            screened[::step] = True
            if may_hold is not None:
                screened |= may_hold
        screen = screen_features(features, sensor, robot, basis=self.basis, focus=self.focus,
                                 focus_range=self.focus_range, geometry=geometry, screened=screened)
        guard = None
        if self.guard:
            mask, scale, spacing = guarded_mask(features, screen, robot, level=self.level, focus=self.focus,
                                                focus_range=self.focus_range, geometry=geometry,
                                                may_hold=may_hold)
            guarded = np.flatnonzero(mask)  # a few hundred of a million features
            guard = build_guard(geometry.alpha.take(guarded), geometry.horizontal.take(guarded) * scale.take(guarded),
                                self.level, reach=SPREAD_SHARE * spacing)
        # The line-of-sight index served the screen and the guard; the samples need none of
        # it (at 10M features it holds 250 MB).
        screen = screen.without_sight()
        origin = screen.origin
        keep: NDArray[np.intp] | None = None
        if step > 1:
            # The pieces are placed from an even subsample: a few dozen linear pieces need no
            # more, and the samples of every feature would not fit in memory (10M features:
            # 50M samples, 5 GB). The return guard above saw every feature.
            keep = np.arange(0, len(features), step)
            keep = keep[~screen.mismatch.take(keep)]
        elif screen.mismatch.any():
            keep = np.flatnonzero(~screen.mismatch)
        if keep is None:
            usable = features
        else:
            usable = features.select(keep)
            geometry = geometry.select(keep, usable.points)
        # The samples with their pan angles measured from the origin, as the fit bins them.
        blocks = sensor._sample_blocks(usable, robot, rng, turn=origin, geometry=geometry)
        if sum(block.count(SAMPLE_KINDS[kind]) for block in blocks for kind in ("hit", "near", "floor")) == 0:
            raise InputError("no features left to fit (every feature was dropped as floor)")
        if self.focus:
            # Only the samples the focus keeps are written (focused_with_frontier, in one pass).
            turned = focused_blocks(blocks, robot, self.focus_range, planar=screen.planar,
                                    floor_is_obstacle=sensor.floor == "obstacle")
        else:
            turned = Samples.of_blocks(blocks)
        del blocks
        fitter = _Fitter(self, turned, robot, profile_returns(usable, sensor, robot, origin, geometry),
                         pieces=pieces, floor_is_obstacle=sensor.floor == "obstacle", depth_error=sensor.depth_error,
                         progress=progress)
        tree, loss_history = yield from fitter.run_steps()
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
        #: What the position observed (an :class:`occtool.fuse.Observation`), where a model
        #: file of a set keeps one (the model reader fills it in; a fit leaves it ``None``).
        self.observed_: Any = None

    def guarded_returns(self, features: Features) -> NDArray[np.bool_]:
        """Which of ``features`` the return guard holds (:mod:`occtool.guard`): the returns
        every navigation map of a model fitted to them keeps the robot's radius from.

        A function of the features and the estimator's parameters alone (fitted or not).
        """
        self._validate()
        sensor = self.sensor if self.sensor is not None else SensorModel()
        robot = self.robot if self.robot is not None else Robot()
        screen = screen_features(features, sensor, robot, basis=self.basis, focus=self.focus,
                                 focus_range=self.focus_range)
        return guarded_mask(features, screen, robot, level=self.level, focus=self.focus,
                            focus_range=self.focus_range)[0]

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



def fit_together(params: dict[str, Any], chunk: Sequence[Features]) -> list[OccupancyRegressor | Exception]:
    """``OccupancyRegressor(**params).fit(features)`` of each of a few positions' ``features``,
    or the exception it raised: the fits run in turns (:meth:`OccupancyRegressor.fit_steps`),
    the linear programmes they ask for at the same turn solved in one batch
    (:func:`occtool.linear_program_batch.solved_together`), which is the larger share of a
    small fit's programmes' cost (the campus's 1571 keyframes' programmes: 4.3 s one fit at a
    time, 2.1 s sixteen at a time). Every model is the one its own fit makes; its
    ``fit_seconds_`` counts its own steps and its share of the batches'."""
    models = [OccupancyRegressor(**params) for _ in chunk]
    out: list[OccupancyRegressor | Exception] = []
    for model, (_, error, seconds) in zip(models, solved_together(
            [model.fit_steps(features) for model, features in zip(models, chunk)])):
        if error is None:
            model.fit_seconds_ = seconds
            out.append(model)
        elif isinstance(error, Exception):
            out.append(error)
        else:
            raise error
    return out


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

