"""Registering scans and whole logs: the sequential scan-to-map registration, and a log read
for ``occtool map`` with its poses registered when it needs them."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Pose, Position, RangeLog
from occtool.register._core import (
    MAX_REFUSED_SHARE,
    PLANAR_SPREAD,
    FloatArray,
    RegistrationReport,
    RegistrationSettings,
    _Aligner,
    _extruded,
    _in_world,
    _matrix,
    _pose,
    compose,
    information_roots,
    information_scale,
    matched_share,
    planar_information,
    relative,
    scan_points,
)
from occtool.register._graph import close_loops


# ---------------------------------------------------------------------- registration
def register_scans(scans: Sequence[FloatArray], odometry: Sequence[Pose | None] | None = None, *,
                   settings: RegistrationSettings | None = None,
                   report: RegistrationReport | None = None) -> list[Pose]:
    """The world pose of every scan (the first at its odometry pose, or the origin).

    Parameters
    ----------
    scans
        ``(N_k, 3)`` returns of each scan in its sensor-centred robot frame.
    odometry
        Each scan's odometry pose or ``None``; relative odometry between consecutive scans
        seeds each registration, else the previous step's motion does.
    """
    settings = settings or RegistrationSettings()
    count = len(scans)
    if count == 0:
        return []
    odometry = list(odometry) if odometry is not None else [None] * count
    if len(odometry) != count:
        raise InputError(f"{count} scans but {len(odometry)} odometry poses")
    planar = all(len(p) == 0 or float(np.ptp(p[:, 2])) <= PLANAR_SPREAD for p in scans)
    aligner = _Aligner(settings)
    started = time.process_time()
    prepared = [_extruded(p) if planar else p for p in scans]
    poses: list[Pose] = [odometry[0] if odometry[0] is not None else Pose()]
    information: list[FloatArray | None] = [None]
    weak = np.zeros(count, dtype=bool)
    submap: list[int] = [0]
    refused = 0
    for k in range(1, count):
        if odometry[k] is not None and odometry[k - 1] is not None:
            step = relative(odometry[k - 1], odometry[k])  # type: ignore[arg-type]
        elif k >= 2:
            step = relative(poses[k - 2], poses[k - 1])
        else:
            step = Pose()
        guess = compose(poses[k - 1], step)
        source = prepared[k]
        if len(scans[k]) < 10:
            poses.append(guess)
            information.append(None)
            weak[k] = True
            refused += 1
            continue
        target = np.concatenate([_in_world(prepared[i], poses[i]) for i in submap])
        matrix = aligner.align(target, source, _matrix(guess))
        info = aligner.information
        # Only an odometry seed is retried: a jump is the odometry's; the constant-velocity
        # guess of a log without odometry (CCNY's 10 Hz scans) fits poorly at 0.1 m far more
        # often, and retrying it cost minutes there for nothing.
        if settings.retry_below > 0.0 and odometry[k] is not None and odometry[k - 1] is not None:
            others = [compose(poses[k - 1], relative(poses[k - 2], poses[k - 1])) if k >= 2 else guess, poses[k - 1]]
            others += [compose(guess, Pose(0.0, 0.0, 0.0, turn)) for turn in settings.retry_turns]
            matrix, info, weak[k] = _retried(aligner, target, source, matrix, info, others, settings)
        if matched_share(target, source, matrix, settings.max_correspondence) >= settings.min_inliers:
            poses.append(_pose(matrix, planar))
            information.append(info)
        else:
            poses.append(guess)
            information.append(None)
            weak[k] = True
            refused += 1
        last = poses[submap[-1]]
        moved = relative(last, poses[k])
        if math.hypot(moved.x, moved.y) >= settings.submap_step or abs(moved.yaw) >= settings.submap_turn:
            submap.append(k)
            if len(submap) > settings.submap_scans:
                submap.pop(0)
    if report is not None:
        report.refused += refused
        report.seconds["registration"] = time.process_time() - started
    if settings.loop_closure and count > 2:
        weights = step_weights(poses, information, weak, settings)
        scale = information_scale(_step_blocks(poses, information), settings.odometry_sigma)
        poses = close_loops(prepared, poses, planar, aligner, settings, report, weights, information_scale=scale)
    return poses


def _retried(aligner: _Aligner, target: FloatArray, source: FloatArray, matrix: FloatArray,
             info: FloatArray | None, seeds: Sequence[Pose], settings: RegistrationSettings
             ) -> tuple[FloatArray, FloatArray | None, bool]:
    """``matrix`` (and its information), or when it fits poorly (fewer than
    ``settings.retry_below`` of the points within ``settings.retry_radius``) the best fit
    from the other ``seeds`` if it fits clearly better: a scan seeded by an odometry jump of
    a metre or 20 degrees converges to the wrong wall otherwise. The flag: the fit kept is
    still poor (a weak step for the pose graph)."""
    first = best = matched_share(target, source, matrix, settings.retry_radius)
    if best >= settings.retry_below:
        return matrix, info, False
    chosen = (matrix, info)
    for seed in seeds:
        found = aligner.align(target, source, _matrix(seed), settings.retry_search)
        found = aligner.align(target, source, found)
        share = matched_share(target, source, found, settings.retry_radius)
        if share > best and share >= first + settings.retry_margin:
            best, chosen = share, (found, aligner.information)
    return chosen[0], chosen[1], best < settings.retry_below


def _step_blocks(poses: list[Pose], information: Sequence[FloatArray | None]) -> list[FloatArray | None]:
    """Each step's x, y, yaw information from GICP, in the frame of the step's first pose."""
    return [planar_information(information[k], poses[k].yaw - poses[k - 1].yaw) for k in range(1, len(poses))]


def step_weights(poses: list[Pose], information: Sequence[FloatArray | None], weak: NDArray[np.bool_],
                 settings: RegistrationSettings) -> FloatArray | None:
    """Square roots of each step's information for the pose graph, ``(len(poses) - 1, 3, 3)``,
    or ``None`` for the plain sigmas of ``settings``. With ``settings.step_information``,
    GICP's own (x, y, yaw block turned into the previous pose's frame, scaled so that the
    median step has the translation information of ``settings.odometry_sigma``; a step
    without it gets the plain sigmas, three times wider); a weak step (refused, or a poor
    fit) ``settings.weak_step_scale`` times wider still."""
    st, sr = settings.odometry_sigma
    plain = np.diag([1 / st, 1 / st, 1 / sr])
    if not settings.step_information and (settings.weak_step_scale == 1.0 or not weak.any()):
        return None
    out = np.repeat(plain[None], len(poses) - 1, axis=0)
    if settings.step_information:
        out = information_roots(_step_blocks(poses, information), settings.odometry_sigma)
    out[weak[1:]] /= settings.weak_step_scale
    return out


# ---------------------------------------------------------------------- whole logs
def register_log(log: RangeLog, *, settings: RegistrationSettings | None = None,
                 position_tolerance: Sequence[float] | None = None, use_odometry: bool = True,
                 max_range: float | None = None) -> tuple[RangeLog, RegistrationReport]:
    """Register the scans of ``log`` (one scan a position: ``read_log(..., group_by="message")``)
    and group them into positions on the registered poses.

    The log's poses, where it has them, seed the registration as odometry
    (``use_odometry=False`` ignores them). Returns the regrouped log (its notes say how
    its poses were made) and the report, whose ``poses`` hold every scan's registered pose.
    """
    from occtool.io.positions import DEFAULT_POSITION_TOLERANCE, Scan, build_log

    if not log.positions:
        raise InputError(f"{log.source or 'the log'} holds no range data")
    odometry = [p.pose for p in log.positions] if use_odometry else [None] * len(log.positions)
    seeded = "seeded by the log's poses" if any(o is not None for o in odometry) else "no odometry: constant velocity"
    settings = settings or RegistrationSettings()
    report = RegistrationReport(scans=len(log.positions), seeded_by=seeded, backend=settings.backend)
    points = [scan_points(p.features, max_range) for p in log.positions]
    poses = register_scans(points, odometry, settings=settings, report=report)
    if len(points) > 1 and report.refused > MAX_REFUSED_SHARE * (len(points) - 1):
        what = ("the log has no poses and its scans" if all(o is None for o in odometry)
                else "the log's scans")
        raise InputError(
            f"{log.source or 'the log'}: {what} could not be registered ({report.refused} of {len(points) - 1} "
            "refused: too few returns, or too little overlap from one scan to the next); "
            "map it without registration (--no-register, register=False)")
    report.poses = poses
    report.stamps = [p.stamp for p in log.positions]
    report.odometry = [p.pose for p in log.positions]
    scans = [Scan(p.features.points, p.features.evidence, pose, p.stamp, p.source)
             for p, pose in zip(log.positions, poses)]
    notes = [n for n in log.notes if not n.startswith("the log has no poses")]
    notes.append(f"poses registered: {report.describe()}")
    regrouped = build_log(scans, source=log.source, tolerance=position_tolerance or DEFAULT_POSITION_TOLERANCE,
                          notes=notes)
    regrouped.pose_kind = "registered"
    return regrouped, report


def pose_kind(log: RangeLog) -> str | None:
    """What a log's poses are: its reader's word (``log.pose_kind``), else from its notes
    (``"odometry"``, ``"tf"``), else ``"log"`` (its own pose fields), ``None`` without poses."""
    if not log.has_poses:
        return None
    if log.pose_kind:
        return log.pose_kind
    if any(n.startswith("poses from odometry") for n in log.notes):
        return "odometry"
    if any(n.startswith("poses from /tf") for n in log.notes):
        return "tf"
    return "log"


def needs_registration(log: RangeLog) -> bool:
    """Whether ``occtool map`` registers a log by default: it has no poses, or only odometry."""
    return pose_kind(log) in (None, "odometry")


def read_registered_log(path: str | Sequence[str | os.PathLike[str]], read_options: dict[str, Any],
                        register: bool | None = None, *,
                        settings: RegistrationSettings | None = None
                        ) -> tuple[RangeLog, RegistrationReport | None]:
    """Read a log for ``occtool map``: scan by scan, registered when ``register`` is true,
    or by default (``None``) when :func:`needs_registration`; grouped into positions as
    ``read_options`` ask either way. Returns the log and the report (``None`` when the
    log's own poses are kept)."""
    from occtool.io import read_log
    from occtool.io.positions import DEFAULT_POSITION_TOLERANCE, Scan, build_log

    options = dict(read_options)
    group_by = options.pop("group_by", "position") or "position"
    tolerance = options.get("position_tolerance") or DEFAULT_POSITION_TOLERANCE
    if register is False:
        return read_log(path, group_by=group_by, **options), None
    scans = read_log(path, group_by="message", **options)
    if register is None and not needs_registration(scans):
        regrouped = build_log([Scan(p.features.points, p.features.evidence, p.pose, p.stamp, p.source)
                               for p in scans.positions], source=scans.source, tolerance=tolerance,
                              group_by=group_by, notes=scans.notes)
        regrouped.pose_kind, regrouped.to_log_frame = scans.pose_kind, scans.to_log_frame
        return regrouped, None
    registered, report = register_log(scans, settings=settings, position_tolerance=tolerance)
    if group_by == "message":
        registered = positions_with_poses(scans, report.poses)
        registered.notes.append(f"poses registered: {report.describe()}")
        registered.pose_kind = "registered"
    return registered, report



def positions_with_poses(log: RangeLog, poses: Sequence[Pose]) -> RangeLog:
    """``log`` (one scan a position) with its poses replaced by ``poses``."""
    if len(poses) != len(log.positions):
        raise InputError(f"{len(log.positions)} scans but {len(poses)} poses")
    return RangeLog([Position(p.index, p.features, pose, p.stamp, p.source) for p, pose in zip(log.positions, poses)],
                    source=log.source, notes=list(log.notes))
