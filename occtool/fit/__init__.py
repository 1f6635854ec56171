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
3. Each centre piece's level crossing is placed by a small linear programme as far out
   as the segment's first obstacles allow, at every height of the body band; its slope in
   ``r`` comes from a robust fit to the samples.
4. Optional refit sweeps: each piece is refitted by bounded, Huber-weighted least squares
   to the samples where it is active, accepted only if the total Huber loss goes down
   (plain alternation oscillates).

Every constraint (``c >= c_min``, ``|dF/dalpha| <= a_max``, ``|b| <= b_max``) holds exactly
for every piece at every step, since each candidate piece is projected onto them.
The parts, one concept a module (private; everything public is imported from here):

========================  ===============================================================
``_regressor``            the estimator: parameters, ``fit``, fitted state, predictions
``_screen``               obstacles, mismatches, pan origin and guarded returns
``_sight``                the line-of-sight test that finds mismatches
``_focus``                the samples kept (focus) and added (frontier)
``_profile``              angle bins, the first-obstacle profile, its segments
``_construction``         the initial tree: segments, centre pieces by LP, side pieces
``_refit``                the loss, the constraints, box QP and the refit sweeps
========================  ===============================================================
"""

from occtool.fit._focus import focus_samples, frontier_samples, join_samples
from occtool.fit._profile import (
    FOCUS_ANGLE_BINS,
    FOCUS_SUPPORT,
    FOCUS_WINDOW,
    FOCUS_WINDOW_ABS,
    adaptive_support,
    angle_bins,
    first_obstacle_distance,
    first_obstacles_in_band,
    segment_near_runs,
    sorted_within_bins,
)
from occtool.fit._refit import LOSS_SAMPLES, ProgressCallback, box_qp, huber_loss
from occtool.fit._regressor import (
    DEFAULT_BASIS,
    DEFAULT_FOCUS_RANGE,
    DEFAULT_PIECES,
    MORE_PIECES_FROM,
    MOST_DEFAULT_PIECES,
    PLANAR_FOCUS_RANGE,
    OccupancyRegressor,
    default_pieces,
    features_digest,
    fit_together,
    slope_bounds,
)
from occtool.fit._sight import contradicted_features

__all__ = [
    "DEFAULT_BASIS",
    "DEFAULT_FOCUS_RANGE",
    "PLANAR_FOCUS_RANGE",
    "DEFAULT_PIECES",
    "FOCUS_ANGLE_BINS",
    "FOCUS_SUPPORT",
    "FOCUS_WINDOW",
    "FOCUS_WINDOW_ABS",
    "LOSS_SAMPLES",
    "MORE_PIECES_FROM",
    "MOST_DEFAULT_PIECES",
    "OccupancyRegressor",
    "ProgressCallback",
    "adaptive_support",
    "angle_bins",
    "box_qp",
    "contradicted_features",
    "default_pieces",
    "features_digest",
    "first_obstacle_distance",
    "fit_together",
    "first_obstacles_in_band",
    "focus_samples",
    "frontier_samples",
    "huber_loss",
    "join_samples",
    "segment_near_runs",
    "slope_bounds",
    "sorted_within_bins",
]
