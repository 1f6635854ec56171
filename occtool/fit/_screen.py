"""What the fit knows of the features before any sample is made: the screen.

Which features are obstacles, which are mismatches (:func:`~occtool.fit._sight.contradicted_features`),
the pan origin the fit's angle bins start at, and which returns the return guard holds
(:mod:`occtool.guard`): each return confirmed by returns on neighbouring rays.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from occtool import guard as guard_module
from occtool.features import FeatureGeometry, Features
from occtool.fit._profile import NEAR_SUPPORT_DISTANCE, mean_direction, order_within_bins
from occtool.fit._sight import SightIndex, contradicted_features, sight_index
from occtool.guard import GUARD_BINS, Support, guard_candidates, is_planar_scan, ray_spacing, support_count
from occtool.robot import Robot
from occtool.sensor import SensorModel

FloatArray = NDArray[np.float64]
#: A support query's result: each point's neighbour distances and indices (:class:`Support`).
Neighbours = tuple[FloatArray, NDArray[np.intp]]

#: The return guard's line-of-sight test (:func:`guarded_mask`): rays
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


class Screen:
    """What the fit and the return guard know of the features before any sample is made."""

    # A plain class, not a dataclass: each dataclass made was about 1 ms of a fresh
    # process's import, for a record only the fit builds and reads.
    __slots__ = ("obstacle", "origin", "planar", "mismatch", "sight")

    def __init__(self, obstacle: NDArray[np.bool_], origin: float, planar: bool, mismatch: NDArray[np.bool_],
                 sight: SightIndex | None = None) -> None:
        self.obstacle, self.origin, self.planar, self.mismatch = obstacle, origin, planar, mismatch
        #: The line-of-sight test's index of the features (built by the first test that needs it).
        self.sight = sight

    def without_sight(self) -> Screen:
        """The same screen without its line-of-sight index."""
        return Screen(self.obstacle, self.origin, self.planar, self.mismatch)


def screen_features(features: Features, sensor: SensorModel, robot: Robot, *, basis: str, focus: bool,
                    focus_range: float, geometry: FeatureGeometry | None = None,
                    screened: NDArray[np.bool_] | None = None) -> Screen:
    """Which features are obstacles, which are mismatches, and the fit's pan origin
    (``geometry``: the features' :class:`~occtool.features.FeatureGeometry`, if held).

    ``screened``: the features whose mismatch is asked (default: all); the others are
    not tested, and not reported as mismatches. A feature's answer does not depend on
    which others are tested: every feature counts as a ray."""
    # Mismatches a few centimetres apart can pass for a small obstacle; where other
    # rays in nearly the same direction see through them, they are dropped. Floor
    # features are not obstacles, and grazing rays see "through" them all the time.
    # The trig basis has no seam, so the angular bins can start anywhere: starting them
    # at the mean direction of the obstacle features makes the whole fit (the mismatch
    # test included) turn with the scene: rotating the features rotates the model
    # exactly, not up to a bin.
    geometry = FeatureGeometry.of(features) if geometry is None else geometry
    obstacle = sensor.is_obstacle(features, robot, geometry=geometry) & ~sensor.is_floor(features.points[:, 2], robot)
    obstacle_index = np.flatnonzero(obstacle)
    origin = mean_direction(geometry.alpha.take(obstacle_index)) if basis == "trig" else 0.0
    # A planar scan (a 2D laser) has one beam per direction: a beam passing beside a
    # return says only that the object is narrower than the beam spacing, never that
    # the return is a mismatch (a chair leg is often hit by a single beam).
    planar = is_planar_scan(features.points[:, 2].take(obstacle_index))
    mismatch = np.zeros(len(features), dtype=bool)
    if focus and not planar:
        # Only features the focus keeps can mislead the fit: test those alone.
        candidates = obstacle & (geometry.horizontal <= focus_range)
        if screened is not None:
            candidates &= screened
        sight = sight_index(features, origin, geometry=geometry)
        mismatch = contradicted_features(features, origin=origin, candidates=candidates, index=sight)
        return Screen(obstacle, origin, planar, mismatch, sight)
    return Screen(obstacle, origin, planar, mismatch)


def guarded_mask(features: Features, screen: Screen, robot: Robot, *, level: float, focus: bool,
                 focus_range: float, geometry: FeatureGeometry | None = None,
                 may_hold: NDArray[np.bool_] | None = None) -> tuple[NDArray[np.bool_], FloatArray, float]:
    """The guarded returns, the share of each feature's distance the guard keeps, and the
    ray spacing (radians; 0 for a planar scan, whose beams the guard's bins match)
    (``geometry``: the features' :class:`~occtool.features.FeatureGeometry`, if held;
    ``may_hold``: their :func:`~occtool.guard.guard_candidates` at ``level``, if held)."""
    geometry = FeatureGeometry.of(features) if geometry is None else geometry
    horizontal = geometry.horizontal
    if may_hold is None:
        may_hold = guard_candidates(features, features.evidence, robot, level, horizontal=horizontal)
    returns = screen.obstacle & may_hold
    if focus:
        # Only as far as the fit reaches: beyond it the model is an extrapolation anyway.
        returns &= horizontal <= focus_range + robot.radius
    if screen.planar:
        # A planar scan has no mismatches of this kind: every return is guarded, as measured.
        return returns, np.ones(len(features)), 0.0
    # 3D data. A return is dropped as a mismatch only when rays clearly pass through it:
    # a stricter test than the fit's, which also drops the front edge of a thin seat or
    # table top that rays graze on their way to the floor beyond.
    # Only the fit's mismatches are tested (none: no test, and no index built for it).
    tested = returns & screen.mismatch
    strict = np.zeros(len(features), dtype=bool)
    if tested.any():
        strict = contradicted_features(features, origin=screen.origin, candidates=tested,
                                       tolerance=GUARD_SIGHT_TOLERANCE, ratio=GUARD_SIGHT_RATIO, index=screen.sight)
    returns &= ~strict
    spacing = ray_spacing(features.points)
    # A return alone may be a mismatch; one confirmed by returns on neighbouring rays at
    # nearly its range (at any height: a sign hanging into the band is confirmed by its
    # part above it) is a surface.
    index = np.flatnonzero(returns)
    candidates = features.points[index]
    distance = horizontal[index]
    # Support from returns near enough (in reach and height) to confirm a candidate.
    z = features.points[:, 2]
    low, high = robot.body_band
    near = (horizontal <= 1.2 * float(distance.max(initial=0.0)) + 0.1) & (
        z >= low - SUPPORT_HEIGHT_REACH) & (z <= high + SUPPORT_HEIGHT_REACH)
    # At any evidence: a weak return still ended its ray there, which is what tells a surface
    # from a lone mismatch (the guarded return itself needs the level). Supporters at the
    # level only left a hanging lamp unguarded when evidence ran 0.3-1 (1.9 % violation at 1k).
    support = np.flatnonzero(near & screen.obstacle & ~strict)
    # Near the robot a surface spans a wide tilt range and many rays end on it, while
    # two mismatches there box the robot in: the count grows as 1 / distance, as the fit's.
    needed = support_count(len(features)) * np.maximum(1.0, NEAR_SUPPORT_DISTANCE / np.maximum(distance, 1e-9))
    # Only a guard bin's nearest confirmed return counts: test each bin's nearest
    # returns first, and farther ones only in bins where none was confirmed yet (a
    # million features: 0.9 s of the fit for the support test of every return).
    bins = np.mod(np.floor((geometry.alpha[index] + math.pi)
                           * (GUARD_BINS / (2.0 * math.pi))).astype(np.int64), GUARD_BINS)
    order, bounds = order_within_bins(bins, distance, GUARD_BINS)
    starts = bounds[:-1]
    rank = np.empty(order.size, dtype=np.int64)
    rank[order] = np.arange(order.size) - starts[bins[order]]
    confirmed = np.zeros(index.size, dtype=bool)
    settled = np.zeros(GUARD_BINS, dtype=bool)
    confirming = Support.of_rows(features.points, support, spacing)
    # The neighbours each test found, for the seen-from-above test of the confirmed returns
    # (one query for both where it can serve both). Only the first test shares its query:
    # each bin's nearest returns are mostly kept (10k features: 3,079 of 3,261), farther ones
    # seldom (a million: 499 of 132k), so those ask for no more neighbours than they need
    # (the kept ones are then queried again, and the same neighbours found).
    found: list[tuple[NDArray[np.intp], Neighbours]] = []
    low_rank, chunk = 0, GUARD_TEST_CHUNK
    while low_rank < max(int(rank.max(initial=-1)) + 1, 0):
        tested = (rank >= low_rank) & (rank < low_rank + chunk) & ~settled[bins]
        if not tested.any():
            break
        chosen = np.flatnonzero(tested)
        confirmed[chosen], neighbours = confirming._confirmed(candidates[chosen], needed[chosen],
                                                              steep=low_rank == 0)
        if neighbours is not None:
            found.append((chosen, neighbours))
        settled[bins[chosen[confirmed[chosen]]]] = True
        low_rank, chunk = low_rank + chunk, 2 * chunk
    returns[index[~confirmed]] = False
    # A surface seen from above is first hit up to a ray spacing or two behind its front
    # edge: its returns are taken that much nearer. A wall's or a leg's first return is
    # its front (at 1k features the blanket shrink cost 0.07 IoU).
    scale = np.ones(len(features))
    kept = np.flatnonzero(returns)  # index[confirmed]: returns was index before the test
    tops = confirming.seen_from_above(features.points[kept],
                                      _neighbours_of(np.flatnonzero(confirmed), found, confirming, candidates))
    scale[kept[tops]] = max(0.0, 1.0 - guard_module.SPACING_FACTOR * spacing)
    return returns, scale, spacing


def _neighbours_of(positions: NDArray[np.intp], found: list[tuple[NDArray[np.intp], Neighbours]],
                   support: Support, candidates: FloatArray) -> Neighbours | None:
    """The neighbours :meth:`Support.seen_from_above` needs for the candidates at
    ``positions`` (rows of ``candidates``), in that order: those ``found`` (chunks of
    positions and their query) copied, the rest queried (none found: None)."""
    if not found:
        return None
    size = max(int(positions.max(initial=-1)) + 1, max(int(c.max(initial=-1)) + 1 for c, _ in found))
    chunk_of = np.full(size, -1)
    row_of = np.zeros(size, dtype=np.intp)
    for number, (chosen, _) in enumerate(found):
        chunk_of[chosen] = number
        row_of[chosen] = np.arange(chosen.size)
    chunks, rows = chunk_of[positions], row_of[positions]
    k = found[0][1][0].shape[1]
    distance = np.empty((positions.size, k))
    index = np.empty((positions.size, k), dtype=np.intp)
    for number, (_, (chunk_distance, chunk_index)) in enumerate(found):
        mine = np.flatnonzero(chunks == number)
        distance[mine] = chunk_distance[rows[mine]]
        index[mine] = chunk_index[rows[mine]]
    missing = np.flatnonzero(chunks < 0)
    if missing.size:
        distance[missing], index[missing] = support.steep_neighbours(candidates[positions[missing]])
    return distance, index


def profile_returns(features: Features, sensor: SensorModel, robot: Robot,
                    origin: float, geometry: FeatureGeometry | None = None) -> tuple[FloatArray, FloatArray]:
    """Turned pan angle and horizontal distance of the returns the range profile is made of:
    the features that give hit samples, in the body band (from the floor up when the
    floor is an obstacle) (``geometry``: the features' :class:`~occtool.features.FeatureGeometry`,
    if held)."""
    geometry = FeatureGeometry.of(features) if geometry is None else geometry
    low, high = robot.body_band
    if sensor.floor == "obstacle":
        low = -np.inf
    z = features.points[:, 2]
    chosen = np.flatnonzero(sensor.is_obstacle(features, robot, geometry=geometry) & (z >= low) & (z <= high))
    return geometry.turned(origin).take(chosen), geometry.horizontal.take(chosen)
