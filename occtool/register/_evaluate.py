"""Registration measured: odometry-like poses from true ones, and the errors of an estimate."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from occtool.features import Pose
from occtool.register._core import FloatArray, compose, relative


# ---------------------------------------------------------------------- tests and benchmarks
def degrade_poses(poses: Sequence[Pose], *, distance_share: float = 0.03, turn_per_metre: float = math.radians(1.5),
                  seed: int = 0) -> list[Pose]:
    """Odometry-like poses from true ones: each step's motion with a scale error and a
    heading error that grow with the distance driven.

    Per step of length ``d`` (metres) and turn ``dtheta``: the translation is scaled by
    ``1 + distance_share`` (a systematic wheel-radius error) plus noise of standard
    deviation ``distance_share * d`` on each axis; the heading gains a bias of
    ``turn_per_metre * d`` (a drift to one side) plus noise of ``turn_per_metre * d`` and
    1 % of ``dtheta``. The first pose is kept.
    """
    rng = np.random.default_rng(seed)
    out = [poses[0]]
    for k in range(1, len(poses)):
        step = relative(poses[k - 1], poses[k])
        d = math.hypot(step.x, step.y)
        noise = rng.normal(size=3)
        dx = step.x * (1.0 + distance_share) + distance_share * d * noise[0]
        dy = step.y * (1.0 + distance_share) + distance_share * d * noise[1]
        dyaw = step.yaw + turn_per_metre * d * (1.0 + noise[2]) + 0.01 * step.yaw * rng.normal()
        out.append(compose(out[-1], Pose(dx, dy, step.z, dyaw)))
    return out


def trajectory_error(estimate: Sequence[Pose], truth: Sequence[Pose], *, align: bool = True) -> float:
    """RMS of the position error (metres), after the rigid 2D motion that fits the
    estimate to the truth best (``align=True``, as the absolute trajectory error is
    usually given) or as it is."""
    e = np.array([[p.x, p.y] for p in estimate])
    t = np.array([[p.x, p.y] for p in truth])
    if align:
        e = _aligned(e, t)
    return float(np.sqrt(np.mean(np.sum((e - t) ** 2, axis=1))))


def _aligned(e: FloatArray, t: FloatArray) -> FloatArray:
    ce, ct = e.mean(axis=0), t.mean(axis=0)
    u, _, vt = np.linalg.svd((e - ce).T @ (t - ct))
    d = np.sign(np.linalg.det(u @ vt))
    rotation = (u @ np.diag([1.0, d]) @ vt).T
    return (e - ce) @ rotation.T + ct


def segment_errors(estimate: Sequence[Pose], truth: Sequence[Pose], length: float = 10.0) -> FloatArray:
    """The translation error (metres) of the relative motion over every stretch of
    ``length`` metres of travel (by the truth), one per starting scan."""
    t = np.array([[p.x, p.y] for p in truth])
    travel = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(t, axis=0).T))])
    errors = []
    for i in range(len(truth)):
        j = int(np.searchsorted(travel, travel[i] + length))
        if j >= len(truth):
            break
        true_step, step = relative(truth[i], truth[j]), relative(estimate[i], estimate[j])
        errors.append(math.hypot(true_step.x - step.x, true_step.y - step.y))
    return np.array(errors)
