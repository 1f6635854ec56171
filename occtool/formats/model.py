"""Model files: the fitted occupancy tree and its inverse as versioned JSON.

A model file holds everything needed to use and to reproduce the model: the tree and
its pieces, the constraints the fit enforced, the frame and units, the sensor model and
robot, the fit parameters and a training summary (with a sha256 digest of the input
features). Everything that naturally differs between two runs on the same input
(duration, date, occtool version, host) lives in the one top-level ``run`` object, so two
fits with the same input and seed give files identical outside ``run``.

Floats are written with Python's shortest round-trip representation, so loading gives
back bit-identical coefficients and every constraint still holds exactly.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from occtool._files import atomic_write
from occtool._json import read_json
from occtool.errors import InputError, ModelFormatError
from occtool.robot import Robot
from occtool.sensor import SensorModel
from occtool.tree import InverseTree, MinMaxTree

MODEL_FORMAT = "occtool-model"
INVERSE_FORMAT = "occtool-inverse"
#: The newest format version this occtool writes and reads.
FORMAT_VERSION = 1

FRAME = {
    "id": "base_link",
    "origin": "sensor centre",
    "axes": "REP-103: x forward, y left, z up",
    "coordinates": "alpha = atan2(y, x), h = z, r = |p|",
}
UNITS = {"alpha": "rad", "h": "m", "r": "m", "m": "occupancy in [0, 1]"}

def _fit_params() -> tuple[str, ...]:
    """The estimator's parameters a model file records (its constructor's keywords, in
    order, but the sensor model and robot, which have sections of their own)."""
    from occtool.fit import OccupancyRegressor

    return tuple(name for name in OccupancyRegressor._get_param_names() if name not in ("sensor", "robot"))


def model_to_dict(model: Any, *, run: dict | None = None, observed: Any | None = None) -> dict[str, Any]:
    """The JSON-ready content of a model file for a fitted :class:`OccupancyRegressor`;
    ``observed``: what its position observed (:class:`occtool.observation.Observation`; by default
    the model's own ``observed_``, read from a file, if any)."""
    model._check_fitted()
    tree = model.tree_
    data: dict[str, Any] = {
        "format": MODEL_FORMAT,
        "format_version": FORMAT_VERSION,
        "frame": dict(FRAME),
        "units": dict(UNITS),
        "function": "m = tree of MIN/MAX nodes over linear pieces; F increases strictly in r",
        **tree.to_dict(),
        "constraints": {"c_min": float(model.c_min), "a_max": float(model.a_max), "b_max": float(model.b_max)},
        "slope_bounds": dict(model.slope_bounds_),
        "sensor_model": model.sensor_.to_dict(),
        "robot": _robot_dict(model.robot_),
        "fit": {name: getattr(model, name) for name in _fit_params()},
        "training": model.training_summary(),
    }
    if getattr(model, "guard_", None) is not None:
        data["guard"] = model.guard_.to_dict()
    observed = observed if observed is not None else getattr(model, "observed_", None)
    if observed is not None:
        data["observed"] = observed.to_dict()
    if run is not None:
        data["run"] = dict(run)
    return data


def _optional_block(data: dict[str, Any], key: str, reader: Any, source: str) -> Any:
    """``reader(data[key])``, or ``None`` where the file has no ``key``; its format errors name ``source``."""
    if data.get(key) is None:
        return None
    try:
        return reader(data[key])
    except ModelFormatError as exc:
        raise ModelFormatError(f"{source}: {exc}") from None


def _observed_from(data: dict[str, Any], source: str) -> Any:
    """The file's :class:`occtool.observation.Observation` (``None`` when it has none: a single fit,
    files written before model sets kept one)."""
    from occtool.observation import Observation

    return _optional_block(data, "observed", Observation.from_dict, source)


def _guard_from(data: dict[str, Any], source: str) -> Any:
    """The file's return guard (``None`` when it has none: older files, ``--no-guard``)."""
    from occtool.guard import ReturnGuard

    return _optional_block(data, "guard", ReturnGuard.from_dict, source)


def _robot_dict(robot: Robot) -> dict[str, float]:
    return {k: float(getattr(robot, k)) for k in ("radius", "sensor_height", "body_height", "ground_clearance")}


def save_model(model: Any, path: str | os.PathLike[str], *, run: dict | None = None) -> None:
    """Write a fitted model as JSON (atomically: the file is complete or absent).

    Parameters
    ----------
    model
        A fitted :class:`~occtool.fit.OccupancyRegressor`.
    path
        Destination file, or ``"-"`` for standard output.
    run
        Details of this run (duration, date, version, host) for the ``run`` object.
    """
    text = _dumps(model_to_dict(model, run=run))
    with atomic_write(path, "w") as handle:
        handle.write(text + "\n")


#: The ``run`` object a worker writes into a model's text, replaced by :func:`with_run`.
RUN_PLACEHOLDER = {"@@occtool-run@@": 0}


def model_text(model: Any, *, run: dict | None = None, observed: Any | None = None) -> str:
    """The text of the model file :func:`save_model` writes (``run=RUN_PLACEHOLDER`` to
    fill the run object in later with :func:`with_run`, where the file is written;
    ``observed`` as :func:`model_to_dict`)."""
    return _dumps(model_to_dict(model, run=run, observed=observed)) + "\n"


def _run_block(run: dict) -> str:
    text = _dumps({"run": dict(run)})
    return text[len('{\n "run": '):-len("\n}")]


def with_run(text: str, run: dict) -> str:
    """A model text made with ``run=RUN_PLACEHOLDER``, with the run object ``run``: the same
    bytes as :func:`model_text` with ``run`` (the run object is the file's last key)."""
    placeholder = _run_block(RUN_PLACEHOLDER)
    head, found, tail = text.rpartition(placeholder)
    if not found:
        raise ValueError("the model text holds no run placeholder")
    return head + _run_block(run) + tail


def save_model_text(text: str, path: str | os.PathLike[str]) -> None:
    """Write a model file's text (from :func:`model_text`) atomically."""
    with atomic_write(path, "w") as handle:
        handle.write(text)


def _dumps(data: dict[str, Any]) -> str:
    """JSON with one key a line, but each piece, the tree and the guard's hundreds of
    distances on a line of their own: a 64-piece model stays well under 16 KB."""
    compact: dict[str, str] = {}

    def placeholder(value: Any) -> str:
        marker = f"@@compact-{len(compact)}@@"
        compact[marker] = json.dumps(value, separators=(", ", ": "), allow_nan=False)
        return marker

    shaped = dict(data)
    if isinstance(shaped.get("tree"), dict):
        shaped["tree"] = placeholder(shaped["tree"])
    if isinstance(shaped.get("pieces"), list):
        shaped["pieces"] = [placeholder(piece) for piece in shaped["pieces"]]
    if isinstance(shaped.get("guard"), dict):
        shaped["guard"] = {**shaped["guard"], "distance_mm": placeholder(shaped["guard"]["distance_mm"])}
    if isinstance(shaped.get("observed"), dict):
        shaped["observed"] = {key: placeholder(value) if isinstance(value, list) else value
                              for key, value in shaped["observed"].items()}
    text = json.dumps(shaped, indent=1, allow_nan=False)
    for marker, value in compact.items():
        text = text.replace(json.dumps(marker), value, 1)
    return text


#: Deepest tree of MIN/MAX nodes read (occtool writes depth 2: MAX over MIN over pieces).
MAX_TREE_DEPTH = 64


def _read_json(path: str | os.PathLike[str]) -> Any:
    data = read_json(path, error=ModelFormatError)
    _check_finite(data, str(path))
    return data


def _check_finite(data: Any, source: str) -> None:
    """Refuse NaN and infinity anywhere in a file: occtool writes neither (``allow_nan=False``),
    so one there is damage, and a NaN setting or bound would load and poison every map."""
    stack: list[tuple[Any, str]] = [(data, "")]
    while stack:  # a stack, not recursion: a deep tree is refused by its own check, with its own message
        item, where = stack.pop()
        if isinstance(item, float):
            if not math.isfinite(item):
                raise ModelFormatError(f"{source}: {where or 'the file'} is not a finite number ({item})")
        elif isinstance(item, dict):
            stack.extend((value, f"{where}.{key}" if where else str(key)) for key, value in item.items())
        elif isinstance(item, list):
            stack.extend((value, f"{where}[{index}]") for index, value in enumerate(item))


def _check_tree_depth(tree: Any, source: str) -> None:
    """Refuse a tree nested deeper than :data:`MAX_TREE_DEPTH` before anything recurses into it."""
    level = [tree]
    for _ in range(MAX_TREE_DEPTH + 1):
        children = [node.get("children") for node in level if isinstance(node, dict)]
        level = [child for group in children if isinstance(group, list) for child in group]
        if not level:
            return
    raise ModelFormatError(f"{source}: the tree is nested deeper than {MAX_TREE_DEPTH} levels")


def _check_header(data: Any, expected: str, path: str | os.PathLike[str]) -> None:
    if not isinstance(data, dict):
        raise ModelFormatError(f"{path}: a model file must hold a JSON object")
    kind = data.get("format")
    if kind != expected:
        raise ModelFormatError(f"{path}: not an {expected} file (format is {kind!r})")
    version = data.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ModelFormatError(f"{path}: format_version must be a whole number >= 1, got {version!r}")
    if version > FORMAT_VERSION:
        raise ModelFormatError(
            f"{path}: written by a newer occtool (format version {version}; this one reads up to {FORMAT_VERSION})"
        )
    units = data.get("units")
    if units is not None and units != UNITS:
        raise ModelFormatError(f"{path}: unsupported units {units!r} (expected {UNITS})")


def model_from_dict(data: Any, source: str = "model") -> Any:
    """Rebuild a fitted :class:`OccupancyRegressor` from :func:`model_to_dict` output."""
    from occtool.fit import OccupancyRegressor

    _check_header(data, MODEL_FORMAT, source)
    for key in ("constraints", "sensor_model", "robot", "fit", "training"):
        if not isinstance(data.get(key), dict):
            raise ModelFormatError(f"{source}: '{key}' is missing or not an object")
    _check_tree_depth(data.get("tree"), source)
    # Files written before the least-squares construction was removed record
    # `construction`: "profile" is what every fit now does; "regression" cannot be refitted.
    construction = data["fit"].get("construction", "profile")
    if construction != "profile":
        raise ModelFormatError(f"{source}: construction {construction!r} is no longer supported: refit the model")
    try:
        tree = MinMaxTree.from_dict(data)
    except ModelFormatError as exc:
        raise ModelFormatError(f"{source}: {exc}") from None
    except OverflowError:
        raise ModelFormatError(f"{source}: a piece coefficient is too large for a number") from None
    try:
        sensor = SensorModel.from_dict(data["sensor_model"])
        robot = Robot(**{k: float(v) for k, v in data["robot"].items()})
        names = _fit_params()
        fit_params = {k: v for k, v in data["fit"].items() if k in names}
        constraints = {k: float(data["constraints"][k]) for k in ("c_min", "a_max", "b_max")}
    except (InputError, TypeError, ValueError, KeyError, AttributeError, OverflowError) as exc:
        raise ModelFormatError(f"{source}: invalid settings: {exc}") from None
    for key, value in constraints.items():
        if not (math.isfinite(value) and value > 0):
            raise ModelFormatError(f"{source}: constraint {key} must be a finite number > 0, got {value}")
    fit_params.update(constraints)
    _check_constraints(tree, constraints, source)
    try:
        model = OccupancyRegressor(**fit_params, sensor=sensor, robot=robot)
    except (InputError, TypeError, ValueError) as exc:
        raise ModelFormatError(f"{source}: invalid fit settings: {exc}") from None
    training = data["training"]
    try:
        loss = training.get("loss")
        n_features, n_samples = int(training["n_features"]), int(training["n_samples"])
        sample_counts = {str(k): int(v) for k, v in training.get("samples_by_kind", {}).items()}
        rmse = float(training["rmse"])
        n_sweeps = int(training.get("sweeps", 0))
        digest = str(training["features_sha256"])
        loss = math.nan if loss is None else float(loss)
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
        raise ModelFormatError(f"{source}: incomplete training summary ({exc})") from None
    if not math.isfinite(rmse):
        raise ModelFormatError(f"{source}: the training summary's rmse is not a finite number")
    model._set_fitted(tree, sensor=sensor, robot=robot, guard=_guard_from(data, source), n_features=n_features,
                      n_samples=n_samples, sample_counts=sample_counts, rmse=rmse, loss_history=[],
                      loss=loss, n_sweeps=n_sweeps, features_digest=digest,
                      seconds=math.nan)
    model.observed_ = _observed_from(data, source)
    model.run_ = dict(data["run"]) if isinstance(data.get("run"), dict) else {}
    return model


def _check_constraints(tree: MinMaxTree, constraints: dict[str, float], source: str) -> None:
    bounds = {"c_min": float(tree.c.min()), "a_max": float(tree.angle_weight.max()), "b_max": float(abs(tree.b).max())}
    if bounds["c_min"] < constraints["c_min"] or bounds["c_min"] <= 0:
        raise ModelFormatError(f"{source}: a piece has c = {bounds['c_min']} below c_min = {constraints['c_min']}")
    if bounds["a_max"] > constraints["a_max"]:
        raise ModelFormatError(f"{source}: a piece's pan weight {bounds['a_max']} exceeds a_max = {constraints['a_max']}")
    if bounds["b_max"] > constraints["b_max"]:
        raise ModelFormatError(f"{source}: a piece's height weight {bounds['b_max']} exceeds b_max = {constraints['b_max']}")


def load_model(path: str | os.PathLike[str]) -> Any:
    """Read a model file written by :func:`save_model`.

    Returns
    -------
    OccupancyRegressor
        A fitted estimator (``predict``, ``inverse_range``, ``invert`` work; ``run_``
        holds the file's run details).

    Raises
    ------
    ModelFormatError
        If the file is not JSON, not a model file, written by a newer format, or
        inconsistent (bad tree, a constraint that does not hold).
    """
    return model_from_dict(_read_json(path), str(path))


def inverse_to_dict(inverse: InverseTree, *, model: Any | None = None, level_hint: float | None = None,
                    run: dict | None = None) -> dict[str, Any]:
    """The JSON-ready content of an inverse file."""
    data: dict[str, Any] = {
        "format": INVERSE_FORMAT,
        "format_version": FORMAT_VERSION,
        "frame": dict(FRAME),
        "units": dict(UNITS),
        "function": "r = tree of MIN/MAX nodes over pieces solved for r (the model's tree with MIN and MAX swapped)",
        **inverse.to_dict(),
    }
    if model is not None:
        data["slope_bounds"] = dict(model.slope_bounds_)
        data["robot"] = _robot_dict(model.robot_)
        if getattr(model, "guard_", None) is not None:
            data["guard"] = model.guard_.to_dict()
        data["model_training"] = model.training_summary()
    if run is not None:
        data["run"] = dict(run)
    return data


def save_inverse(inverse: InverseTree, path: str | os.PathLike[str], *, model: Any | None = None,
                 run: dict | None = None) -> None:
    """Write an inverse tree ``r = F^-1(alpha, h, m)`` as JSON (atomically).

    Parameters
    ----------
    inverse
        The :class:`~occtool.tree.InverseTree`.
    path
        Destination file or ``"-"``.
    model
        The fitted model it came from: its slope bounds, robot and training summary are
        copied into the file.
    run
        Details of this run for the ``run`` object.
    """
    text = _dumps(inverse_to_dict(inverse, model=model, run=run))
    with atomic_write(path, "w") as handle:
        handle.write(text + "\n")


def load_inverse(path: str | os.PathLike[str]) -> InverseTree:
    """Read an inverse file written by :func:`save_inverse`; :class:`ModelFormatError` if malformed."""
    data = _read_json(path)
    _check_header(data, INVERSE_FORMAT, path)
    _check_tree_depth(data.get("tree"), str(path))
    try:
        inverse = InverseTree.from_dict(data)
    except ModelFormatError as exc:
        raise ModelFormatError(f"{path}: {exc}") from None
    except OverflowError:
        raise ModelFormatError(f"{path}: a piece coefficient is too large for a number") from None
    if not (inverse.coefficients[:, -2] > 0).all():
        raise ModelFormatError(f"{path}: every inverse piece needs a positive weight on m")
    return inverse


def read_any(path: str | os.PathLike[str]) -> tuple[str, Any] | None:
    """``("model", regressor)`` or ``("inverse", tree)`` if ``path`` is one of ours, else ``None``.

    A JSON file that names one of our formats but is broken raises :class:`ModelFormatError`.
    """
    try:
        with open(path, "rb") as handle:
            head = handle.read(4096)
    except IsADirectoryError:
        return None
    text = head.lstrip()
    if not text.startswith(b"{") or (MODEL_FORMAT.encode() not in head and INVERSE_FORMAT.encode() not in head):
        return None
    data = _read_json(path)
    if isinstance(data, dict) and data.get("format") == MODEL_FORMAT:
        return "model", model_from_dict(data, str(path))
    if isinstance(data, dict) and data.get("format") == INVERSE_FORMAT:
        return "inverse", load_inverse(path)
    return None


@dataclass(frozen=True)
class Navigable:
    """What :func:`occtool.navigation.navigation_map` needs of a model or inverse file.

    Attributes
    ----------
    inverse_range
        ``inverse_range(alpha, h, level) -> r`` (0 where the level is reached at the sensor).
    free_bounds
        Exact lower bounds of the free horizontal distance over boxes
        (:meth:`occtool.tree.InverseTree.horizontal_lower_bound`).
    slope_bounds
        The pieces' largest weights, or ``None`` when the file records none.
    robot
        The robot the model was fitted for, or ``None``.
    guard
        The position's :class:`~occtool.guard.ReturnGuard`, or ``None``.
    """

    inverse_range: Any
    free_bounds: Any
    slope_bounds: dict[str, float] | None
    robot: Robot | None
    guard: Any

    def navigation_options(self, *, bounds: bool = True) -> dict[str, Any]:
        """Keyword arguments for :func:`~occtool.navigation.navigation_map` (but ``robot``);
        ``bounds=False`` gives the paper's plain cut at the given heights (no bounds)."""
        if not bounds:
            return {"guard": self.guard}
        return {"free_bounds": self.free_bounds, "slope_bounds": self.slope_bounds, "guard": self.guard}


def read_navigable(path: str | os.PathLike[str]) -> Navigable:
    """The inverse function, bounds, robot and return guard of a model or inverse file.

    Raises
    ------
    InputError
        If the file is neither (:class:`ModelFormatError` if it is one but broken).
    """
    found = read_any(path)
    if found is None:
        raise InputError(f"{path}: not an occtool model or inverse file (write one with `occtool fit`)")
    kind, item = found
    if kind == "model":
        return Navigable(item.inverse_range, item.free_distance_bounds, dict(item.slope_bounds_), item.robot_,
                         item.guard_)

    def inverse_range(alpha: Any, h: Any, level: float) -> Any:
        # The inverse tree gives where the level is crossed, before the sensor too (r < 0).
        r = item.range(alpha, h, level)
        return np.maximum(np.where(np.isnan(r), np.inf, r), 0.0)

    data = _read_json(path)
    bounds = data.get("slope_bounds")
    robot = data.get("robot")
    try:
        robot = Robot(**{k: float(v) for k, v in robot.items()}) if isinstance(robot, dict) else None
    except (InputError, TypeError, ValueError, OverflowError):
        robot = None
    return Navigable(inverse_range, item.horizontal_lower_bound, dict(bounds) if isinstance(bounds, dict) else None,
                     robot, _guard_from(data, str(path)))


__all__ = [
    "FORMAT_VERSION",
    "INVERSE_FORMAT",
    "MODEL_FORMAT",
    "inverse_to_dict",
    "load_inverse",
    "load_model",
    "model_from_dict",
    "model_to_dict",
    "read_any",
    "save_inverse",
    "save_model",
]
