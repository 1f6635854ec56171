"""Asking a fitted model what to draw: ``F`` on grids, the active piece, its robot and extent."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError, OcctoolError
from occtool.plot._canvas import FloatArray
from occtool.robot import Robot

if TYPE_CHECKING:  # pragma: no cover

    pass


def evaluate_on_floor_grid(
    model: Any, height: float, extent: float, resolution: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Evaluate ``F`` on a square x, y grid around the robot at one sensor-frame height.

    Parameters
    ----------
    model
        A fitted model with ``predict(alpha, h, r)``.
    height
        Sensor-frame height ``h`` (negative below the sensor), metres.
    extent
        Half-width of the square, metres.
    resolution
        Cells along each side.

    Returns
    -------
    x, y, F
        Cell-centre coordinates (``(resolution,)`` each) and ``(resolution, resolution)``
        occupancy values, rows along y.
    """
    axis, alpha, h, r = _floor_grid(height, extent, resolution)
    values = np.asarray(model.predict(alpha, h, r), dtype=np.float64).reshape(resolution, resolution)
    return axis, axis.copy(), values


def _floor_grid(height: float, extent: float, resolution: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Cell centres of a square x, y grid at one height, and their (alpha, h, r), flattened row by row."""
    if resolution < 2:
        raise InputError(f"resolution must be at least 2 cells, got {resolution}")
    step = 2.0 * extent / resolution
    axis: FloatArray = -extent + step * (np.arange(resolution, dtype=np.float64) + 0.5)
    gx, gy = np.meshgrid(axis, axis)
    alpha = np.arctan2(gy, gx).ravel()
    h = np.full(alpha.shape, float(height))
    r = np.sqrt(gx.ravel() ** 2 + gy.ravel() ** 2 + height**2)
    return axis, alpha, h, r


def occupied_projection(
    model: Any,
    level: float,
    heights: Sequence[float],
    max_range: float,
    *,
    angles: int = 180,
    ranges: int = 60,
) -> tuple[FloatArray, FloatArray]:
    """Points of a uniform (alpha, h, r) grid where ``F`` exceeds a level, projected on the floor.

    Sampling is uniform in the model's own coordinates, which gives the picture the
    circular look of the paper's Figure 5b.

    Parameters
    ----------
    model
        A fitted model with ``predict(alpha, h, r)``.
    level
        Occupancy level; points with ``F > level`` are returned.
    heights
        Sensor-frame heights to sample, metres.
    max_range
        Largest horizontal distance sampled, metres.
    angles, ranges
        Samples in pan angle and in horizontal distance.

    Returns
    -------
    xy, values
        ``(K, 2)`` floor coordinates and the ``(K,)`` occupancy values there.
    """
    heights_array = np.asarray(heights, dtype=np.float64).reshape(-1)
    if heights_array.size == 0:
        raise InputError("at least one height is needed for the projection")
    alpha = np.linspace(-np.pi, np.pi, angles, endpoint=False)
    horizontal = np.linspace(max_range / ranges, max_range, ranges)
    a, h, d = np.meshgrid(alpha, heights_array, horizontal, indexing="ij")
    r = np.sqrt(d**2 + h**2)
    values = np.asarray(model.predict(a.ravel(), h.ravel(), r.ravel()), dtype=np.float64)
    keep = values > level
    x = (d.ravel() * np.cos(a.ravel()))[keep]
    y = (d.ravel() * np.sin(a.ravel()))[keep]
    return np.column_stack([x, y]), values[keep]


def active_piece_function(model: Any) -> Callable[[FloatArray, FloatArray, FloatArray], NDArray[np.intp]] | None:
    """The model's "which linear piece is active" function, if it has one.

    Looks for ``active_piece(alpha, h, r)`` on the fitted estimator's ``tree_`` and on
    the object itself (a :class:`occtool.tree.MinMaxTree` has it).

    Returns
    -------
    callable or None
        ``f(alpha, h, r) -> piece index`` per point, or None when there is none.
    """
    for owner in (getattr(model, "tree_", None), model):
        function = getattr(owner, "active_piece", None)
        if callable(function):
            return function
    return None


def model_piece_count(model: Any) -> int | None:
    """Number of linear pieces in a model's tree, when it says."""
    for owner in (getattr(model, "tree_", None), model):
        value = getattr(owner, "n_pieces", None)
        if isinstance(value, (int, np.integer)):
            return int(value)
    return None


def model_robot(model: Any) -> Robot:
    """The robot a model was fitted for (``robot_``, else ``robot``), or the default robot."""
    for name in ("robot_", "robot"):
        robot = getattr(model, name, None)
        if isinstance(robot, Robot):
            return robot
    return Robot()


def model_extent(model: Any, level: float, robot: Robot | None = None, *, default: float = 5.0) -> float:
    """Half-width of the area worth drawing around a model, metres.

    Twice the horizontal distance at which ``F`` reaches ``level``,
    taken at the median over pan angles and heights of the robot's body band,
    between 1 and 30 m; ``default`` for a model without ``inverse_range``.
    """
    inverse = getattr(model, "inverse_range", None)
    if not callable(inverse):
        return default
    robot = robot or model_robot(model)
    heights = np.linspace(*robot.body_band, 3)[:, None]
    alpha = np.linspace(-np.pi, np.pi, 180, endpoint=False)[None, :]
    r = np.asarray(inverse(alpha, heights, level), dtype=np.float64)
    horizontal = np.sqrt(np.clip(r**2 - heights**2, 0.0, None))
    finite = horizontal[np.isfinite(horizontal)]
    if finite.size == 0 or finite.max() <= 0:
        return default
    # The median, not the maximum or a high percentile: where the model saw no features
    # (or only far ones) F rises slowly and the level is crossed far away, which would
    # shrink the surroundings of the robot to a dot.
    return float(np.clip(2.0 * np.median(finite), 1.0, 30.0))


def _model_summary(model: Any) -> str:
    summary = getattr(model, "training_summary", None)
    if not callable(summary):
        return ""
    try:
        values = summary()
    except OcctoolError:  # an unfitted model has no summary to show
        return ""
    parts = []
    if isinstance(values.get("n_features"), int):
        parts.append(f"{values['n_features']} features")
    if isinstance(values.get("rmse"), float):
        parts.append(f"RMSE {values['rmse']:.3f}")
    return ", ".join(parts)
