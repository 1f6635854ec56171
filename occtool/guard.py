"""The return guard: a position's own returns, which its navigation polygon must keep clear of.

A min/max tree of a few dozen linear pieces is a smooth summary: an obstacle seen by one
or two rays (a chair leg in a laser scan, a pallet corner in sparse stereo) can fall
between its pieces, and the navigation map would then send the robot into a return of
its own scan. The returns are known when the model is fitted, so the model keeps the
least it needs to rule that out: per pan-angle bin (:data:`GUARD_BINS` over
``[-pi, pi)``), the horizontal distance of the nearest *guarded return*, a feature

* with evidence at or above the model's level (the threshold it is fitted for),
* inside the robot's height band (above the ground clearance, below the body's top),
* outside the robot's current footprint (a return inside it is the robot itself or a
  mismatch: the robot stands there), within the fit's reach (``focus_range`` plus the
  radius), and
* for 3D data, not clearly passed through by other rays (:func:`occtool.fit.contradicted_features`
  with a tight tolerance) and confirmed by returns on neighbouring rays at nearly its
  range (:class:`Support`); a *planar* scan's returns are all guarded as measured,
  since its beams pass beside each other, never through the same spot twice.

For 3D data a guarded return also holds the bins within half a ray spacing of its pan
angle (the surface between it and the next ray, which no ray saw), and one that may lie
on a surface seen from above (a table top: its first return lies up to a ray spacing or
two behind its front edge; :meth:`Support.seen_from_above`) is taken two ray spacings
nearer. A wall's or a leg's first return is its front, and is kept as measured.

The navigation map (:func:`occtool.navigation.navigation_map`) caps every ray's free
distance by the guard's distances around it, before the shrink by the robot's radius:
the star polygon through the rays then holds no guarded return strictly inside, so the
shrunk polygon keeps every one at least the radius away. (The tree itself is not bent to
single returns: that cost IoU for no safety the guard does not give.)

A guard is 360 distances, under 2 KB in a model file, whatever the number of features.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool._stats import median
from occtool.errors import ModelFormatError
from occtool.features import Features
from occtool.neighbours import NeighbourIndex, nearest_other_distance
from occtool.robot import Robot

FloatArray = NDArray[np.float64]

#: Pan-angle bins of a guard over [-pi, pi): one degree, a SICK scanner's beam spacing (a
#: return stands for its whole bin, 9 mm either side at 1 m).
GUARD_BINS = 360
#: Distances are stored rounded *down* to whole millimetres, so a stored guard is never
#: farther than the returns it stands for.
GUARD_RESOLUTION = 0.001  # metres
#: A position is a planar scan when all its returns lie within this height (m) of each other.
PLANAR_TOLERANCE = 0.01


@dataclass(frozen=True, eq=False)
class ReturnGuard:
    """Nearest guarded return per pan-angle bin.

    Attributes
    ----------
    distance
        ``(bins,)`` horizontal distance (m) of the nearest guarded return in each bin of
        ``[-pi, pi)`` (bin ``i`` spans ``-pi + i w`` to ``-pi + (i + 1) w``, ``w = 2 pi / bins``);
        ``inf`` where there is none.
    level
        Evidence at or above which a return is guarded: the model's level. A map cut at a
        lower threshold is guarded only for returns at or above this level.
    """

    distance: FloatArray
    level: float

    def __post_init__(self) -> None:
        distance = np.asarray(self.distance, dtype=np.float64).reshape(-1)
        if distance.size < 8:
            raise ModelFormatError(f"a return guard needs at least 8 bins, got {distance.size}")
        if np.isnan(distance).any() or (distance <= 0).any():
            raise ModelFormatError("a return guard's distances must be numbers > 0 (or null for none)")
        if not (math.isfinite(self.level) and 0.0 < self.level <= 1.0):
            raise ModelFormatError(f"a return guard's level must lie in (0, 1], got {self.level!r}")
        object.__setattr__(self, "distance", distance)

    @property
    def bins(self) -> int:
        return int(self.distance.size)

    @property
    def n_returns_bins(self) -> int:
        """Bins holding a guarded return."""
        return int(np.isfinite(self.distance).sum())

    def ray_bounds(self, alpha: ArrayLike) -> FloatArray:
        """Farthest free distance of each of ``n`` evenly spaced rays that keeps the guard.

        ``alpha`` are the map's pan angles, ``alpha[i + 1] - alpha[i] = 2 pi / n``. Each
        ray gets the least guarded distance over the bins that overlap the angles from its
        previous to its next ray: the two triangles (origin, ray, neighbour ray) of a star
        polygon through rays so capped lie within the disk of that distance, so no guarded
        return lies strictly inside the polygon.
        """
        alpha = np.asarray(alpha, dtype=np.float64).reshape(-1)
        n = alpha.size
        if n == 0:
            return np.empty(0)
        step = 2.0 * math.pi / n
        width = 2.0 * math.pi / self.bins
        # Bin indices (unwrapped) of each ray's window [alpha - step, alpha + step]; a
        # hair wider, so rounding never leaves out a bin that the window touches.
        slack = 1e-9
        low = np.floor((alpha - step - slack + math.pi) / width).astype(np.int64)
        high = np.floor((alpha + step + slack + math.pi) / width).astype(np.int64)
        span = int((high - low).max()) + 1
        index = low[:, None] + np.arange(span)[None, :]
        values = self.distance[np.mod(index, self.bins)]
        values = np.where(index <= high[:, None], values, np.inf)
        return values.min(axis=1)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"bins", "level", "distance_mm": [whole millimetres, or null for none]}``."""
        return {
            "bins": self.bins,
            "level": float(self.level),
            "distance_mm": [None if not math.isfinite(d) else int(round(d * 1000.0)) for d in self.distance.tolist()],
        }

    @classmethod
    def from_dict(cls, data: Any) -> ReturnGuard:
        """Read :meth:`to_dict` output; :class:`ModelFormatError` when it is malformed."""
        if not isinstance(data, dict):
            raise ModelFormatError("'guard' must be an object")
        values = data.get("distance_mm")
        if not isinstance(values, list) or data.get("bins") != len(values):
            raise ModelFormatError("the guard's 'distance_mm' must be a list of 'bins' whole numbers or nulls")
        distance = np.empty(len(values))
        for i, value in enumerate(values):
            if value is None:
                distance[i] = np.inf
            elif isinstance(value, int) and not isinstance(value, bool) and 0 < value < 10**9:
                distance[i] = value / 1000.0
            else:
                raise ModelFormatError(f"the guard's distance {i} is not a whole number of millimetres > 0 or null: "
                                       f"{value!r}")
        level = data.get("level")
        if isinstance(level, bool) or not isinstance(level, (int, float)):
            raise ModelFormatError(f"the guard's level must be a number, got {level!r}")
        return cls(distance, float(level))


def is_planar_scan(heights: ArrayLike) -> bool:
    """Whether returns at sensor-frame ``heights`` all lie in one horizontal plane (a 2D laser)."""
    heights = np.asarray(heights, dtype=np.float64)
    return heights.size > 0 and float(heights.max() - heights.min()) <= PLANAR_TOLERANCE


def guard_candidates(features: Features, evidence: ArrayLike, robot: Robot, level: float, *,
                     horizontal: FloatArray | None = None) -> NDArray[np.bool_]:
    """Features that are returns the robot must keep clear of (before the mismatch test).

    Evidence at or above ``level``, height within the robot's body band, horizontal
    distance beyond the robot's radius. ``evidence`` is the features' evidence (passed
    apart so a caller may mask free rays or floor features beforehand); ``horizontal``
    the features' ``hypot(x, y)``, when the caller has it.
    """
    x, y, z = features.points.T
    low, high = robot.body_band
    if horizontal is None:
        horizontal = np.hypot(x, y)
    return (
        (np.asarray(evidence) >= level) & (z >= low) & (z <= high) & (horizontal > robot.radius)
    )


#: Returns (itself included) that confirm a return of 3D data at about
#: :data:`SUPPORT_REFERENCE` features per position; the count grows with the square root
#: of the feature count, as mismatches do per neighbourhood.
SUPPORT_COUNT = 2
SUPPORT_REFERENCE = 1000
#: Neighbours confirm a return when their rays lie within this many ray spacings of its
#: ray and they end at nearly its range (:data:`SUPPORT_RANGE_SHARE`): a surface is hit by
#: neighbouring rays at nearly the same range, a mismatch lies alone on its ray.
SUPPORT_SPACINGS = 3.0
#: Relative range difference (about 15 %) within which neighbouring returns lie on one surface.
SUPPORT_RANGE_SHARE = 0.15


def support_count(n_features: int) -> int:
    """Returns that confirm one another among ``n_features``."""
    return max(SUPPORT_COUNT, int(math.floor(SUPPORT_COUNT * math.sqrt(max(n_features, 1) / SUPPORT_REFERENCE))))


#: Most support points indexed at once (an even subsample beyond).
SUPPORT_SAMPLE = 50_000
#: Points whose support is counted at once (their neighbours are held meanwhile).
SUPPORT_QUERY_BLOCK = 1 << 16


def _support_step(count: int) -> int:
    """The step of the even subsample that stands for ``count`` support points."""
    return max(1, -(-count // SUPPORT_SAMPLE))


class Support:
    """The returns that may confirm a guarded return, indexed once for many queries.

    A return is confirmed by ``count`` of them (itself included) on neighbouring rays:
    within :data:`SUPPORT_SPACINGS` ray spacings (``spacing``, radians) of direction and
    :data:`SUPPORT_RANGE_SHARE` of range. A surface is hit by neighbouring rays at nearly
    the same range, even a thin sign or a seat seen from above; a mismatch lies alone on
    its ray. A sign hanging into the body's height band is confirmed by its part above it.

    Beyond :data:`SUPPORT_SAMPLE` of them an even subsample of one in ``step`` stands for
    them: its spacing (:attr:`spacing`) is ``sqrt(step)`` times ``spacing``, and it needs
    ``count / sqrt(step)`` of its points (:func:`support_count` grows as the square root
    of the count of returns): the test of a position of ``1 / step`` the returns.
    """

    def __init__(self, support: ArrayLike, spacing: float) -> None:
        support = np.asarray(support, dtype=np.float64).reshape(-1, 3)
        # Beyond SUPPORT_SAMPLE points an even subsample stands for them, with the reach
        # and count of its own ray spacing (_index; at a million features the full set
        # took 6.5 s of the fit).
        self._index(support[::_support_step(support.shape[0])], support.shape[0], spacing)

    @classmethod
    def of_rows(cls, points: FloatArray, rows: NDArray[np.intp], spacing: float) -> Support:
        """``Support(points[rows], spacing)``, without gathering the rows its subsample
        leaves out (a million features: 480k rows gathered for 48k kept)."""
        support = object.__new__(cls)
        support._index(points.take(rows[::_support_step(rows.size)], axis=0), rows.size, spacing)
        return support

    def _index(self, points: FloatArray, count: int, spacing: float) -> None:
        """Index ``points``, the subsample of ``count`` support points."""
        self.step = _support_step(count)
        # The subsample's rays lie sqrt(step) times as far apart as all the returns': the
        # reach grows with them, so a surface's return finds as many of the subsample's
        # points around it as at full density (dividing the count by the step at the full
        # reach asked a wall for 7 of the 2 or 3 it showed: at a million features the guard
        # lost a fifth of its bins, a table top's edge among them).
        self.spacing = float(spacing) * math.sqrt(self.step)
        self.points = points
        # Reach 1 in the embedding (numpy: scipy.spatial's import cost a fresh process more
        # CPU than a fit of 10k features; the answers are cKDTree's, occtool.neighbours).
        self.tree = NeighbourIndex(self._embedded(self.points), reach=1.0)

    @cached_property
    def _heights(self) -> FloatArray:
        return np.ascontiguousarray(self.points[:, 2])

    @cached_property
    def _horizontal(self) -> FloatArray:
        return np.hypot(self.points[:, 0], self.points[:, 1])

    def _embedded(self, p: FloatArray) -> FloatArray:
        # Unit direction scaled so the angular reach is 1, log range so the range share is 1.
        r = np.linalg.norm(p, axis=1)
        direction = p / r[:, None] / max(SUPPORT_SPACINGS * self.spacing, 1e-9)
        return np.column_stack([direction, np.log(r) / math.log1p(SUPPORT_RANGE_SHARE)])

    def confirmed(self, points: ArrayLike, count: ArrayLike) -> NDArray[np.bool_]:
        """Whether each of ``points`` (x, y, z) has ``count`` (per point, or one for all) support."""
        return self._confirmed(points, count)[0]

    def _confirmed(self, points: ArrayLike, count: ArrayLike, *, steep: bool = False
                   ) -> tuple[NDArray[np.bool_], tuple[FloatArray, NDArray[np.intp]] | None]:
        """:meth:`confirmed`; with ``steep``, also each point's neighbours as
        :meth:`seen_from_above` queries them (its ``k``), when one query can serve both (no
        more than that ``k`` needed: asking for more neighbours than the needed-th changes
        no count), else ``None``."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        count = np.broadcast_to(np.asarray(count, dtype=np.float64), (points.shape[0],))
        # The count grows as the square root of the returns (support_count): the
        # subsample needs the count of a position of count / step returns.
        needed = np.ceil(count / math.sqrt(self.step)).astype(np.int64)
        if points.shape[0] == 0 or (needed <= 1).all() or self.tree.n == 0:
            return needed <= 1, None
        # The needed-th nearest within reach, not a count of all: dense surfaces hold hundreds.
        # Shared only while the wider answer stays small: at 10M features the candidates'
        # 16 neighbours each took 1.8 GB (peak 1.3 -> 3.1 GB).
        share = steep and int(needed.max()) <= STEEP_CANDIDATES and points.shape[0] <= SHARED_QUERY_POINTS
        k = int(min(STEEP_CANDIDATES if share else needed.max(), self.tree.n))
        if share:
            distance, index = self._query(points, k)
            within = np.isfinite(distance).sum(axis=1)
            return within >= needed, (distance, index)
        # Only the counts are kept: a block at a time bounds the (n, k) answers (10M
        # features asked 1.1M points for 21 neighbours at once: 370 MB).
        within = np.empty(points.shape[0], dtype=np.intp)
        for first in range(0, points.shape[0], SUPPORT_QUERY_BLOCK):
            block = slice(first, first + SUPPORT_QUERY_BLOCK)
            distance, _ = self._query(points[block], k)
            within[block] = np.isfinite(distance).sum(axis=1)
        return within >= needed, None

    def _query(self, points: FloatArray, k: int) -> tuple[FloatArray, NDArray[np.intp]]:
        """Each of ``points``' ``k`` nearest support points within reach: the ``(n, k)``
        distances (``inf`` beyond reach) and indices, a row per point in the points' order.

        The index asks them in the order of its cells itself (:mod:`occtool.neighbours`),
        and each point's answer is its own whatever the order. (The rows were once copied
        back from an order of strips of pan angle that served cKDTree's walk of its tree:
        with the points' own order that copy was two fresh (n, k) arrays a fit.)
        """
        return self.tree.query(self._embedded(points), k=k, distance_upper_bound=1.0)

    def steep_neighbours(self, points: ArrayLike) -> tuple[FloatArray, NDArray[np.intp]]:
        """The query :meth:`seen_from_above` makes of ``points`` (a nonempty support):
        their :data:`STEEP_CANDIDATES` nearest support points within reach, ``(n, k)``
        distances (``inf`` beyond reach) and indices."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return self._query(points, int(min(STEEP_CANDIDATES, self.tree.n)))

    def seen_from_above(self, points: ArrayLike,
                        neighbours: tuple[FloatArray, NDArray[np.intp]] | None = None) -> NDArray[np.bool_]:
        """Whether each of ``points`` may lie on a surface seen from above (a table or
        crate top, a beam), whose first return can lie a ray spacing or two behind its
        front edge.

        A return on a wall or a leg has returns of its own surface straight above or
        below it: at least :data:`STEEP_NEIGHBOURS` of its neighbours (within the support's
        reach) lie a ray row or more higher or lower, at a horizontal distance that changes
        by at most :data:`STEEP_SLOPE` of the height. Its first return is then its front.
        Any other return, or one with too few neighbours to tell, counts as seen from
        above: the safe side. ``neighbours``: the points' query result when
        :meth:`_confirmed` made it already.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if points.shape[0] == 0 or self.tree.n == 0:
            return np.ones(points.shape[0], dtype=bool)
        k = int(min(STEEP_CANDIDATES, self.tree.n))
        distance, index = self.steep_neighbours(points) if neighbours is None else neighbours
        found = np.isfinite(np.asarray(distance).reshape(points.shape[0], k))
        near = np.where(found, np.asarray(index).reshape(points.shape[0], k), 0)
        horizontal = np.hypot(points[:, 0], points[:, 1])
        # The neighbours' heights and horizontal distances, each support point's computed once.
        rise = np.abs(self._heights[near] - points[:, None, 2])
        run = np.abs(self._horizontal[near] - horizontal[:, None])
        row = 0.5 * self.spacing * np.linalg.norm(points, axis=1)
        steep = found & (rise >= row[:, None]) & (run <= STEEP_SLOPE * rise)
        return steep.sum(axis=1) < STEEP_NEIGHBOURS


#: Neighbours searched for returns of the same steep surface (:meth:`Support.seen_from_above`).
STEEP_CANDIDATES = 16
#: Most points whose confirmation query also serves :meth:`Support.seen_from_above`
#: (16 neighbours each: 64 MB of answers at this count).
SHARED_QUERY_POINTS = 250_000
#: Returns above or below on the same steep surface that make a return a wall's or a leg's.
STEEP_NEIGHBOURS = 2
#: Largest change of horizontal distance per metre of height between two returns of one
#: steep surface (a face within about 27 degrees of vertical).
STEEP_SLOPE = 0.5


def supported_returns(points: ArrayLike, support: ArrayLike, count: ArrayLike, spacing: float) -> NDArray[np.bool_]:
    """:meth:`Support.confirmed` of ``points`` among ``support`` in one call."""
    return Support(support, spacing).confirmed(points, count)


#: A guarded return of 3D data on a surface seen from above (a crate's top, a pallet) stands
#: this many ray spacings nearer than measured (see :func:`ray_spacing`): such a surface is
#: first hit up to a ray spacing behind its front edge.
SPACING_FACTOR = 2.0
#: A guarded return of 3D data also holds the guard's bins within this many ray spacings
#: of its pan angle (:func:`build_guard`'s ``reach``).
SPREAD_SHARE = 0.5
#: Features whose nearest neighbours measure the ray spacing, at most (an even subsample).
SPACING_SAMPLE = 2000


def ray_spacing(points: ArrayLike) -> float:
    """Typical angle (radians) between neighbouring rays: twice the median angle from a
    ray to its nearest neighbour (an even subsample of at most :data:`SPACING_SAMPLE`
    rays, scaled back to the full count)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = points.shape[0]
    if n < 2:
        return 0.0
    step = max(1, n // SPACING_SAMPLE)
    sample = points[::step]
    directions = sample / np.linalg.norm(sample, axis=1, keepdims=True)
    distance = nearest_other_distance(directions)
    # Chord to angle; a subsample's spacing is sqrt(step) times the full set's.
    angle = 2.0 * np.arcsin(np.clip(distance / 2.0, 0.0, 1.0))
    return float(2.0 * median(angle) / math.sqrt(step))


def build_guard(alpha: ArrayLike, distance: ArrayLike, level: float, bins: int = GUARD_BINS, *,
                reach: float = 0.0) -> ReturnGuard:
    """The guard of returns at pan angles ``alpha`` and horizontal distances ``distance``.

    Each return holds its own bin and every bin within ``reach`` radians of its pan angle:
    between two rays of sparse 3D data lies surface no ray saw, and a return stands for
    its share of it (half a ray spacing either side).
    """
    alpha = np.asarray(alpha, dtype=np.float64)
    distance = np.asarray(distance, dtype=np.float64)
    nearest = np.full(bins, np.inf)
    width = 2.0 * math.pi / bins
    position = (alpha + math.pi) / width
    index = np.floor(position).astype(np.int64)
    np.minimum.at(nearest, np.mod(index, bins), distance)
    span = reach / width
    for offset in range(1, int(math.ceil(span)) + 1):  # a loop over a few bins; points are vectorised
        # The bin `offset` places on is held when it starts within `reach` of the return.
        ahead = (index + offset) - position <= span
        behind = position - (index - offset + 1) <= span
        np.minimum.at(nearest, np.mod(index[ahead] + offset, bins), distance[ahead])
        np.minimum.at(nearest, np.mod(index[behind] - offset, bins), distance[behind])
    # Down to whole millimetres (a hair below, so x / 1000 read back is never farther than
    # the return): the guard in memory is the guard a model file gives back.
    finite = np.isfinite(nearest)
    millimetres = np.maximum(np.floor(nearest[finite] / GUARD_RESOLUTION - 1e-6), 1.0)
    nearest[finite] = millimetres / 1000.0
    return ReturnGuard(nearest, float(level))


__all__ = [
    "GUARD_BINS", "ReturnGuard", "Support", "build_guard", "guard_candidates", "is_planar_scan", "ray_spacing",
    "support_count", "supported_returns",
]
