"""Building a fused map: fitting a log's keyframe positions, or placing fitted models."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from occtool.errors import InputError
from occtool.executor import Failed
from occtool.features import Pose, RangeLog
from occtool.fuse._combine import DEFAULT_COMBINATION
from occtool.fuse._keyframes import KEYFRAME_NEW_SHARE, select_keyframes
from occtool.fuse._map import FusedMap
from occtool.fuse._sightings import RunReturns, returns_of_positions
from occtool.observation import is_scanning_laser, observe, reach_from_guard, returns_from_guard
from occtool.robot import Robot


@dataclass
class FuseReport:
    """What building a fused map took."""

    positions: int
    skipped: list[tuple[int, str]]
    fit_seconds: float
    fuse_seconds: float
    notes: list[str] = field(default_factory=list)
    #: The position index of each fitted model, in the models' order.
    fitted: list[int] = field(default_factory=list)
    #: Positions left out before fitting because earlier keyframes covered what they saw.
    not_keyframes: list[int] = field(default_factory=list)
    #: What every position saw, keyframes or not (:func:`occtool.fuse.returns_of_positions`):
    #: the world map's walls (:func:`occtool.fuse.build_world_map`'s ``sightings``).
    sightings: RunReturns | None = None


def _fit_keyframes(params: dict[str, Any], chunk: list[Any]) -> list[Any]:
    """Fit a few keyframes' features with ``params`` (runs in this process or on a worker):
    for each, the fitted model and its :class:`~occtool.observation.Observation`, or
    :class:`~occtool.executor.Failed`."""
    from occtool.errors import OcctoolError
    from occtool.fit import fit_together

    out: list[Any] = []
    # The fits run in turns, their centres' programmes solved together (the same models).
    for model, features in zip(fit_together(params, chunk), chunk):
        if isinstance(model, OcctoolError):
            out.append(Failed(str(model)))
            continue
        if isinstance(model, Exception):
            raise model
        # Every return, far ones too: they mark walls; the map's return_reach keeps them from
        # lending occupancy or clearing cells past the guard's reach.
        out.append((model, observe(model, features)))
    return out


def fit_in_order(positions: Sequence[Any], params: dict[str, Any], executor: Any = None,
                 progress: Callable[[int, int], None] | None = None, *, release: bool = False) -> list[Any]:
    """:func:`_fit_keyframes` of every position of ``positions`` on ``executor`` (an
    :class:`occtool.executor.Executor`; ``None``: this process), in chunks; the outcomes in
    the positions' order whatever order the chunks finish in, so the map does not depend on
    where the fits ran. ``release``: each entry of ``positions`` (a list) is set to ``None``
    once its features are handed to their task, so that they go when it is done."""
    from occtool.executor import in_order, tasks_of_fits

    total = len(positions)

    def arguments() -> Any:
        for chunk in tasks_of_fits(range(total), lambda k: len(positions[k].features)):
            features = [positions[k].features for k in chunk]
            if release:
                for k in chunk:
                    positions[k] = None  # type: ignore[index]  # a list, as the docstring says
            yield params, features
            del features

    outcomes: list[Any] = []
    for outcome in in_order(executor, "fitting the keyframes", _fit_keyframes, arguments()):
        outcomes += outcome
        if progress is not None:
            progress(len(outcomes), total)
    return outcomes


def fuse_log(log: RangeLog, template: Any, *, combination: str = DEFAULT_COMBINATION, threshold: float = 0.6,
             progress: Callable[[int, int], None] | None = None,
             keyframe_share: float = KEYFRAME_NEW_SHARE,
             heights_from_data: bool = False, executor: Any = None,
             consume: bool = False) -> tuple[FusedMap, list[Any], FuseReport]:
    """Fit the keyframe positions of ``log`` with copies of ``template`` (an unfitted
    :class:`occtool.fit.OccupancyRegressor`) and fuse them.

    Keyframes (:func:`select_keyframes`): a position is fitted when at least
    ``keyframe_share`` of the cells its returns fall in are new; 0 fits every position.

    The data is checked against the template's robot first, as ``occtool fit`` checks it
    (:func:`occtool.modelset.estimator_for_log`): a warning for each disagreement, the
    floor's naming ``--sensor-height`` and the height the data gives. With
    ``heights_from_data`` (no sensor or body height given) a 3D log whose floor disagrees
    takes the data's sensor height. A planar laser log keeps the template's robot and focus
    range (the fit's planar defaults are not taken: docs/map.md).

    Positions without a pose cannot be placed and raise, unless the log is a single
    position without one (its frame becomes the map's, noted in the report); positions
    whose fit fails for their data (no usable features) are skipped and reported.

    ``executor`` (an :class:`occtool.executor.Executor`: local processes or a Dask cluster,
    :func:`occtool.executor.make_executor`; ``None``: this process) fits the keyframes, a
    few at a time; the map is the same, byte for byte, wherever they were fitted.

    ``consume``: the log is used up (its :attr:`~occtool.features.RangeLog.positions` list
    is emptied once every position's sightings are read), and each keyframe's features go
    once it is fitted: a large log's features are not held beside its models. The map is the same.

    Returns
    -------
    fused, models, report
        The :class:`FusedMap`, the fitted regressors (for their navigation maps) and a
        :class:`FuseReport`.
    """
    from occtool.modelset import estimator_for_log

    notes = []
    positions = list(log.positions)
    missing = [p.index for p in positions if p.pose is None]
    if missing and len(positions) == 1:
        # One position and no pose (a log without any): its own frame is the map.
        positions = [replace(positions[0], pose=Pose())]
        notes.append("the log has no poses: its single position is the map frame's origin")
    elif missing:
        raise InputError(f"{log.source or 'the log'}: position {missing[0]} has no pose; a world map needs poses")
    # Once per log, as the fit does: warnings where the data and the robot disagree.
    template = estimator_for_log(template, positions, floor_defaults=heights_from_data)
    params = template.get_params()
    robot = params.get("robot") or Robot()
    keep = select_keyframes(positions, robot, new_share=keyframe_share)
    not_keyframes = sorted(set(p.index for p in positions) - {positions[k].index for k in keep})
    focus_range = params.get("focus_range", math.inf) if params.get("focus", True) else math.inf
    sightings = returns_of_positions(positions, robot, focus_range=focus_range, level=params.get("level"))
    positions = [positions[k] for k in keep]
    if consume:
        log.positions.clear()  # the keyframes' features are all that is still needed, each until it is fitted
    placed = [(item.index, item.pose, item.stamp) for item in positions]
    started = time.perf_counter()
    models, poses, reaches, returns, return_offsets, stamps, skipped = [], [], [], [], [], [], []
    fitted_positions: list[int] = []
    for (index, pose, stamp), outcome in zip(placed, fit_in_order(positions, params, executor, progress,
                                                                 release=consume)):
        if isinstance(outcome, Failed):
            skipped.append((index, outcome.reason))
            continue
        model, observed = outcome
        fitted_positions.append(index)
        models.append(model)
        poses.append(pose)
        stamps.append(stamp)
        reaches.append(observed.reach)
        returns.append(observed.returns)
        return_offsets.append(observed.offsets)
    fitted = time.perf_counter()
    if not models:
        raise InputError(f"{log.source or 'the log'}: no position could be fitted ({skipped[0][1]})")
    fused = FusedMap([m.tree_ for m in models], poses, np.stack(reaches), robot, combination=combination,  # type: ignore[arg-type]  # poses checked above
                     threshold=threshold, stamps=stamps, returns=np.stack(returns),
                     return_offsets=np.stack(return_offsets), return_reach=focus_range + robot.radius,
                     scanning_laser=sightings.scanning_laser)
    report = FuseReport(len(models), skipped, fitted - started, time.perf_counter() - fitted, notes, fitted_positions,
                        not_keyframes, sightings)
    return fused, models, report


def fuse_models(models: Sequence[Any], poses: Sequence[Pose], *, reaches: ArrayLike | None = None,
                combination: str = DEFAULT_COMBINATION, threshold: float = 0.6,
                stamps: Sequence[float | None] | None = None, scanning_laser: bool = False) -> FusedMap:
    """Fuse fitted regressors (e.g. a model set read back) placed at ``poses``.

    When every model knows what its position observed (``observed_``, an
    :class:`~occtool.fuse.Observation`: the model files of ``occtool fit LOG -o DIR/``), the
    map keeps its reaches and returns as :func:`fuse_log` does. Otherwise (models fitted
    here, older files) each model's reach without ``reaches`` and its returns come from its
    return guard (:func:`reach_from_guard`, :func:`returns_from_guard`): directions where it
    saw no return stay unknown and each return is spread over the bins beside it.
    ``scanning_laser``: the models are a scanning laser's (:attr:`FusedMap.scanning_laser`;
    a model file cannot tell).
    """
    if not models:
        raise InputError("a fused map needs at least one local model")
    robot = models[0].robot_
    observed = [o for o in (getattr(m, "observed_", None) for m in models) if o is not None]
    if len(observed) == len(models):
        if reaches is None:
            reaches = np.stack([o.reach for o in observed])
        returns, offsets = np.stack([o.returns for o in observed]), np.stack([o.offsets for o in observed])
        # As fuse_log: returns beyond the guard's reach mark walls but lend no occupancy.
        return_reach = max(m.focus_range if m.focus else math.inf for m in models) + robot.radius
    else:
        if reaches is None:
            reaches = np.stack([reach_from_guard(getattr(m, "guard_", None),
                                                  m.focus_range if m.focus else math.inf) for m in models])
        returns = np.stack([returns_from_guard(getattr(m, "guard_", None)) for m in models])
        offsets, return_reach = None, math.inf
    return FusedMap([m.tree_ for m in models], poses, reaches, robot, combination=combination, threshold=threshold,
                    stamps=stamps, returns=returns, return_offsets=offsets, return_reach=return_reach,
                    scanning_laser=scanning_laser)


def fuse_model_set(path: Any, *, combination: str = DEFAULT_COMBINATION,
                   threshold: float = 0.6) -> tuple[FusedMap, list[Any], list[tuple[int, Pose, float | None]]]:
    """Fuse a model set written by ``occtool fit LOG -o DIR/`` (``DIR`` or ``DIR/index.json``).

    Returns the fused map, the models and, for each, its position index, pose and stamp.
    The map is a scanning laser's (:attr:`FusedMap.scanning_laser`) when the index gives
    every position's returns per degree (``returns_per_degree``) and they say so.

    Raises
    ------
    InputError
        If the set is malformed (:func:`occtool.modelset.read_model_set`) or a position has
        no pose: a world map needs every model placed.
    """
    from occtool.formats.model import load_model
    from occtool.modelset import read_model_set

    folder, entries = read_model_set(path)
    models, poses, stamps, positions = [], [], [], []
    for entry in entries:
        if entry.get("pose") is None:
            raise InputError(f"{folder / 'index.json'}: position {entry['position']} has no pose for a world map")
        try:
            pose = Pose.from_dict(entry["pose"])
        except (TypeError, ValueError):
            raise InputError(f"{folder / 'index.json'}: position {entry['position']}'s pose is not numbers") from None
        stamp = entry.get("stamp") if isinstance(entry.get("stamp"), (int, float)) else None
        models.append(load_model(folder / entry["file"]))
        poses.append(pose)
        stamps.append(stamp)
        positions.append((entry["position"], pose, stamp))
    # Written by `occtool fit` per position (sets written before it was: walls facing both sides).
    densities = [entry.get("returns_per_degree") for entry in entries]
    known = all(isinstance(d, (int, float)) and not isinstance(d, bool) and math.isfinite(d) and d >= 0
                for d in densities)
    laser = bool(entries) and known and is_scanning_laser(densities)
    return (fuse_models(models, poses, combination=combination, threshold=threshold, stamps=stamps,
                        scanning_laser=laser), models, positions)
