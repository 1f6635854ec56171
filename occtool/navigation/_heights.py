"""Where the model is cut: the slice heights, and the margin that makes the map hold between them.

The requested heights (by default :func:`default_heights` across the body band) are the
map's slices. With a piecewise-linear model's ``slope_bounds``, slices are added and the
threshold is lowered by the most the model can vary between a body height and its nearest
slice and between neighbouring rays; with exact ``free_bounds``, the band is covered by
thin height boxes instead, with no margin (docs/navigation.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.robot import Robot

FloatArray = NDArray[np.float64]

#: Default spacing of the default heights across the robot's body band, metres.
DEFAULT_HEIGHT_SPACING = 0.25
#: With slope bounds and no ``slice_spacing``: slices are added until the height part of
#: the threshold margin is at most this (occupancy units) ...
DEFAULT_HEIGHT_MARGIN = 0.05
#: ... but never closer than this, metres, so a very steep model cannot ask for
#: thousands of slices; the rest of the margin then lowers the threshold.
MIN_AUTO_SLICE_SPACING = 0.01
#: With ``free_bounds``: the body band is covered by boxes at most this tall, metres (the
#: bound is exact piece by piece; a box spanning the height where two pieces of a group
#: trade places gives a little away, less the thinner the box).
BOUND_HEIGHT_STEP = 0.1
#: Most heights a map may be cut at (a guard against a tiny slice spacing or a huge body).
MAX_SLICES = 10_000


def default_heights(robot: Robot, spacing: float = DEFAULT_HEIGHT_SPACING) -> FloatArray:
    """Sensor-frame heights spanning the robot's body band.

    The band (from the ground clearance to the top of the body) is split into
    ``ceil(band / spacing)`` equal parts and cut at their midpoints, which puts every
    body height as close to a cut as that many cuts can.

    Parameters
    ----------
    robot
        The robot whose :attr:`~occtool.robot.Robot.body_band` is spanned.
    spacing
        Largest distance between neighbouring heights, metres.

    Returns
    -------
    numpy.ndarray
        Ascending heights, metres.

    Examples
    --------
    >>> default_heights(Robot(sensor_height=1.0, body_height=1.0, ground_clearance=0.0)).round(3)
    array([-0.875, -0.625, -0.375, -0.125])
    """
    low, high = robot.body_band
    count = max(1, math.ceil((high - low) / spacing - 1e-9))
    return low + (np.arange(count) + 0.5) * (high - low) / count


def farthest_from_slices(heights: ArrayLike, band: tuple[float, float]) -> float:
    """The largest distance from a height of ``band`` (or between the heights) to a slice.

    Parameters
    ----------
    heights
        Slice heights, metres.
    band
        ``(low, high)`` heights that must be covered, metres.

    Returns
    -------
    float
        Metres; the heights' own span is covered too when it reaches beyond the band.
    """
    cuts = np.sort(np.asarray(heights, dtype=np.float64))
    low, high = min(band[0], cuts[0]), max(band[1], cuts[-1])
    gaps = np.diff(cuts) / 2.0
    return float(max(cuts[0] - low, high - cuts[-1], gaps.max(initial=0.0)))


def add_slices(heights: ArrayLike, band: tuple[float, float], spacing: float) -> FloatArray:
    """Insert heights so that no body height is farther than ``spacing / 2`` from a slice.

    The requested heights are kept; each gap between them is split evenly, and slices
    are added below the lowest and above the highest down to and up to the band ends.

    Parameters
    ----------
    heights
        Requested heights, metres.
    band
        ``(low, high)`` heights that must be covered, metres.
    spacing
        Largest allowed gap between neighbouring slices, metres.

    Returns
    -------
    numpy.ndarray
        Ascending heights including the requested ones.
    """
    cuts = np.unique(np.asarray(heights, dtype=np.float64))
    parts = [cuts]
    for lower, upper in zip(cuts[:-1], cuts[1:]):
        pieces = math.ceil((upper - lower) / spacing - 1e-9)
        if pieces > 1:
            parts.append(lower + (upper - lower) * np.arange(1, pieces) / pieces)
    below = cuts[0] - band[0]
    if below > spacing / 2:
        parts.append(cuts[0] - spacing * np.arange(1, math.ceil((below - spacing / 2) / spacing - 1e-9) + 1))
    above = band[1] - cuts[-1]
    if above > spacing / 2:
        parts.append(cuts[-1] + spacing * np.arange(1, math.ceil((above - spacing / 2) / spacing - 1e-9) + 1))
    return np.unique(np.concatenate(parts))


def _checked_bounds(slope_bounds: Mapping[str, float]) -> tuple[float, float, float]:
    values = []
    for key in ("a_max", "b_max", "c_max"):
        if key not in slope_bounds:
            raise InputError(f"slope bounds need a_max, b_max and c_max; {key} is missing")
        value = float(slope_bounds[key])
        if not math.isfinite(value) or value < 0:
            raise InputError(f"slope bound {key} must be a finite number >= 0, got {slope_bounds[key]}")
        values.append(value)
    return values[0], values[1], values[2]


def height_lipschitz(slope_bounds: Mapping[str, float]) -> float:
    """How fast the occupancy can change with height at a fixed horizontal distance.

    At a fixed pan angle and horizontal distance ``rho``, a piece ``a alpha + b h + c r + d``
    with ``r = sqrt(rho^2 + h^2)`` changes with ``h`` at ``b + c h / r``, and ``|h / r| <= 1``;
    min and max nodes keep the largest of their children's rates.

    Parameters
    ----------
    slope_bounds
        ``a_max``, ``b_max``, ``c_max`` of the model's pieces.

    Returns
    -------
    float
        ``b_max + c_max``, occupancy per metre.
    """
    _, b_max, c_max = _checked_bounds(slope_bounds)
    return b_max + c_max


def requested_heights(heights: ArrayLike | None, robot: Robot) -> FloatArray:
    """The heights asked for (default :func:`default_heights`), checked, unique and ascending."""
    band = robot.body_band
    if heights is None and (band[1] - band[0]) / DEFAULT_HEIGHT_SPACING > MAX_SLICES:
        raise InputError(f"a body band of {band[1] - band[0]:g} m would need over {MAX_SLICES} cuts")
    requested = default_heights(robot) if heights is None else np.asarray(heights, dtype=np.float64).ravel()
    if requested.size == 0:
        raise InputError("at least one height is needed")
    if requested.size > MAX_SLICES:
        raise InputError(f"heights holds {requested.size:,} heights, more than {MAX_SLICES:,}")
    if not np.isfinite(requested).all():
        raise InputError(f"heights must be finite numbers, got {requested.tolist()}")
    if (requested <= robot.floor_h).any():
        raise InputError(
            f"height {requested.min():g} m is at or below the floor ({robot.floor_h:g} m in the sensor frame, "
            f"sensor height {robot.sensor_height:g} m)"
        )
    return np.unique(requested)


class Cuts(NamedTuple):
    """The heights the model is cut at and the threshold margin that goes with them."""

    #: Every cut height (the requested ones and any added), ascending; with exact bounds
    #: the edges of the height boxes.
    heights: FloatArray
    #: How far the threshold is lowered (0 without slope bounds).
    margin: float
    #: Whether the margin covers the model's variation between rays too, so each ray must
    #: take the least of its own and its neighbours' distances.
    between_rays: bool


def cut_heights(requested: FloatArray, robot: Robot, n_angles: int, *,
                slope_bounds: Mapping[str, float] | None, slice_spacing: float | None,
                exact_bounds: bool) -> Cuts:
    """Where to cut the model for ``requested`` heights, and the margin that makes the map hold.

    With ``exact_bounds`` (a model's ``free_bounds``): the requested heights and the band's
    ends, split into boxes at most :data:`BOUND_HEIGHT_STEP` tall, and no margin. Otherwise,
    with ``slope_bounds``: slices added ``slice_spacing`` apart (default: enough for a height
    margin of :data:`DEFAULT_HEIGHT_MARGIN`) and the margin of :func:`height_lipschitz`
    times the farthest body height from a slice, plus ``a_max`` times half a ray step.
    """
    band = robot.body_band
    margin = 0.0
    if exact_bounds:
        # Exact bounds over boxes: no Lipschitz margin, no added slices.
        slope_bounds, slice_spacing = None, None
    if slope_bounds is not None:
        a_max, _, _ = _checked_bounds(slope_bounds)
        lipschitz = height_lipschitz(slope_bounds)
        if slice_spacing is None and lipschitz > 0:
            slice_spacing = max(2.0 * DEFAULT_HEIGHT_MARGIN / lipschitz, MIN_AUTO_SLICE_SPACING)
    if slice_spacing is not None:
        extent = max(band[1], requested[-1]) - min(band[0], requested[0])
        if extent / slice_spacing > MAX_SLICES:
            raise InputError(
                f"slice spacing {slice_spacing:g} m would cut the {extent:g} m the heights and body span over "
                f"{MAX_SLICES} times"
            )
    cuts = requested if slice_spacing is None else add_slices(requested, band, float(slice_spacing))
    if exact_bounds:
        # Box edges: the requested heights and the band's ends, split to BOUND_HEIGHT_STEP.
        edges = np.unique(np.concatenate([requested, [band[0], band[1]]]))
        cuts = add_slices(edges, (edges[0], edges[-1]), BOUND_HEIGHT_STEP)
    # Keep added slices above the floor: a cut on the floor sees only the floor.
    cuts = cuts[cuts > robot.floor_h]
    if slope_bounds is not None:
        margin = lipschitz * farthest_from_slices(cuts, band) + a_max * np.pi / n_angles
    return Cuts(cuts, margin, slope_bounds is not None)
