"""The scores: ROC AUC, polygon IoU, the held-out split and its test points."""

from __future__ import annotations

import numpy as np
import shapely
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Features
from occtool.robot import Robot

FloatArray = NDArray[np.float64]

#: Fractions of a held-out feature's range where the "free" test points lie.
FREE_FRACTIONS = (0.25, 0.5, 0.75)


def roc_auc(occupied: FloatArray, free: FloatArray) -> float:
    """Area under the ROC curve of scores for "occupied" against "free" points.

    The Mann-Whitney statistic: the probability that a random occupied point scores above
    a random free one, ties counting half. NaN when either set is empty.
    """
    from scipy.stats import rankdata

    occupied = np.asarray(occupied, dtype=np.float64)
    free = np.asarray(free, dtype=np.float64)
    n_occ, n_free = occupied.size, free.size
    if n_occ == 0 or n_free == 0:
        return float("nan")
    ranks = rankdata(np.concatenate([occupied, free]))
    return float((ranks[:n_occ].sum() - n_occ * (n_occ + 1) / 2.0) / (n_occ * n_free))


def polygon_iou(a: shapely.Geometry, b: shapely.Geometry) -> float:
    """Intersection over union of two areas; 1 when both are empty."""
    area_a, area_b = float(a.area), float(b.area)
    if area_a == 0.0 and area_b == 0.0:
        return 1.0
    overlap = float(shapely.intersection(a, b).area)
    union = area_a + area_b - overlap
    return overlap / union if union > 0 else 0.0


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
