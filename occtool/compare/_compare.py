"""The comparison itself: :func:`compare_grid` builds, extracts and scores every model; the report."""

from __future__ import annotations

import json
import logging
import warnings
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
from numpy.typing import NDArray

from occtool.compare._baselines import GRID, OCTOMAP, Baseline, BuildInputs, observation_band
from occtool.compare._results import ModelResult, _save_model_size, _timed, tree_bytes
from occtool.errors import InputError
from occtool.features import Features, polar
from occtool.robot import Robot
from occtool.scoring import holdout_points, in_front_of_first_obstacle, polygon_iou, roc_auc, split_holdout

if TYPE_CHECKING:
    from occtool.fit import OccupancyRegressor

FloatArray = NDArray[np.float64]


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


def _load_libraries(octomap: bool) -> None:
    """Import what the models' builds and extractions share, and each one's own library,
    before any of them is timed: a model's time is its build's and extraction's, first
    call included, not the process's first use of a module. The parametric model ran
    first and paid them alone: occtool.navigation and numpy.ma (np.unique's first call
    imports it) in its extraction, scipy.spatial in its fit until the guard stopped using
    it; the grid then found them loaded. OctoMap's bindings are imported here too
    (occtool.fit and occtool.grid are by then)."""
    import numpy.ma  # noqa: F401 - np.unique imports it on its first call

    import occtool.navigation  # noqa: F401

    if octomap:
        from occtool.grid import require_pyoctomap

        require_pyoctomap()


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
    _load_libraries(octomap)
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
        from occtool.scoring import evaluate_navigation

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
                from occtool.scoring import evaluate_navigation

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
