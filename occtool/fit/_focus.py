"""The samples the fit sees: the focus on what a monotone model can show, and the frontier.

``F`` increases with ``r``, so behind the first obstacle at a pan angle the samples can only
pull the fit away from it: :func:`focus_samples` keeps those in front of it, in the body's
height band and within the focus range. Where the observed free space ends short of that
range, :func:`frontier_samples` adds occupied samples, so linear pieces do not extrapolate
free space into what was never seen.
"""

from __future__ import annotations

import numpy as np

from occtool.fit._profile import (
    FOCUS_ANGLE_BINS,
    FOCUS_WINDOW,
    FOCUS_WINDOW_ABS,
    adaptive_support,
    angle_bins,
    first_obstacle_distance,
    group_by_bin,
)
from occtool.robot import Robot
from occtool.sensor import SAMPLE_KINDS, Samples

#: Samples up to this fraction (and the window) beyond the first obstacle are kept.
FOCUS_MARGIN = 0.1


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
