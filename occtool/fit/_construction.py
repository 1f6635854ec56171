"""Building the tree: the centre pieces placed by linear programmes, the side pieces.

One :class:`_Fitter` per fit. The near runs of the first-obstacle profile are cut into
segments, one group of pieces each (``F = MAX over groups (MIN over the group's pieces)``).
Each centre piece's level crossing is placed by a small linear programme as far out as the
segment's first obstacles allow, at every height of the body band; its slope in ``r``
comes from a robust fit to the samples. Two side pieces rise steeply (within ``a_max``)
outside the segment and so switch the group off there. The loss, the constraints every
candidate piece is projected onto and the optional refit sweeps that follow are
:class:`~occtool.fit._refit._Refitter`'s, which this class extends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from occtool._stats import median
from occtool.fit._profile import (
    adaptive_support,
    angle_bins,
    first_obstacle_distance,
    group_by_bin,
    profile_bins,
    segment_cost,
    segment_near_runs,
)
from occtool.fit._refit import FitSettings, FloatArray, ProgressCallback, _Refitter
from occtool.linear_program_batch import Steps, solve_lps, solved
from occtool.robot import Robot
from occtool.sensor import SAMPLE_KINDS, Samples
from occtool.tree import MinMaxTree

#: Share of ``focus_range`` beyond which pushing a crossing farther out gains nothing: with
#: the default 2.5 m, 2.25 m, the default 1.5 m max range of the navigation map plus
#: room for the shrink by the robot radius. A share, not a distance, so that the fit
#: scales with the scene (``focus_range``) as the paper's model does.
NAVIGATION_REACH_SHARE = 0.9
#: Where obstacles allow, centre crossings stay this far (m) outside the robot's radius.
BODY_CLEARANCE = 0.1
#: A centre's crossing stays above this share of the segment's nearest crossing.
FLAT_SHARE = 0.97
#: Heights of the body band at which a centre's crossing is kept in front of obstacles.
PROFILE_HEIGHTS = 9
#: Samples of a segment the slope of its crossing is estimated from, at most.
SLOPE_SAMPLES = 8192


@dataclass
class _Segments:
    """What turns the segments' centre programmes' optima into pieces (a row or an entry
    a segment)."""

    lower: FloatArray
    upper: FloatArray
    #: Pan angle of the segment's middle (the programmes' local angle terms are about it).
    middle: FloatArray
    #: The centres' slope in r (:meth:`_Fitter.crossing_slopes`).
    c: FloatArray
    #: The nearest crossing of the segment's obstacles (where every floor is infeasible).
    nearest: FloatArray


@dataclass
class _CentreProgrammes:
    """Every centre's programmes, stacked (:func:`~occtool.linear_program_batch.solve_stacked`).

    Centre ``i`` (of segment ``segment_of[i]``) minimises ``objective[i] @ q`` (its gains,
    negated) under its segment's rows (``r* <= bound``), with the flat or the body floor on
    its emphasised rows (``-r* <= flat[...]``, ``body[...]`` alike: both hold the floors
    negated), or none. Its rows are the ``own_count[i]`` entries of ``own`` (indices into
    ``rows``, with their ``bound``) after the earlier centres', its emphasised rows the
    ``chosen_count[i]`` entries of ``chosen`` alike.
    """

    segments: _Segments
    segment_of: NDArray[np.intp]
    objective: FloatArray
    rows: FloatArray
    own: NDArray[np.intp]
    own_count: NDArray[np.intp]
    bound: FloatArray
    chosen: NDArray[np.intp]
    chosen_count: NDArray[np.intp]
    flat: FloatArray
    body: FloatArray

    def unfloored(self, i: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """Centre ``i``'s programme without a floor: ``cost, A_ub, b_ub, lower, upper``."""
        end = int(self.own_count[: i + 1].sum())
        own = slice(end - int(self.own_count[i]), end)
        g = int(self.segment_of[i])
        return (self.objective[i], self.rows[self.own[own]], self.bound[own], self.segments.lower[g],
                self.segments.upper[g])

    def floored(self) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.intp], FloatArray, FloatArray]:
        """Each centre's programme with the flat floor, then with the body floor, stacked:
        ``cost, A_ub, b_ub, rows, lower, upper``.

        Programme ``2 i + f`` is centre ``i``'s own rows, then its chosen rows negated
        (floor ``f``); formed for all of them at once by where each block starts."""
        own_count, chosen_count = self.own_count, self.chosen_count
        n_own, n_chosen = self.own.size, self.chosen.size
        # The rows and bounds every block reads from: the own rows, then the chosen rows
        # negated (-r* <= -floor), with their bounds and their two floors.
        pool_rows = np.concatenate([self.rows[self.own], -self.rows[self.chosen]])
        pool_values = np.concatenate([self.bound, self.flat[self.chosen], self.body[self.chosen]])
        # Blocks, in order: own, chosen (flat), own, chosen (body) of each centre, and where
        # each starts in the pools.
        sizes = np.column_stack([own_count, chosen_count, own_count, chosen_count]).ravel()
        own_from = np.cumsum(own_count) - own_count
        chosen_from = n_own + np.cumsum(chosen_count) - chosen_count
        sources = np.column_stack([own_from, chosen_from, own_from, chosen_from]).ravel()
        entry = np.arange(int(sizes.sum())) + np.repeat(sources - (np.cumsum(sizes) - sizes), sizes)
        A = pool_rows[entry]
        # The body floor's bounds lie after the flat floor's.
        values = pool_values[entry + np.repeat(np.tile([0, 0, 0, n_chosen], own_count.size), sizes)]
        counts = np.repeat(own_count + chosen_count, 2)
        lower = self.segments.lower[self.segment_of]
        upper = self.segments.upper[self.segment_of]
        return (np.repeat(self.objective, 2, axis=0), A, values, counts,
                np.repeat(lower, 2, axis=0), np.repeat(upper, 2, axis=0))


class _Fitter(_Refitter):
    """One fit: the refit's samples and constraints, the robot and the profile's returns."""

    def __init__(self, params: FitSettings, samples: Samples, robot: Robot,
                 returns: tuple[FloatArray, FloatArray], *, pieces: int,
                 floor_is_obstacle: bool = False, depth_error: float = 0.0,
                 progress: ProgressCallback | None = None) -> None:
        super().__init__(params, samples, progress=progress)
        #: The pieces to place (the estimator's ``pieces``, or the count's default).
        self.n_pieces = pieces
        #: Pan angle (turned) and horizontal distance of the obstacle returns in the body band.
        self.returns = returns
        self.depth_error = depth_error
        self.floor_is_obstacle = floor_is_obstacle
        self.robot = robot
        self.on_rays = self.hit | (samples.kind == SAMPLE_KINDS["near"])
        # Hit and near samples grouped by profile bin, and the bins' bounds (built on first use).
        self._ray_groups: tuple[NDArray[np.intp], NDArray[np.intp]] | None = None

    @cached_property
    def profile_heights(self) -> FloatArray:
        """The :data:`PROFILE_HEIGHTS` heights, from the floor up, at which a centre's
        crossing is kept in front of the obstacles (the map's lowest cut may lie a little
        under the clearance)."""
        low, high = self.robot.floor_h, self.robot.body_band[1]
        return np.linspace(low, max(high, 0.0), PROFILE_HEIGHTS)

    def turned_tree(self, tree: MinMaxTree, origin: float) -> MinMaxTree:
        """The tree fitted in pan angles measured from ``origin``, in the robot's angles.

        ``cos(alpha - o)`` and ``sin(alpha - o)`` are a rotation of ``cos(alpha)``,
        ``sin(alpha)``, so the pan weights turn by ``o`` and keep their length.
        """
        W = tree.coefficients.copy()
        co, so = math.cos(origin), math.sin(origin)
        a1, a2 = W[:, 0].copy(), W[:, 1].copy()
        W[:, 0] = a1 * co - a2 * so
        W[:, 1] = a1 * so + a2 * co
        W = self.project_rows(W)
        return MinMaxTree(tree.basis, W, tree.root)

    # ---------------------------------------------------------------- initial tree
    def range_profile(self, n_bins: int) -> FloatArray:
        """Horizontal distance of the first obstacle per pan-angle bin, outliers ignored."""
        s = self.samples
        support, _ = adaptive_support(s.count("robot"))
        # From the returns themselves (the surface is where they are, not their hit samples
        # at r (1 -+ depth error)), a feature for every two hit samples of the support. The
        # front is the cluster's last return of that support, not its nearest: the nearest
        # of many noisy returns lies farther in front of the surface the more there are
        # (about 2.5 sigma of range noise at 80 returns a bin, 2 at 30; the map lost
        # 0.02-0.04 IoU from 10k to 30k features), but no more than the depth error beyond
        # the cluster's return half way there, so a table top seen from above keeps its
        # front edge (first_obstacle_distance).
        alpha, distance = self.returns
        keep = support // 2
        profile = first_obstacle_distance(alpha, distance, n_bins, keep, front=keep - 1, cap=1.0 + self.depth_error)
        frontier = np.flatnonzero(s.kind == SAMPLE_KINDS["frontier"])  # a few hundred of millions
        if frontier.size:
            reach = np.sqrt(np.maximum(s.r.take(frontier) ** 2 - s.h.take(frontier) ** 2, 0.0))
            np.minimum.at(profile, angle_bins(s.alpha.take(frontier), n_bins), reach)
        cap = self.p.focus_range if self.p.focus else (distance.max() if distance.size else 1.0)
        return np.minimum(profile, cap)

    def initial_groups(self, n_groups: int, range_profile: FloatArray) -> list[tuple[int, int]]:
        """Segments ``(first_bin, end_bin)`` of the profile's bins (end exclusive, may exceed
        the bin count: wraps).

        Bins whose first obstacle lies beyond the navigation reach need no group (where
        no group is on, the neighbours' sides recede and the space reads free), so only
        the near runs are cut into at most ``n_groups`` segments.
        """
        n_bins = range_profile.shape[0]
        if n_groups == 1:
            return [(0, n_bins)]
        reach = NAVIGATION_REACH_SHARE * self.p.focus_range
        profile = np.minimum(range_profile, reach)
        far = profile >= reach
        if far.all():
            return [(0, n_bins)]
        shift = 0
        if self.basis == "trig":
            if far.any():
                # Start where a far run starts, so no segment wraps around the cut.
                starts = np.flatnonzero(far & ~np.roll(far, 1))
                shift = int(starts[0]) if starts.size else int(np.flatnonzero(far)[0])
            else:
                # Start the linear DP where the profile jumps most: a natural segment edge.
                shift = int(np.argmax(np.abs(profile - np.roll(profile, 1))))
        rolled = np.roll(profile, -shift)
        # A group's sides can only switch it off outside a segment narrower than pi.
        max_length = min(n_bins // 2 - 1, 2 * int(math.ceil(n_bins / n_groups)))
        segments = segment_near_runs(rolled, np.roll(far, -shift), n_groups, max_length)
        return [(a + shift, b + shift) for a, b in segments]

    def run(self) -> tuple[MinMaxTree, list[float]]:
        """The fitted tree and the loss after each sweep."""
        return solved(self.run_steps())

    def run_steps(self) -> Steps:
        """:meth:`run` as steps: it yields the centres' programmes stacked and is sent their
        results (:func:`occtool.linear_program_batch.solved_together` solves those of several
        fits at once), and returns what :meth:`run` does."""
        p = self.p
        L = self.n_pieces
        # Four pieces a group by default: two centres (low and high part of the body band)
        # and two sides.
        n_groups = int(p.groups) if p.groups is not None else max(1, L // 4)
        if n_groups > 1 and L < 3 * n_groups:
            n_groups = max(1, L // 3)
        n_bins = profile_bins(self.samples.count("robot"))
        profile = self.range_profile(n_bins)
        segments = self.initial_groups(n_groups, profile)
        width = 2.0 * np.pi / n_bins

        pieces: list[FloatArray] = []
        members: list[list[int]] = []
        extra = L - (3 * len(segments) if len(segments) > 1 else 1)
        # Extra centres go to the segments whose profile a single line fits worst, in turn:
        # as many rounds over all of them as there are, the rest by that order (which is
        # only needed then: the default 64 pieces in 16 segments give every one a second).
        rounds, rest = divmod(max(extra, 0), len(segments))
        centres_per_group = [1 + rounds] * len(segments)
        if rest:
            seg_cost = [segment_cost(profile, first, end) for first, end in segments]
            order = np.argsort(-np.asarray(seg_cost), kind="stable")
            for i in range(rest):
                centres_per_group[int(order[i])] += 1

        programmes = self.centre_programmes(profile, segments, centres_per_group)
        centres = yield from self.place_centres_steps(programmes)
        # Each segment's centres (in programme order: segment by segment), then its two sides.
        segment_of = np.asarray(programmes.segment_of, dtype=np.intp)
        first_centre = np.searchsorted(segment_of, np.arange(len(segments)))
        if len(segments) > 1:
            # Side pieces start at the segment's edges and switch the group off beyond
            # them; where neighbouring groups overlap, the MAX keeps the nearer obstacle.
            bases = centres[first_centre]
            start_angles = [first * width - np.pi for first, _ in segments]
            end_angles = [end * width - np.pi for _, end in segments]
            sides = self.side_pieces(np.concatenate([bases, bases]), start_angles + end_angles,
                                     [+1] * len(segments) + [-1] * len(segments))
        for g, count in enumerate(centres_per_group):
            group: list[int] = []
            for i in range(int(first_centre[g]), int(first_centre[g]) + count):
                group.append(len(pieces))
                pieces.append(centres[i])
            if len(segments) > 1:
                for side in (sides[g], sides[len(segments) + g]):
                    group.append(len(pieces))
                    pieces.append(side)
            members.append(group)
            if self.progress is not None:
                self.progress(g + 1, len(segments) + int(p.max_sweeps))
        W = np.array(pieces)
        self.progress_offset = len(segments)
        return self.alternate(W, members)

    def centre_programmes(self, profile: FloatArray, segments: list[tuple[int, int]],
                          counts: list[int]) -> _CentreProgrammes:
        """The programmes of each segment's centre pieces (``counts[g]`` for segment ``g``),
        whose level crossing lies just in front of the segment's first obstacles
        (:meth:`place_centres` solves them).

        In range terms a piece crosses ``level`` at ``r* = p0 + p_angle . angle_terms + p_h h``.
        A linear programme pushes ``r*`` as far out as it may go while staying at or below
        ``sqrt(D(alpha)^2 + h^2)`` (the first obstacle at horizontal distance ``D``) at the
        edges of every bin of the segment, its overlap and every height of the body band.
        The slope ``c`` through the crossing comes from a robust least-squares fit to the
        segment's samples, so the sensor model decides how sharp the crossing is.

        Every segment's bin edges are formed at once (``seg`` says whose): the same values,
        element by element, as one segment at a time (16 segments' small arrays took a
        fifth of a planar laser's fit).
        """
        n_bins = profile.shape[0]
        width = 2.0 * np.pi / n_bins
        first = np.array([a for a, _ in segments], dtype=np.intp)
        end = np.array([b for _, b in segments], dtype=np.intp)
        n = end - first
        # The crossing must stay in front of the obstacles over the segment's own bins only:
        # where a group reaches past its segment, the MAX over groups keeps the nearer one.
        seg = np.repeat(np.arange(n.size), n)
        bins = first[seg] + np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n)
        D_bins = profile[np.mod(bins, n_bins)]
        # Between two bins the obstacle may be as near as in either of them.
        left = np.where(bins > first[seg], np.minimum(D_bins, profile[np.mod(bins - 1, n_bins)]), D_bins)
        right = np.where(bins < end[seg] - 1, np.minimum(D_bins, profile[np.mod(bins + 1, n_bins)]), D_bins)
        # The right edge of one bin is the left edge of the next, with the same bound:
        # keep each edge once (the nearer bound), halving the programmes' rows.
        eseg = np.repeat(np.arange(n.size), n + 1)
        e = np.arange(eseg.size) - np.repeat(np.cumsum(n + 1) - (n + 1), n + 1)
        D_edges = np.full(eseg.size, np.inf)
        D_edges[e < n[eseg]] = left
        D_edges[e > 0] = np.minimum(D_edges[e > 0], right)
        edges = (first[eseg] + e) * width - np.pi
        if self.k_angle == 1:
            # The paper's basis is discontinuous at +-pi: keep the overlap on this side.
            keep = (edges >= -np.pi) & (edges <= np.pi)
            edges, D_edges, eseg = edges[keep], D_edges[keep], eseg[keep]
        n_edges = np.bincount(eseg, minlength=n.size)
        estart = np.cumsum(n_edges) - n_edges
        # From the floor up: the map's lowest cut may lie a little under the clearance.
        heights = self.profile_heights
        # Rows edge by edge, PROFILE_HEIGHTS heights each.
        target = np.sqrt((D_edges**2)[:, None] + (heights**2)[None, :]).ravel()
        reach = np.minimum(D_edges, NAVIGATION_REACH_SHARE * self.p.focus_range)
        cap = np.sqrt((reach**2)[:, None] + (heights**2)[None, :]).ravel()
        body = np.sqrt((self.robot.radius + BODY_CLEARANCE) ** 2 + heights**2)
        keep_off = np.minimum(body[None, :], (target - 1e-6).reshape(-1, PROFILE_HEIGHTS)).ravel()
        nearest = np.sqrt(np.minimum.reduceat(D_edges, estart)[:, None] ** 2 + heights**2)
        floor_flat = np.minimum((FLAT_SHARE * nearest)[eseg], (target - 1e-6).reshape(-1, PROFILE_HEIGHTS)).ravel()
        # The crossing line in local angle terms about the segment's middle, where they are
        # well conditioned: 1, cos(da) - 1, sin(da), h (linear basis: 1, da, h).
        middle = (first + end) / 2.0 * width - np.pi
        delta = edges - middle[eseg]
        local = [delta] if self.k_angle == 1 else [np.cos(delta) - 1.0, np.sin(delta)]
        rows = np.empty((edges.size * PROFILE_HEIGHTS, 2 + len(local)))
        rows[:, 0] = 1.0
        for column, values in enumerate(local, start=1):
            rows[:, column] = np.repeat(values, PROFILE_HEIGHTS)
        rows[:, -1] = np.tile(heights, edges.size)

        # Each centre's programme: its segment's rows (own) and, of them, those at the
        # heights of its part of the band (chosen), for all centres at once.
        G = len(counts)
        segment_of = np.repeat(np.arange(G), counts)
        n_centres = segment_of.size
        # Several centres split the height band: the crossing sqrt(D^2 + h^2) is convex in h,
        # and the group's crossing (the farthest of its pieces') follows it with one tangent
        # line per part.
        count_of = np.repeat(np.asarray(counts, dtype=np.intp), counts)
        part = np.arange(n_centres) - np.repeat(np.cumsum(counts) - counts, counts)
        low, high = self.robot.floor_h, self.robot.body_band[1]
        part_lo = low + (max(high, 0.0) - low) * part / count_of
        part_hi = low + (max(high, 0.0) - low) * (part + 1) / count_of
        emphasis = (heights >= (part_lo - 1e-9)[:, None]) & (heights <= (part_hi + 1e-9)[:, None])
        own_start = (estart * PROFILE_HEIGHTS)[segment_of]
        own_count = (n_edges * PROFILE_HEIGHTS)[segment_of]
        own_first = np.cumsum(own_count) - own_count
        owner = np.repeat(np.arange(n_centres), own_count)
        own = np.arange(owner.size) - np.repeat(own_first - own_start, own_count)
        # A segment's rows start at a whole edge: row i is at height i % PROFILE_HEIGHTS.
        emphasised = emphasis[owner, own % PROFILE_HEIGHTS]
        chosen = own[emphasised]
        chosen_count = np.bincount(owner[emphasised], minlength=n_centres)

        ray_rows = [self.segment_ray_samples(int(first[g]), int(end[g]), n_bins) for g in range(G)]
        distance = [median(D_bins[seg == g]) for g in range(G)]
        c = self.crossing_slopes(ray_rows, distance)
        # Half the pan-weight budget is left to the side pieces that switch the group off.
        bound_angle = 0.5 * self.p.a_max / c / (math.sqrt(2.0) if self.k_angle == 2 else 1.0)
        bound_h = self.p.b_max / c
        # The offset is free.
        if self.k_angle == 1:
            lower = np.column_stack([np.full(G, -np.inf), -bound_angle, -bound_h])
            upper = np.column_stack([np.full(G, np.inf), bound_angle, bound_h])
        else:
            # The crossing may only curve away from the robot off the middle (cos - 1 <= 0 with a
            # weight <= 0): far from its segment a group then recedes, and its sides can
            # switch it off.
            lower = np.column_stack([np.full(G, -np.inf), -bound_angle, -bound_angle, -bound_h])
            upper = np.column_stack([np.full(G, np.inf), np.zeros(G), bound_angle, bound_h])
        segments_out = _Segments(lower, upper, middle, c, np.minimum.reduceat(target, estart * PROFILE_HEIGHTS))
        # Maximise the emphasised crossings, but only up to the range the map looks at
        # (t_i <= min(r*_i, cap_i)): pushing out far walls must not tilt the line into a
        # near obstacle. Relative gains: a centimetre near the robot counts more. (Maximising
        # the linearised horizontal distance per bin edge instead measured 0.01-0.02 worse.)
        # A programme in the line's own k unknowns: the crossings are capped at the
        # range the map looks at (r*_i <= cap_i) as constraints. (An auxiliary variable
        # per row, t_i <= min(r*_i, cap_i), gave the same maps on 4 scenes x 3 seeds at
        # 2k and 10k features, and took twice as long: 19 programmes of ~400 variables were most of the fit's time.)
        gains = rows[chosen] / cap[chosen, None] ** 2
        # One sum a centre, row after row as sum(axis=0) adds them (np.add.reduceat rounds
        # differently): each centre's gains padded with zeros after its own rows, summed
        # along the rows (x + 0.0 is x, and a sum from 0 is never -0.0).
        at = np.arange(chosen.size) - np.repeat(np.cumsum(chosen_count) - chosen_count, chosen_count)
        padded = np.zeros((n_centres, int(chosen_count.max(initial=0)), rows.shape[1]))
        padded[owner[emphasised], at] = gains
        objective = -padded.sum(axis=1)
        # r*_i <= target_i everywhere and r*_i <= cap_i on the emphasised rows: one row
        # each, bounded by the smaller.
        capped = np.minimum(target, cap)
        bound = np.where(emphasised, capped[own], target[own])
        # Keep the crossing off the robot's body wherever the obstacle allows: at the
        # floor, a crossing a few centimetres too near in r is a body in collision.
        # Only this centre's part of the band: the group's crossing is the farthest of its
        # centres', so each needs to keep off the body where it is the one that counts.
        # Nor may it dip below (nearly) the segment's nearest obstacle at that height, which
        # a flat crossing would keep: a tilt that gains far away must not cost near by.
        # Each floor is dropped again if it makes the programme infeasible
        # (place_centres), the flat one first.
        flat = -np.minimum(np.maximum(keep_off, floor_flat), cap)
        body = -np.minimum(keep_off, cap)
        return _CentreProgrammes(segments_out, segment_of, objective, rows, own, own_count, bound, chosen,
                                 chosen_count, flat, body)

    def place_centres(self, programmes: _CentreProgrammes) -> FloatArray:
        """Every centre piece, one row each in the programmes' order: the optima of their
        programmes (:meth:`centre_programmes`).

        A centre's programme is tried with the flat floor, then the body floor, then none,
        each only if the one before is infeasible. The programmes are independent, so they
        are solved in a batch (:mod:`occtool.linear_program_batch`: ``solve_lp``'s answers,
        a fraction of its time), the flat and the body floors of every centre at once (the
        body floor was needed by about 30 % of the Freiburg campus's centres, and a batch's
        cost is mostly its count of steps, not its width).
        """
        return solved(self.place_centres_steps(programmes))

    def place_centres_steps(self, programmes: _CentreProgrammes) -> Steps:
        """:meth:`place_centres` as steps (:meth:`run_steps`): the floored programmes are
        yielded and their results sent back."""
        results = yield programmes.floored()
        optima: list[FloatArray | None] = []
        for flat, body in zip(results[::2], results[1::2]):
            optima.append(flat.x if flat.status == 0 else body.x if body.status == 0 else None)
        bare = [i for i, q in enumerate(optima) if q is None]
        if bare:
            unfloored = solve_lps([programmes.unfloored(i) for i in bare])
            for i, result in zip(bare, unfloored):
                optima[i] = result.x if result.status == 0 else None
        segments, of = programmes.segments, programmes.segment_of
        return self.centre_pieces(optima, segments.middle[of], segments.c[of], segments.nearest[of])

    def centre_pieces(self, optima: list[FloatArray | None], middle: FloatArray, c: FloatArray,
                      nearest: FloatArray) -> FloatArray:
        """The pieces of centre programmes' optima (a row each; an optimum None: every floor
        infeasible, a flat crossing at ``nearest``), whose segments' middles are ``middle``
        and slopes ``c``.

        All of them at once, each element by the same operations as one piece at a time
        (a few dozen pieces one by one were mostly numpy's per-call overhead)."""
        k = self.k_angle
        Q = np.zeros((len(optima), k + 2))
        for i, q in enumerate(optima):
            if q is None:
                Q[i, 0] = nearest[i]
            else:
                Q[i] = q
        # Back to the global basis: the crossing r* = p0 + p_angle . angle terms + p_h h.
        if k == 1:
            p_angle = Q[:, 1:2]
            p0 = Q[:, 0] - Q[:, 1] * middle
        else:
            # (math's cosine and sine, as for one piece: numpy's may differ in the last bit.)
            cm = np.array([math.cos(m) for m in middle.tolist()])
            sm = np.array([math.sin(m) for m in middle.tolist()])
            p_angle = np.column_stack([Q[:, 1] * cm - Q[:, 2] * sm, Q[:, 1] * sm + Q[:, 2] * cm])
            p0 = Q[:, 0] - Q[:, 1]
        # F = level + c (r - r*): angle and height weights -c p, offset level - c p0.
        pieces = np.empty((len(optima), self.n_terms))
        pieces[:, :k] = -c[:, None] * p_angle
        pieces[:, k] = -c * Q[:, -1]
        pieces[:, k + 1] = c
        pieces[:, -1] = self.p.level - c * p0
        return self.project_rows(pieces)

    def segment_ray_samples(self, first: int, end: int, n_bins: int) -> NDArray[np.intp]:
        """Indices of the hit and near samples in bins ``first`` to ``end`` - 1 (wrapping).

        Only the samples on rays near their feature say how sharp a crossing is; the robot
        and footprint samples would pull ``c`` down to ``level / distance``. The samples
        are grouped by bin once per fit, so each segment takes slices instead of a pass
        over every sample (8 passes over 2M samples were 0.2 s at 1M features).
        """
        if self._ray_groups is None or self._ray_groups[1].size != n_bins + 1:
            rays = np.flatnonzero(self.on_rays)
            order, bounds = group_by_bin(angle_bins(self.samples.alpha[rays], n_bins), n_bins)
            self._ray_groups = (rays[order], bounds)
        grouped, bounds = self._ray_groups
        start, length = first % n_bins, end - first
        if start + length <= n_bins:
            return grouped[bounds[start]:bounds[start + length]]
        return np.concatenate([grouped[bounds[start]:], grouped[:bounds[start + length - n_bins]]])

    def crossing_slopes(self, segment_rows: list[NDArray[np.intp]], distances: list[float]) -> FloatArray:
        """Robust estimates of ``c`` in ``F = level + c (r - r*)``, one a segment, from its
        samples ``segment_rows[g]`` and its obstacles' distance ``distances[g]`` (an even
        subsample of at most :data:`SLOPE_SAMPLES` samples a segment: one number needs no
        more, and at a million features the full segments took 1.3 s of a 6 s fit).

        Reweighted least squares, four steps: each segment's two sums by its own dot
        products (their rounding is np.dot's), the samples' residuals and weights for all
        segments at once (element by element as one segment at a time)."""
        rows_of = [rows[:: max(1, -(-rows.size // SLOPE_SAMPLES))] for rows in segment_rows]
        sizes = [rows.size for rows in rows_of]
        rows = np.concatenate(rows_of)
        s = self.samples
        r_star = np.sqrt(np.repeat([d**2 for d in distances], sizes) + s.h[rows] ** 2)
        x = s.r[rows] - r_star
        y = s.m[rows] - self.p.level
        w = base = self.w[rows]
        hit = self.hit[rows]
        xx, xy = x * x, x * y
        ends = np.cumsum(sizes).tolist()
        parts = [slice(end - size, end) for size, end in zip(sizes, ends)]
        c = [1.0] * len(parts)
        running = list(range(len(parts)))
        for _ in range(4):
            still = []
            for g in running:
                part = parts[g]
                denominator = float(np.dot(w[part], xx[part]))
                if denominator <= 0:
                    continue
                c[g] = float(np.dot(w[part], xy[part])) / denominator
                still.append(g)
            running = still
            if not running:
                break
            w = self.irls_weights(np.repeat(c, sizes) * x - y, base, hit)
        return np.clip(np.maximum(c, self.p.c_floor), self.p.c_min, self.p.c_max)

    def side_pieces(self, centres: FloatArray, angles: list[float], directions: list[int]) -> FloatArray:
        """Pieces that let each centre's group recede steeply in range beyond its angle
        (a row each: centre ``centres[i]``, angle ``angles[i]``, direction ``directions[i]``).

        A side crosses ``level`` where its centre does at the angle, with the least slope
        in ``r`` (``c_min``) and the full pan weight left within ``a_max``: its crossing then
        moves away from the robot at ``(a_max - |a_centre|) / c_min`` metres per radian
        outside the segment, and inside it stays nearer than the centre's crossing, so the
        group (a MIN: its crossing is the farthest of its pieces') keeps the centre's there.
        Direction +1: the side rises for pan angles above the angle (segment start);
        -1: below it (segment end).

        All of them at once, each element by the same operations as one piece at a time.
        """
        k = self.k_angle
        scale = np.minimum(1.0, self.p.c_min / centres[:, k + 1])
        level = self.p.level
        pieces = centres * scale[:, None]
        pieces[:, -1] = centres[:, -1] * scale + level * (1.0 - scale)
        A = self.p.a_max
        direction = np.array(directions, dtype=np.float64)
        angle = np.array(angles, dtype=np.float64)
        if k == 1:
            a = pieces[:, 0]
            gain = np.where(direction > 0, A - a, A + a)
            pieces[:, 0] = a + direction * gain
            pieces[:, -1] -= direction * gain * angle
        else:
            # direction * sin(alpha - angle) = direction * (cos(angle) sin(alpha) - sin(angle) cos(alpha))
            u = direction[:, None] * np.array([[-math.sin(t), math.cos(t)] for t in angles])
            v = pieces[:, :2]
            # (Two-term dot products as numpy's v @ u rounds them: each product, then their sum.)
            vu = v[:, 0] * u[:, 0] + v[:, 1] * u[:, 1]
            vv = v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1]
            gain = -vu + np.sqrt(np.maximum(vu * vu - vv + A * A, 0.0))
            pieces[:, :2] = v + gain[:, None] * u
        return self.project_rows(pieces)
