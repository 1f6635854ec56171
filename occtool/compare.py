"""The parametric model against occupancy grids, on the same features and the same output.

:func:`compare_grid` fits the parametric model and builds the baselines from the same
features (less a held-out share), extracts the navigation polygon from each with the
same settings, and reports what each costs (samples, time, memory) and how each does
(agreement with the parametric polygon, IoU and safety against a scene's truth, ROC AUC
of occupancy on held-out features). The report is a plain dict, the layout of
``occtool compare-grid --json`` (see docs/comparison.md).

Baselines, each a :class:`Baseline` (a name, a build function, its samples and figures)
whose built map offers the :class:`OccupancyMap` protocol (``inverse_range``,
``occupancy``, ``memory_bytes``, ``file_bytes``); every baseline goes through the same
build, extraction and scoring:

* ``grid`` (:data:`GRID`): the dense 3D grid of :mod:`occtool.grid`, fed with the same
  sensor model;
* ``octomap`` (:data:`OCTOMAP`): OctoMap through ``pyoctomap`` (:mod:`occtool.octomap`),
  optional.

Both get the parametric model's prior on the robot's footprint (it is free), since the
robot's own sensor never sees the columns under it. Their navigation polygons read
unobserved space as free (the default) or, with ``unknown="occupied"``, as a careful
planner does: closed where no cell of the column was observed in the robot's body band.
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import shapely
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Features, polar
from occtool.robot import Robot

if TYPE_CHECKING:
    from occtool.fit import OccupancyRegressor

FloatArray = NDArray[np.float64]

#: Fractions of a held-out feature's range where the "free" test points lie.
FREE_FRACTIONS = (0.25, 0.5, 0.75)

REPORT_VERSION = 1

#: The report's ``unknown_space`` line for each reading of unobserved space.
UNKNOWN_SPACE_NOTES = {
    "free": (
        "unobserved grid cells keep the prior 0.5, free for thresholds above 0.5: "
        "the grids read unseen space as free"
    ),
    "occupied": (
        "the grids' rays also end at the first cell whose column has no observed cell between heights "
        "{low:g} and {high:g} m (the body band): the grids read unseen space as occupied"
    ),
}

logger = logging.getLogger("occtool.compare")


def roc_auc(occupied: FloatArray, free: FloatArray) -> float:
    """Area under the ROC curve of scores for "occupied" against "free" points.

    The Mann-Whitney statistic: the probability that a random occupied point scores above
    a random free one, ties counting half. NaN when either set is empty.
    """
    from scipy.stats import rankdata

    occupied = np.asarray(occupied, dtype=np.float64)
    free = np.asarray(free, dtype=np.float64)
    n_occ, n_free = occupied.size, free.size
    if n_occ == 0 or n_free == 0:
        return float("nan")
    ranks = rankdata(np.concatenate([occupied, free]))
    return float((ranks[:n_occ].sum() - n_occ * (n_occ + 1) / 2.0) / (n_occ * n_free))


def polygon_iou(a: shapely.Geometry, b: shapely.Geometry) -> float:
    """Intersection over union of two areas; 1 when both are empty."""
    area_a, area_b = float(a.area), float(b.area)
    if area_a == 0.0 and area_b == 0.0:
        return 1.0
    overlap = float(shapely.intersection(a, b).area)
    union = area_a + area_b - overlap
    return overlap / union if union > 0 else 0.0


def split_holdout(n: int, holdout: float, seed: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices of the features used to build the models and of the held-out ones.

    Parameters
    ----------
    n
        Number of features.
    holdout
        Share held out, in [0, 0.5].
    seed
        Seed of the random split.
    """
    if not 0.0 <= holdout <= 0.5:
        raise InputError(f"the held-out share must lie in [0, 0.5], got {holdout}")
    order = np.random.default_rng(seed).permutation(n)
    n_out = int(round(holdout * n))
    if n - n_out < 1:
        raise InputError(f"{n} features leave none to build the models from")
    return np.sort(order[n_out:]), np.sort(order[:n_out])


def holdout_points(features: Features, free_ray: NDArray[np.bool_]) -> tuple[FloatArray, FloatArray]:
    """Test points from held-out features: their end points and points along their rays.

    Free rays (floor features, which every model here reads as free space, and features
    with evidence 0) are left out of the occupied points; their rays still give free
    points.

    Returns
    -------
    occupied, free
        ``(K, 3)`` and ``(M, 3)`` points in the sensor frame.
    """
    points = features.points
    occupied = points[~free_ray]
    free = np.concatenate([points * f for f in FREE_FRACTIONS]) if len(points) else np.zeros((0, 3))
    return occupied, free


def in_front_of_first_obstacle(points: FloatArray, features: Features, robot: Robot, *,
                               occupied: bool) -> NDArray[np.bool_]:
    """Test points that lie in front of the first obstacle at their pan angle, in the body band.

    A function increasing in range cannot show free space behind an obstacle at the same
    pan angle (a ray passing over a low box to the wall beyond): those points are
    unreachable for the parametric model by construction. Per pan-angle bin the first
    obstacle is the nearest cluster of ``features``' returns in the body band (the fit's
    :func:`occtool.fit.first_obstacle_distance`); free points count when nearer than it,
    ``occupied`` points (returns) when no farther than it plus its cluster window.
    """
    from occtool.fit import (
        FOCUS_ANGLE_BINS,
        FOCUS_WINDOW,
        FOCUS_WINDOW_ABS,
        adaptive_support,
        angle_bins,
        first_obstacle_distance,
    )

    low, high = robot.body_band
    x, y, z = features.points.T
    band = (z >= low) & (z <= high) & (features.evidence > 0)
    distance = np.hypot(x[band], y[band])
    support, _ = adaptive_support(len(features))
    # Each feature counts twice, as the fit's two hit samples do.
    first = first_obstacle_distance(np.repeat(np.arctan2(y[band], x[band]), 2), np.repeat(distance, 2),
                                     FOCUS_ANGLE_BINS, support)
    px, py, pz = np.asarray(points, dtype=np.float64).reshape(-1, 3).T
    limit = first[angle_bins(np.arctan2(py, px), FOCUS_ANGLE_BINS)]
    if occupied:
        limit = limit * (1.0 + FOCUS_WINDOW) + FOCUS_WINDOW_ABS
        return (pz >= low) & (pz <= high) & (np.hypot(px, py) <= limit)
    return (pz >= low) & (pz <= high) & (np.hypot(px, py) < limit)


@dataclass
class ModelResult:
    """What one model cost and produced."""

    name: str
    samples: int
    build_s: float
    extract_s: float
    memory_bytes: int
    file_bytes: int
    polygon: shapely.Geometry
    extra: dict[str, Any] = field(default_factory=dict)
    #: Why the navigation map is degenerate (an empty polygon: the robot in collision), if it is.
    warnings: list[str] = field(default_factory=list)
    #: A grid's polygon under each further reading of unobserved space (``also_unknown``).
    readings: dict[str, shapely.Geometry] = field(default_factory=dict)

    def figures(self) -> dict[str, Any]:
        return {
            "samples": int(self.samples),
            "build_s": float(self.build_s),
            "extract_s": float(self.extract_s),
            "memory_bytes": int(self.memory_bytes),
            "file_bytes": int(self.file_bytes),
            "polygon_area": float(self.polygon.area),
            **self.extra,
            "warnings": list(self.warnings),
        }


def _timed(function: Callable[[], Any], repeat: int) -> tuple[Any, float]:
    """Run ``function`` ``repeat`` times; its last result and the shortest time, seconds."""
    best = float("inf")
    result = None
    for _ in range(max(1, repeat)):
        start = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - start)
    return result, best


def _file_size(write: Callable[[str], Any], suffix: str) -> int:
    fd, name = tempfile.mkstemp(suffix=suffix)
    os.close(fd)
    try:
        write(name)
        return os.path.getsize(name)
    finally:
        os.unlink(name)


def tree_bytes(tree: Any) -> int:
    """Memory of a min/max tree's parameters: the piece coefficients plus one 8-byte
    reference per node of the tree structure."""

    def nodes(node: Any) -> int:
        return 1 if isinstance(node, (int, np.integer)) else 1 + sum(nodes(c) for c in node.children)

    return int(tree.coefficients.nbytes + 8 * nodes(tree.root))


def _save_model_size(model: Any) -> int:
    from occtool.io.model import save_model

    return _file_size(lambda name: save_model(model, name), ".json")


def _navigation(inverse_range: Callable[..., Any], navigation: Mapping[str, Any], **extra: Any) -> Any:
    """The navigation map, with the messages of its NavigationWarnings under ``notes``."""
    from occtool.navigation import NavigationWarning, navigation_map

    with warnings.catch_warnings(record=True) as caught:
        # An empty polygon (the robot in collision) is a result to report, not to warn about:
        # the report says why under the model's "warnings".
        warnings.simplefilter("always", NavigationWarning)
        nav = navigation_map(inverse_range, **{**navigation, **extra})
    notes = list(dict.fromkeys(str(w.message) for w in caught if issubclass(w.category, NavigationWarning)))
    return nav, notes


# --- baselines -------------------------------------------------------------------------------


class OccupancyMap(Protocol):
    """What the comparison asks of a built baseline.

    :class:`occtool.grid.OccupancyGrid` and :class:`occtool.octomap.OctoMapModel` offer it.
    """

    @property
    def memory_bytes(self) -> int:
        """Memory of the map, bytes."""
        ...

    def file_bytes(self) -> int:
        """Size of the map saved to a file, bytes."""
        ...

    def occupancy(self, points: FloatArray) -> FloatArray:
        """Occupancy probability at ``(N, 3)`` points; 0.5 where the map knows nothing."""
        ...

    def inverse_range(
        self,
        alpha: Any,
        h: Any,
        level: float,
        max_range: float | None = None,
        *,
        unknown: str = "free",
        band: tuple[float, float] | None = None,
    ) -> FloatArray:
        """As :meth:`occtool.grid.OccupancyGrid.inverse_range`."""
        ...


@dataclass(frozen=True)
class BuildInputs:
    """What every baseline is built from: the training features and the shared settings."""

    features: Features
    resolution: float
    robot: Robot
    sensor: Any
    grid_bounds: tuple[Any, Any] | None = None
    octomap_scans: int = 10


def _no_figures(built: Any, inputs: BuildInputs) -> dict[str, Any]:
    return {}


@dataclass(frozen=True)
class Baseline:
    """An occupancy map the parametric model is compared with.

    Attributes
    ----------
    name
        Its key in the report (``models``, ``agreement``, ``ratios``, ``auc``, ...).
    build
        Builds the map from the inputs; timed as the baseline's build time.
    samples
        The samples (cell updates) the built map fused, for the report.
    figures
        Figures of its own for its ``models`` entry, after the common ones.
    """

    name: str
    build: Callable[[BuildInputs], OccupancyMap]
    samples: Callable[[Any, BuildInputs], int]
    figures: Callable[[Any, BuildInputs], dict[str, Any]] = _no_figures


def _build_grid(inputs: BuildInputs) -> OccupancyMap:
    from occtool.grid import build_grid

    return build_grid(
        inputs.features,
        resolution=inputs.resolution,
        robot=inputs.robot,
        sensor=inputs.sensor,
        bounds=inputs.grid_bounds,
    )


def _build_octomap(inputs: BuildInputs) -> OccupancyMap:
    from occtool.octomap import build_octomap

    return build_octomap(
        inputs.features,
        resolution=inputs.resolution,
        robot=inputs.robot,
        scans=inputs.octomap_scans,
        sensor=inputs.sensor,
    )


def _octomap_samples(tree: Any, inputs: BuildInputs) -> int:
    from occtool.octomap import octomap_updates

    return octomap_updates(
        inputs.features, inputs.resolution, inputs.octomap_scans, robot=inputs.robot, sensor=inputs.sensor
    )


#: The dense 3D log-odds grid of :mod:`occtool.grid`.
GRID = Baseline(
    "grid",
    build=_build_grid,
    samples=lambda grid, inputs: grid.samples,
    figures=lambda grid, inputs: {
        "cells": int(np.prod(grid.shape)),
        "observed_cells": grid.observed_cells,
        "shape": list(grid.shape),
    },
)

#: OctoMap through ``pyoctomap`` (:mod:`occtool.octomap`); its samples are recounted cell updates.
OCTOMAP = Baseline(
    "octomap",
    build=_build_octomap,
    samples=_octomap_samples,
    figures=lambda tree, inputs: {"leaves": tree.leaf_count, "scans": int(inputs.octomap_scans)},
)


def observation_band(robot: Robot, heights: Any = None) -> tuple[float, float]:
    """Heights whose cells make a grid column observed with ``unknown="occupied"``.

    The robot's body band, widened to any navigation heights asked for outside it: what
    the sensor saw at one height of the band stands for the whole column there
    (docs/comparison.md, "Unobserved space").
    """
    low, high = robot.body_band
    if heights is not None:
        requested = np.asarray(heights, dtype=np.float64).ravel()
        if requested.size and np.isfinite(requested).all():
            low, high = min(low, float(requested.min())), max(high, float(requested.max()))
    return float(low), float(high)


def _run_baseline(
    baseline: Baseline,
    inputs: BuildInputs,
    navigation: Mapping[str, Any],
    *,
    read_range: float,
    unknown: str,
    band: tuple[float, float],
    repeat: int,
    file_sizes: bool,
    test_points: tuple[FloatArray, FloatArray],
    also_unknown: tuple[str, ...] = (),
) -> tuple[ModelResult, tuple[FloatArray, FloatArray]]:
    """Build one baseline, extract its navigation polygon and score its occupancy."""
    built, build_s = _timed(lambda: baseline.build(inputs), repeat)

    def reading(unknown: str) -> Callable[..., FloatArray]:
        def inverse_range(alpha: Any, h: Any, level: float) -> FloatArray:
            return built.inverse_range(alpha, h, level, max_range=read_range, unknown=unknown, band=band)
        return inverse_range

    (nav, notes), extract_s = _timed(lambda: _navigation(reading(unknown), navigation), repeat)
    others = {other: _navigation(reading(other), navigation)[0].polygon for other in also_unknown if other != unknown}
    result = ModelResult(
        name=baseline.name,
        samples=int(baseline.samples(built, inputs)),
        build_s=build_s,
        extract_s=extract_s,
        memory_bytes=int(built.memory_bytes),
        file_bytes=int(built.file_bytes()) if file_sizes else 0,
        polygon=nav.polygon,
        extra=baseline.figures(built, inputs),
        warnings=notes,
        readings=others,
    )
    logger.info(
        "%s: built in %.3f s, extract %.4f s (%s)",
        baseline.name, build_s, extract_s, ", ".join(f"{key} {value}" for key, value in result.extra.items()),
    )
    occupied_points, free_points = test_points
    return result, (built.occupancy(occupied_points), built.occupancy(free_points))


def compare_grid(
    features: Features,
    *,
    regressor: OccupancyRegressor,
    navigation: Mapping[str, Any],
    resolution: float = 0.05,
    octomap: bool = False,
    octomap_scans: int = 10,
    truth: Any = None,
    holdout: float = 0.1,
    seed: int = 0,
    repeat: int = 1,
    file_sizes: bool = True,
    grid_bounds: tuple[Any, Any] | None = None,
    unknown: str = "free",
    also_unknown: tuple[str, ...] = (),
) -> dict[str, Any]:
    """Compare the parametric model with a dense grid (and OctoMap) on the same features.

    Parameters
    ----------
    features
        Range features of one robot position, sensor-centred robot frame.
    regressor
        An unfitted :class:`occtool.fit.OccupancyRegressor` carrying the fit settings, the
        sensor model and the robot; the grid uses the same sensor model and robot.
    navigation
        Keyword arguments of :func:`occtool.navigation.navigation_map` (``robot``,
        ``threshold``, ``heights``, ``max_range``, ``n_angles``, ...), the same for all.
    resolution
        Cell edge of the grids, metres.
    octomap
        Also build the OctoMap baseline (needs ``pyoctomap``).
    octomap_scans
        Features are inserted into OctoMap as this many scans (consecutive runs in log
        order). OctoMap updates each cell at most once per scan, so with one scan a single
        outlier end point marks its cell occupied.
    truth
        A :class:`occtool.simulate.Scene` to score the polygons against, or ``None``.
    holdout
        Share of the features held out of every model to score occupancy (ROC AUC).
    seed
        Seed of the held-out split.
    repeat
        Build and extract each model this many times and report the shortest time.
    file_sizes
        Also measure the saved files' sizes (writes temporary files).
    grid_bounds
        ``(lower, upper)`` corners of the box the dense grid covers, metres (default: the
        features' extent).
    unknown
        How the grids' navigation polygons read unobserved space: ``"free"`` (its prior
        0.5, below the threshold) or ``"occupied"`` (a ray also ends at the first cell
        whose column has no observed cell in the :func:`observation_band`).
    also_unknown
        Further readings of unobserved space to extract the grids' polygons with (each
        grid is built once): the report's ``readings`` then holds, per reading and grid,
        the polygon's area, its agreement with the parametric one and, with ``truth``,
        its IoU and violation.

    Returns
    -------
    dict
        The report; see docs/comparison.md for its layout.
    """
    from occtool.grid import check_unknown
    from occtool.sensor import SensorModel

    if len(features) < 2:
        raise InputError(f"comparing needs at least 2 features, got {len(features)}")
    if not (np.isfinite(resolution) and resolution > 0):
        raise InputError(f"grid resolution must be a positive number of metres, got {resolution}")
    if int(octomap_scans) != octomap_scans or octomap_scans < 1:
        raise InputError(f"OctoMap scans must be a whole number >= 1, got {octomap_scans}")
    check_unknown(unknown)
    navigation = dict(navigation)
    robot: Robot = navigation.get("robot") or regressor.robot or Robot()
    navigation["robot"] = robot
    sensor = regressor.sensor if regressor.sensor is not None else SensorModel()
    # Every model sees the same robot and sensor model; the caller's regressor is left as it is.
    settings = {**regressor.get_params(deep=False), "robot": robot, "sensor": sensor}
    max_range = float(navigation.get("max_range", 1.5))
    # Rays are read past the max range by the robot radius before the shrink, plus a cell.
    read_range = max_range + robot.radius + resolution
    band = observation_band(robot, navigation.get("heights"))
    grid_navigation = {**navigation}
    if grid_navigation.get("slice_spacing") is None:
        # A grid has no slope bounds to hold between cuts: cut it at every cell layer.
        grid_navigation["slice_spacing"] = resolution

    train_index, test_index = split_holdout(len(features), holdout, seed)
    train = features.select(train_index)
    test = features.select(test_index)
    occupied_points, free_points = holdout_points(
        test, np.asarray(sensor.is_floor(test.height, robot), dtype=bool) | (test.evidence == 0)
    )

    results: dict[str, ModelResult] = {}
    scores: dict[str, tuple[FloatArray, FloatArray]] = {}

    # --- parametric model
    model, fit_s = _timed(lambda: type(regressor)(**settings).fit(train), repeat)
    (nav, notes), extract_s = _timed(
        lambda: _navigation(model.inverse_range, navigation, free_bounds=model.free_distance_bounds,
                            guard=model.guard_),
        repeat,
    )
    results["parametric"] = ModelResult(
        name="parametric",
        samples=int(model.n_samples_),
        build_s=fit_s,
        extract_s=extract_s,
        memory_bytes=tree_bytes(model.tree_),
        file_bytes=_save_model_size(model) if file_sizes else 0,
        polygon=nav.polygon,
        extra={"pieces": int(model.tree_.n_pieces), "samples_per_feature": model.n_samples_ / max(1, len(train))},
        warnings=notes,
    )
    logger.info("parametric: fit %.3f s, extract %.4f s, %d pieces", fit_s, extract_s, model.tree_.n_pieces)
    scores["parametric"] = tuple(  # type: ignore[assignment]
        np.asarray(model.predict(*polar(p)), dtype=np.float64) for p in (occupied_points, free_points)
    )

    # --- the baselines, alike
    inputs = BuildInputs(
        features=train,
        resolution=float(resolution),
        robot=robot,
        sensor=sensor,
        grid_bounds=grid_bounds,
        octomap_scans=int(octomap_scans),
    )
    for baseline in [GRID, OCTOMAP] if octomap else [GRID]:
        results[baseline.name], scores[baseline.name] = _run_baseline(
            baseline,
            inputs,
            grid_navigation,
            read_range=read_range,
            unknown=unknown,
            band=band,
            repeat=repeat,
            file_sizes=file_sizes,
            test_points=(occupied_points, free_points),
            also_unknown=tuple(check_unknown(other) for other in also_unknown),
        )

    # The points a function increasing in range can represent: in front of the first
    # obstacle at their pan angle, in the body band (first obstacles from all the features).
    front_occupied = in_front_of_first_obstacle(occupied_points, features, robot, occupied=True)
    front_free = in_front_of_first_obstacle(free_points, features, robot, occupied=False)
    parametric = results["parametric"]
    report: dict[str, Any] = {
        "version": REPORT_VERSION,
        "features": len(features),
        "features_used": len(train),
        "features_held_out": len(test),
        "robot_radius": float(robot.radius),
        "settings": {
            "resolution": float(resolution),
            "threshold": float(navigation.get("threshold", 0.6)),
            "heights": [float(h) for h in nav.heights],
            "slice_heights": [float(h) for h in nav.slice_heights],
            "max_range": max_range,
            "n_angles": int(navigation.get("n_angles", 360)),
            "robot_radius": float(robot.radius),
            "pieces": int(model.tree_.n_pieces),
            "octomap_scans": int(octomap_scans) if octomap else None,
            "holdout": float(holdout),
            "seed": int(seed),
            "repeat": int(repeat),
            "log_odds": "OctoMap defaults: prob_hit 0.7, prob_miss 0.4, clamping 0.1192..0.971",
            "unknown": unknown,
            "observed_band": [band[0], band[1]],
        },
        "footprint_prior": (
            "the grids mark the robot's footprint cylinder (radius "
            f"{robot.radius:g} m over its body band) free, as the parametric model's footprint samples do"
        ),
        "unknown_space": UNKNOWN_SPACE_NOTES[unknown].format(low=band[0], high=band[1]),
        "models": {name: result.figures() for name, result in results.items()},
        "agreement": {
            name: {"iou": polygon_iou(parametric.polygon, result.polygon)}
            for name, result in results.items()
            if name != "parametric"
        },
        "auc": {name: roc_auc(*pair) for name, pair in scores.items()},
        "auc_points": {"occupied": int(occupied_points.shape[0]), "free": int(free_points.shape[0])},
        "auc_front": {name: roc_auc(pair[0][front_occupied], pair[1][front_free]) for name, pair in scores.items()},
        "auc_front_points": {"occupied": int(front_occupied.sum()), "free": int(front_free.sum())},
        "ratios": {},
    }
    for name, result in results.items():
        if name == "parametric":
            continue
        report["ratios"][name] = {
            "memory": result.memory_bytes / max(1, parametric.memory_bytes),
            "file": (result.file_bytes / parametric.file_bytes) if parametric.file_bytes else None,
            "time": (result.build_s + result.extract_s) / max(1e-12, parametric.build_s + parametric.extract_s),
            "build_time": result.build_s / max(1e-12, parametric.build_s),
            "extract_time": result.extract_s / max(1e-12, parametric.extract_s),
        }
    if truth is not None:
        from occtool.evaluate import evaluate_navigation

        report["truth"] = {}
        for name, result in results.items():
            evaluation = evaluate_navigation(result.polygon, truth, robot_radius=robot.radius, max_range=max_range)
            report["truth"][name] = {
                "iou": float(evaluation.iou),
                "violation": float(evaluation.violation),
                "coverage": float(evaluation.coverage),
            }
    readings: dict[str, dict[str, Any]] = {}
    for name, result in results.items():
        for other, polygon in result.readings.items():
            entry: dict[str, Any] = {"polygon_area": float(polygon.area),
                                     "agreement": {"iou": polygon_iou(parametric.polygon, polygon)}}
            if truth is not None:
                from occtool.evaluate import evaluate_navigation

                evaluation = evaluate_navigation(polygon, truth, robot_radius=robot.radius, max_range=max_range)
                entry["truth"] = {"iou": float(evaluation.iou), "violation": float(evaluation.violation),
                                  "coverage": float(evaluation.coverage)}
            readings.setdefault(other, {})[name] = entry
    if readings:
        report["readings"] = readings
    report["polygons"] = {name: json.loads(shapely.to_geojson(result.polygon)) for name, result in results.items()}
    return report


def report_json(report: Mapping[str, Any], *, indent: int | None = 2) -> str:
    """The report as JSON text (NaN written as null)."""

    def clean(value: Any) -> Any:
        if isinstance(value, float) and not np.isfinite(value):
            return None
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [clean(v) for v in value]
        if isinstance(value, np.generic):
            return clean(value.item())
        return value

    return json.dumps(clean(dict(report)), indent=indent, allow_nan=False)
