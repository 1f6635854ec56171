"""Group the scans of a recording into robot positions.

Every reader produces *scans*: the features of one message (or one run of CSV rows)
with the robot pose it was taken at, if the log has poses. A robot standing still, or
nearly so, takes several scans from one place; occtool fits one local model per place,
so consecutive scans whose poses stay within a distance and angle tolerance of the
first scan of the group form one :class:`~occtool.features.Position`. Each scan's
points are then re-expressed in the frame of that position's reference pose, so a
position's features are all in one sensor-centred robot frame.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.features import Features, Note, Pose, Position, RangeLog
from occtool.io.read_options import DEFAULT_POSITION_TOLERANCE, GROUP_BY_CHOICES, check_tolerance
from occtool.limits import MAX_WORLD_COORDINATE


@dataclass(frozen=True, eq=False)
class Scan:
    """The raw output of one message of a log, before grouping into positions.

    Parameters
    ----------
    points
        ``(N, 3)`` points in the sensor-centred robot frame at ``pose``, metres.
    evidence
        ``(N,)`` evidence values in [0, 1].
    pose
        World pose of the sensor-centred robot frame, or ``None`` if unknown.
    stamp
        Time of the scan in seconds, if known.
    source
        Where the scan came from (topic, line), for messages.
    """

    points: NDArray[np.float64]
    evidence: NDArray[np.float64]
    pose: Pose | None = None
    stamp: float | None = None
    source: str = ""


#: How far a pose's quaternion may be from unit length: float32 storage and text rounding
#: leave ~1e-7; more is a damaged or hand-edited pose, whose "rotation" would be a guess.
QUATERNION_TOLERANCE = 1e-2
#: How far a pose's rotation matrix may be from orthonormal (``|R R^T - I|``, each entry).
ROTATION_TOLERANCE = 1e-3


def check_pose(
    where: str,
    translation: ArrayLike,
    *,
    yaw: float | None = None,
    quaternion: ArrayLike | None = None,
    rotation: ArrayLike | None = None,
) -> None:
    """Refuse a world pose that is no pose; every reader calls this once per pose it reads.

    A pose is a translation (metres) and one of a ``yaw`` (radians), a ``quaternion``
    ``(x, y, z, w)`` or a 3x3 ``rotation`` matrix. Every value must be finite and at most
    :data:`occtool.limits.MAX_WORLD_COORDINATE` (metres, radians for the yaw) in size; a
    quaternion must be of unit length within :data:`QUATERNION_TOLERANCE` (the readers
    normalise it), a matrix orthonormal within :data:`ROTATION_TOLERANCE` with determinant +1.

    Raises
    ------
    InputError
        ``"{where}: ..."`` saying what is wrong, ``where`` naming the line or message.

    Examples
    --------
    >>> check_pose("line 3", (1.0, 2.0, 0.0), yaw=0.5)
    >>> check_pose("line 4", (1.0, 2.0, 0.0), quaternion=(0.0, 0.0, 0.0, 2.0))
    Traceback (most recent call last):
    ...
    occtool.errors.InputError: line 4: the pose's quaternion (0, 0, 0, 2) has length 2, not 1: no rotation
    """
    t = np.asarray(translation, dtype=np.float64).reshape(-1)
    parts = [("translation", t)]
    if yaw is not None:
        parts.append(("yaw", np.asarray([yaw], dtype=np.float64)))
    if quaternion is not None:
        parts.append(("quaternion", np.asarray(quaternion, dtype=np.float64).reshape(-1)))
    if rotation is not None:
        parts.append(("rotation", np.asarray(rotation, dtype=np.float64).reshape(-1)))
    for name, values in parts:
        if not np.isfinite(values).all():
            raise InputError(f"{where}: the pose's {name} ({_values(values)}) holds a NaN or infinity")
        if not (np.abs(values) <= MAX_WORLD_COORDINATE).all():
            raise InputError(f"{where}: the pose's {name} ({_values(values)}) reaches past "
                             f"{MAX_WORLD_COORDINATE:g}: no place in any world frame")
    if quaternion is not None:
        q = np.asarray(quaternion, dtype=np.float64).reshape(-1)
        length = float(np.sqrt(q @ q))
        if abs(length - 1.0) > QUATERNION_TOLERANCE:
            raise InputError(f"{where}: the pose's quaternion ({_values(q)}) has length {length:.6g}, not 1: "
                             "no rotation")
    if rotation is not None:
        r = np.asarray(rotation, dtype=np.float64).reshape(3, 3)
        if not (np.abs(r @ r.T - np.eye(3)) <= ROTATION_TOLERANCE).all() or np.linalg.det(r) < 0.0:
            raise InputError(f"{where}: the pose's 3x3 rotation is not a rotation (not orthonormal with "
                             "determinant +1)")


def _values(values: NDArray[np.float64]) -> str:
    return ", ".join(f"{v:.6g}" for v in values[:9])


def _angle_difference(a: float, b: float) -> float:
    return float(abs((a - b + np.pi) % (2.0 * np.pi) - np.pi))


def assign_positions(
    poses: Sequence[Pose | None],
    *,
    tolerance: Sequence[float] = DEFAULT_POSITION_TOLERANCE,
    group_by: str = "position",
) -> NDArray[np.int64]:
    """Label each scan with the index of the position it belongs to.

    Parameters
    ----------
    poses
        The pose of each scan in recording order (``None`` where unknown).
    tolerance
        ``(distance, angle)``: a scan joins the current position while its pose lies
        within this distance (metres) and yaw difference (radians) of the position's
        first pose; otherwise it starts a new position.
    group_by
        ``"position"`` groups as above; ``"message"`` makes every scan its own position.

    Returns
    -------
    numpy.ndarray
        ``(K,)`` position index of each scan, non-decreasing, starting at 0.

    Notes
    -----
    A scan without a pose joins the current position (a log without any poses is one
    position), since nothing says the robot moved.
    """
    if group_by not in GROUP_BY_CHOICES:
        raise InputError(f"group-by must be one of {', '.join(GROUP_BY_CHOICES)}, got {group_by!r}")
    max_distance, max_angle = check_tolerance(tolerance)
    labels = np.zeros(len(poses), dtype=np.int64)
    if group_by == "message":
        return np.arange(len(poses), dtype=np.int64)
    current = 0
    reference: Pose | None = None
    # A loop over scans (messages), not points: a log has thousands of scans at most.
    for k, pose in enumerate(poses):
        if pose is not None:
            if reference is None:
                reference = pose
            else:
                distance = float(np.hypot(pose.x - reference.x, pose.y - reference.y))
                if distance > max_distance or _angle_difference(pose.yaw, reference.yaw) > max_angle:
                    current += 1
                    reference = pose
        labels[k] = current
    return labels


def relative_transform(pose: Pose, reference: Pose) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Rotation and translation taking points in ``pose``'s frame into ``reference``'s frame."""
    rotation = reference.rotation.T @ pose.rotation
    translation = reference.rotation.T @ (pose.translation - reference.translation)
    return rotation, translation


def to_reference_frame(
    points: NDArray[np.float64], pose_rows: NDArray[np.float64], reference: Pose
) -> NDArray[np.float64]:
    """Move points, each with its own pose, into the frame of ``reference``.

    Parameters
    ----------
    points
        ``(N, 3)`` points in the frame of their pose.
    pose_rows
        ``(N, 4)`` pose of each point as ``x, y, z, yaw``.
    reference
        The pose whose frame the result is expressed in.
    """
    dyaw = pose_rows[:, 3] - reference.yaw
    c, s = np.cos(dyaw), np.sin(dyaw)
    # Offset of each point's pose from the reference, rotated into the reference frame.
    dx = pose_rows[:, 0] - reference.x
    dy = pose_rows[:, 1] - reference.y
    cr, sr = np.cos(reference.yaw), np.sin(reference.yaw)
    tx = cr * dx + sr * dy
    ty = -sr * dx + cr * dy
    tz = pose_rows[:, 2] - reference.z
    out = np.empty_like(points, dtype=np.float64)
    out[:, 0] = c * points[:, 0] - s * points[:, 1] + tx
    out[:, 1] = s * points[:, 0] + c * points[:, 1] + ty
    out[:, 2] = points[:, 2] + tz
    return out


def group_scans(
    scans: Iterable[Scan],
    *,
    source: str,
    tolerance: Sequence[float] = DEFAULT_POSITION_TOLERANCE,
    group_by: str = "position",
    notes: list[str] | None = None,
) -> Iterator[Position]:
    """Group scans into positions as they come, yielding each position once its last scan is read.

    The same grouping as :func:`assign_positions` and :func:`build_log`, one scan at a time:
    only the scans of the position being gathered are held. When ``scans`` is exhausted,
    the grouping's notes (a log without poses, points dropped at the sensor origin) are
    appended to ``notes``; a scan whose pose is not finite is an :class:`InputError` when
    it is reached, and so is a log that yielded no position, at its end.
    """
    if group_by not in GROUP_BY_CHOICES:
        raise InputError(f"group-by must be one of {', '.join(GROUP_BY_CHOICES)}, got {group_by!r}")
    max_distance, max_angle = check_tolerance(tolerance)
    notes = notes if notes is not None else []
    group: list[Scan] = []
    reference: Pose | None = None
    count = 0
    has_poses = False
    produced = 0
    dropped_at_origin = 0
    for k, scan in enumerate(scans):
        pose = scan.pose
        # Readers check each pose as they read it (check_pose, naming the line); this is the
        # net under every reader, in plain Python (a NaN fails the comparison too).
        if pose is not None and not all(abs(v) <= MAX_WORLD_COORDINATE for v in (pose.x, pose.y, pose.z, pose.yaw)):
            if not np.isfinite([pose.x, pose.y, pose.z, pose.yaw]).all():
                raise InputError(
                    f"{source}: scan {scan.source or k} was taken at a pose that is not finite "
                    f"(x {pose.x}, y {pose.y}, z {pose.z}, yaw {pose.yaw})"
                )
            check_pose(f"{source}: scan {scan.source or k}", (pose.x, pose.y, pose.z), yaw=pose.yaw)
        count += 1
        new_position = False
        if pose is not None:
            has_poses = True
        if group_by == "message":
            new_position = bool(group)
        elif pose is not None:
            # A scan without a pose joins the current position: nothing says the robot moved.
            if reference is None:
                reference = pose
            elif (float(np.hypot(pose.x - reference.x, pose.y - reference.y)) > max_distance
                  or _angle_difference(pose.yaw, reference.yaw) > max_angle):
                new_position = True
                reference = pose
        if new_position and group:
            position, dropped = _merge_scans(group, produced)
            dropped_at_origin += dropped
            group = []
            if position is not None:
                produced += 1
                yield position
        group.append(scan)
    if group:
        position, dropped = _merge_scans(group, produced)
        dropped_at_origin += dropped
        if position is not None:
            produced += 1
            yield position
    # A single scan without a pose is the normal case of a one-shot file; say so only when
    # several scans were merged on the assumption that the robot did not move.
    if count > 1 and not has_poses and group_by == "position":
        notes.append(Note.warn(
            f"the log has no poses: its {count} scans form one position (group_by='message' splits them)"))
    if dropped_at_origin:
        notes.append(f"{dropped_at_origin} point(s) fell on the position's sensor origin and were dropped")
    if not produced:
        raise InputError(f"{source} holds no range data")


def _merge_scans(group: list[Scan], index: int) -> tuple[Position | None, int]:
    """The scans of one position in the frame of its first pose, and the count of points
    dropped at its sensor origin (``None`` for a position left without features)."""
    reference = next((s.pose for s in group if s.pose is not None), None)
    parts_points = []
    parts_evidence = []
    origins = []  # each scan's sensor in the reference's frame
    for scan in group:
        if scan.points.shape[0] == 0:
            continue
        points = np.asarray(scan.points, dtype=np.float64)
        origin = np.zeros(3)
        if reference is not None and scan.pose is not None and scan.pose != reference:
            rotation, origin = relative_transform(scan.pose, reference)
            points = points @ rotation.T + origin
        parts_points.append(points)
        parts_evidence.append(np.asarray(scan.evidence, dtype=np.float64))
        origins.append(origin)
    if not parts_points:
        return None, 0
    points = np.concatenate(parts_points)
    evidence = np.concatenate(parts_evidence)
    keep = (np.abs(points) > 0.0).any(axis=1)
    dropped = int((~keep).sum())
    sizes = np.array([part.shape[0] for part in parts_points], dtype=np.int64)
    if not keep.all():
        points, evidence = points[keep], evidence[keep]
        sizes = np.bincount(np.repeat(np.arange(sizes.size), sizes)[keep], minlength=sizes.size).astype(np.int64)
    if not points.shape[0]:
        return None, dropped
    # A 3D map starts each ray at its own scan's sensor and holds scans out one by one (Position).
    scan_origins = np.array(origins) if len(origins) > 1 else None
    stamps = [s.stamp for s in group if s.stamp is not None]
    sources = sorted({s.source for s in group if s.source})
    return Position(
        index=index,
        features=Features(points, evidence),
        pose=reference,
        stamp=stamps[0] if stamps else None,
        source=", ".join(sources) if len(sources) <= 3 else f"{sources[0]} ... ({len(group)} scans)",
        scan_origins=scan_origins,
        scan_sizes=sizes if scan_origins is not None else None,
    ), dropped


def build_log(
    scans: Iterable[Scan],
    *,
    source: str,
    tolerance: Sequence[float] = DEFAULT_POSITION_TOLERANCE,
    group_by: str = "position",
    notes: list[str] | None = None,
) -> RangeLog:
    """Group scans into positions and return the :class:`RangeLog` (:func:`group_scans`, held whole).

    A scan whose pose holds a NaN or infinity is an :class:`InputError` (readers refuse or
    drop such poses first, naming the line or message). Scans with no points are kept
    for grouping but contribute nothing; a position
    left without features is dropped. Points that land on the position's sensor origin
    after the move into the reference frame are dropped too (they carry no direction).
    """
    scan_list = list(scans)
    notes = list(notes or [])
    positions = list(group_scans(scan_list, source=source, tolerance=tolerance, group_by=group_by, notes=notes))
    return RangeLog(positions=positions, source=source, notes=notes)
