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


#: The odometry noise models :func:`degrade_odometry` knows: ``"wheel"`` is :func:`degrade_poses`
#: (the model registration was tuned on); the others were added (issue 38) to check that it
#: was not tuned to that one alone.
NOISE_MODELS = ("wheel", "heading_drift", "scale", "jumps", "combined")
#: Heading drift: a yaw-rate bias (radians a second) of 2 degrees a minute (a gyro's bias).
HEADING_DRIFT_RATE = math.radians(2.0) / 60.0
#: Scale error: every step's translation scaled by this (a wheel radius 5 % off).
SCALE_ERROR = 1.05
#: Jumps: this many steps gain a jump of 0.3-1 m (any direction) and 5-20 degrees (either side).
JUMPS = 6


def degrade_odometry(poses: Sequence[Pose], model: str = "wheel", *, seed: int = 0,
                     stamps: Sequence[float | None] | None = None) -> list[Pose]:
    """Odometry-like poses from true ones by one of :data:`NOISE_MODELS` (the first pose kept).

    Every model but ``"wheel"`` (:func:`degrade_poses`) adds a mild noise to each step of
    length ``d``: 1 % of ``d`` on each axis, 0.5 degrees a metre on the heading, and:

    * ``"heading_drift"``: the heading gains :data:`HEADING_DRIFT_RATE` times the step's
      duration (``stamps``, seconds; without them 1 s a step), to a side the seed picks,
      whether the robot moves or not;
    * ``"scale"``: the translation is scaled by :data:`SCALE_ERROR`;
    * ``"jumps"``: :data:`JUMPS` steps, picked by the seed, jump by 0.3-1 m and 5-20 degrees;
    * ``"combined"``: the heading drift, a scale of 1.03 and half the jumps.
    """
    if model == "wheel":
        return degrade_poses(poses, seed=seed)
    if model not in NOISE_MODELS:
        raise ValueError(f"noise model must be one of {', '.join(NOISE_MODELS)}, got {model!r}")
    rng = np.random.default_rng(seed)
    count = len(poses)
    times = np.array([np.nan if t is None else t for t in stamps], dtype=float) if stamps is not None else None
    if times is None or not np.isfinite(times).all():
        times = np.arange(count, dtype=float)
    drift = HEADING_DRIFT_RATE * rng.choice([-1.0, 1.0]) if model in ("heading_drift", "combined") else 0.0
    scale = {"scale": SCALE_ERROR, "combined": 1.03}.get(model, 1.0)
    jumps = {"jumps": JUMPS, "combined": JUMPS // 2}.get(model, 0)
    jump_at: set[int] = set()
    if jumps:
        jump_at = set(rng.choice(np.arange(1, count), size=min(jumps, count - 1), replace=False).tolist())
    out = [poses[0]]
    for k in range(1, count):
        step = relative(poses[k - 1], poses[k])
        d = math.hypot(step.x, step.y)
        noise = rng.normal(size=3)
        dx = step.x * scale + 0.01 * d * noise[0]
        dy = step.y * scale + 0.01 * d * noise[1]
        dyaw = step.yaw + math.radians(0.5) * d * noise[2] + drift * float(times[k] - times[k - 1])
        if k in jump_at:
            length, direction = rng.uniform(0.3, 1.0), rng.uniform(-math.pi, math.pi)
            dx += length * math.cos(direction)
            dy += length * math.sin(direction)
            dyaw += math.radians(rng.uniform(5.0, 20.0)) * rng.choice([-1.0, 1.0])
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
