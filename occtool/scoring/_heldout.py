"""Held-out data: which scans or features are held out, and the test points drawn from them.

Two protocols, each generated here once:

* **Scans of a log** (Ramos and Ott's protocol for Hilbert maps, used by the log scorer and,
  on an inner split of the training scans, by the grid tuner): :func:`holdout_blocks` picks
  whole blocks of consecutive scans; :func:`beam_test_points` makes each held-out return's
  end point occupied and points drawn uniformly along its beam, up to ``margin`` before its
  end, free. :func:`holdout_test_points` does both for scans with poses in the world frame.
* **Features of one position** (``compare-grid``): :func:`split_holdout` holds out a random
  share of the features; :func:`holdout_points` puts test points at their ends and along
  their rays; :func:`in_front_of_first_obstacle` keeps those a function increasing in range
  can show.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError

if TYPE_CHECKING:
    from occtool.features import Features, Position
    from occtool.robot import Robot

FloatArray = NDArray[np.float64]

#: The share of a log's scans held out, in blocks of this many consecutive scans.
HOLDOUT = 0.1
BLOCK = 40
#: Free test points stop this far before the beam's end (metres), as in the protocol.
END_MARGIN = 0.1
FREE_POINTS_PER_BEAM = 5
#: Fractions of a held-out feature's range where the "free" test points lie (:func:`holdout_points`).
FREE_FRACTIONS = (0.25, 0.5, 0.75)


def holdout_blocks(n_scans: int, holdout: float = HOLDOUT, block: int = BLOCK, seed: int = 0) -> NDArray[np.bool_]:
    """Which of ``n_scans`` consecutive scans are held out: ``round(holdout * n / block)`` (at
    least one) whole blocks of ``block`` scans, picked at random with ``seed``."""
    if not 0.0 < holdout < 1.0:
        raise InputError(f"the held-out share must lie strictly between 0 and 1, got {holdout}")
    if block < 1:
        raise InputError(f"block must be a whole number >= 1, got {block}")
    n_blocks = math.ceil(n_scans / block)
    take = max(1, round(holdout * n_scans / block))
    if n_blocks < 2 or take >= n_blocks:
        raise InputError(f"{n_scans} scans make {n_blocks} block(s) of {block}: too few to hold {holdout:.0%} out")
    chosen = np.random.default_rng(seed).choice(n_blocks, size=take, replace=False)
    held = np.zeros(n_scans, dtype=bool)
    for b in chosen:
        held[b * block:(b + 1) * block] = True
    return held


def beam_test_points(starts: FloatArray, ends: FloatArray, seed: int = 0, per_beam: int = FREE_POINTS_PER_BEAM,
                     margin: float = END_MARGIN) -> tuple[FloatArray, FloatArray]:
    """Occupied and free test points of held-out beams that returned, ``(N, D)`` starts and ends.

    Occupied: each beam's end. Free: ``per_beam`` points drawn uniformly (with ``seed``)
    along each beam, from its start up to ``margin`` before its end; a beam no longer than
    ``margin`` gives none. Planar beams (``D = 2``, the grid tuner's) are measured with
    ``np.hypot``, beams in space (``D = 3``, the log scorer's) with ``np.linalg.norm``, as
    each did before they shared this function: the points, and so the published scores,
    stay the same to the last bit.
    """
    delta = ends - starts
    length = np.hypot(*delta.T) if delta.shape[1] == 2 else np.linalg.norm(delta, axis=1)
    usable = length > margin
    fraction = np.random.default_rng(seed).uniform(0.0, 1.0, size=(int(usable.sum()), per_beam))
    reach = ((length[usable] - margin) / length[usable])[:, None] * fraction
    s, e = starts[usable], ends[usable]
    free = (s[:, None, :] + reach[:, :, None] * (e - s)[:, None, :]).reshape(-1, delta.shape[1])
    return ends, free


def world_rays(scans: list[Position]) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], NDArray[np.intp]]:
    """Start (pose), end (world point), is-a-return and scan number of every beam of scans
    with poses, ``(N, 3)`` each."""
    starts, ends, returns, owner = [], [], [], []
    for k, scan in enumerate(scans):
        pose = scan.pose
        assert pose is not None, "scored scans have poses"  # evaluate_log refuses a log without
        points = scan.features.points @ pose.rotation.T + pose.translation
        starts.append(np.broadcast_to(pose.translation, points.shape))
        ends.append(points)
        returns.append(scan.features.evidence > 0)
        owner.append(np.full(points.shape[0], k, dtype=np.intp))
    return np.concatenate(starts), np.concatenate(ends), np.concatenate(returns), np.concatenate(owner)


def holdout_test_points(scans: list[Position], seed: int = 0, per_beam: int = FREE_POINTS_PER_BEAM,
                        margin: float = END_MARGIN) -> tuple[FloatArray, FloatArray]:
    """Occupied (each return's end point) and free (uniform along each return's beam, up to
    ``margin`` before its end) world points of held-out scans (:func:`beam_test_points`)."""
    starts, ends, returns, _ = world_rays(scans)
    return beam_test_points(starts[returns], ends[returns], seed=seed, per_beam=per_beam, margin=margin)


def split_holdout(n: int, holdout: float, seed: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices of the features used to build the models and of the held-out ones.

    Parameters
    ----------
    n
        Number of features.
    holdout
        Share held out, in [0, 0.5].
    seed
        Seed of the random split.
    """
    if not 0.0 <= holdout <= 0.5:
        raise InputError(f"the held-out share must lie in [0, 0.5], got {holdout}")
    order = np.random.default_rng(seed).permutation(n)
    n_out = int(round(holdout * n))
    if n - n_out < 1:
        raise InputError(f"{n} features leave none to build the models from")
    return np.sort(order[n_out:]), np.sort(order[:n_out])


def holdout_points(features: Features, free_ray: NDArray[np.bool_]) -> tuple[FloatArray, FloatArray]:
    """Test points from held-out features: their end points and points along their rays.

    Free rays (floor features, which every model here reads as free space, and features
    with evidence 0) are left out of the occupied points; their rays still give free
    points.

    Returns
    -------
    occupied, free
        ``(K, 3)`` and ``(M, 3)`` points in the sensor frame.
    """
    points = features.points
    occupied = points[~free_ray]
    free = np.concatenate([points * f for f in FREE_FRACTIONS]) if len(points) else np.zeros((0, 3))
    return occupied, free


def in_front_of_first_obstacle(points: FloatArray, features: Features, robot: Robot, *,
                               occupied: bool) -> NDArray[np.bool_]:
    """Test points that lie in front of the first obstacle at their pan angle, in the body band.

    A function increasing in range cannot show free space behind an obstacle at the same
    pan angle (a ray passing over a low box to the wall beyond): those points are
    unreachable for the parametric model by construction. Per pan-angle bin the first
    obstacle is the nearest cluster of ``features``' returns in the body band (the fit's
    :func:`occtool.fit.first_obstacle_distance`); free points count when nearer than it,
    ``occupied`` points (returns) when no farther than it plus its cluster window.
    """
    from occtool.fit import FOCUS_ANGLE_BINS, FOCUS_WINDOW, FOCUS_WINDOW_ABS, angle_bins, first_obstacles_in_band

    low, high = robot.body_band
    first = first_obstacles_in_band(features, robot, FOCUS_ANGLE_BINS)
    px, py, pz = np.asarray(points, dtype=np.float64).reshape(-1, 3).T
    limit = first[angle_bins(np.arctan2(py, px), FOCUS_ANGLE_BINS)]
    if occupied:
        limit = limit * (1.0 + FOCUS_WINDOW) + FOCUS_WINDOW_ABS
        return (pz >= low) & (pz <= high) & (np.hypot(px, py) <= limit)
    return (pz >= low) & (pz <= high) & (np.hypot(px, py) < limit)


__all__ = ["BLOCK", "END_MARGIN", "FREE_FRACTIONS", "FREE_POINTS_PER_BEAM", "HOLDOUT", "beam_test_points",
           "holdout_blocks", "holdout_points", "holdout_test_points", "in_front_of_first_obstacle", "split_holdout",
           "world_rays"]
