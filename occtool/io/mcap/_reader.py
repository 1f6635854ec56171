"""Reading range channels into a :class:`~occtool.features.RangeLog`, step by step."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from occtool.errors import InputError
from occtool.features import Features, Pose, Position, RangeLog
from occtool.io.mcap._channels import OCCTOOL, ODOMETRY, RANGE_KINDS, TF, _get, _protobuf_available, channel_kind
from occtool.io.mcap._decode import _DECODERS, DEFAULT_CONSTANT_EVIDENCE, _decode_occtool, _Options
from occtool.io.mcap._file import ChannelRow, _Reader
from occtool.io.mcap._transforms import (
    _IDENTITY,
    _checked_rigid,
    _compose_sensor,
    _FrameTree,
    _planar_pose,
    _Rigid,
    _strip_frame,
    _transforms_of,
)
from occtool.io.positions import DEFAULT_POSITION_TOLERANCE, Scan, build_log


def _choose_channels(rows: list[ChannelRow], topics: Sequence[str] | None, path: str) -> list[ChannelRow]:
    def listing(items: list[ChannelRow]) -> str:
        return "; ".join(f"{r.topic} ({r.schema or 'no schema'}, {r.messages if r.messages is not None else '?'} messages)" for r in items)

    if topics:
        by_topic = {r.topic: r for r in rows}
        chosen = []
        for topic in topics:
            if topic not in by_topic:
                raise InputError(f"{path} has no topic '{topic}'; its channels: {listing(rows) or 'none'}")
            row = by_topic[topic]
            if row.kind not in RANGE_KINDS:
                raise InputError(
                    f"{path}: topic '{topic}' has schema '{row.schema}' ({row.encoding}), which occtool cannot read "
                    "as range data (it reads sensor_msgs/msg/PointCloud2, sensor_msgs/msg/LaserScan, "
                    "foxglove.PointCloud, foxglove.LaserScan and occtool.RangeFeatures)"
                )
            chosen.append(row)
        return chosen
    candidates = [r for r in rows if r.kind in RANGE_KINDS]
    if not candidates:
        raise InputError(f"{path} holds no range data occtool can read; its channels: {listing(rows) or 'none'}")
    if len(candidates) > 1:
        raise InputError(f"{path} has several range channels, pick one or more with --topic: {listing(candidates)}")
    return candidates


def read_mcap(
    path: str | os.PathLike[str],
    *,
    topics: Sequence[str] | None = None,
    evidence_field: str = "evidence",
    evidence: float | None = None,
    use_intensities: bool = False,
    sensor_frame: str | None = None,
    base_frame: str | None = None,
    position_tolerance: Sequence[float] = DEFAULT_POSITION_TOLERANCE,
    group_by: str = "position",
    skip_invalid: bool = False,
    no_return_range: float | None = None,
    opener: Callable[[str | os.PathLike[str]], Any] | None = None,
) -> RangeLog:
    """Read the range channels of an MCAP file into positions of features.

    Parameters are those of :func:`occtool.io.read_log`; ``opener`` opens another
    container with the same ``channels``/``messages`` interface (ROS bags,
    :mod:`occtool.io.rosbag`).

    Raises
    ------
    InputError
        For a corrupt or truncated file, a missing topic, an unsupported schema, a log
        without range data, or invalid evidence values (unless ``skip_invalid``).
    """
    from occtool.io import check_no_return_range

    name = str(path)
    no_return_range = check_no_return_range(no_return_range)
    with (opener or _Reader)(path) as reader:
        channel_list = reader.channels()
        protobuf = _protobuf_available()
        rows = []
        for _, topic, schema, encoding, count in channel_list:
            kind = channel_kind(schema, encoding)
            if encoding == "protobuf" and kind is not None and not protobuf:
                if topics and topic in topics or kind in RANGE_KINDS and not topics:
                    from occtool.errors import MissingDependencyError

                    raise MissingDependencyError("mcap-protobuf-support", "protobuf", f"reading {topic} (protobuf)")
                kind = None
            rows.append(ChannelRow(topic, schema, encoding, count, kind, ""))
        chosen = _choose_channels(rows, topics, name)
        kinds = {r.topic: r.kind for r in chosen}
        if any(k == OCCTOOL for k in kinds.values()):
            if len(chosen) > 1:
                raise InputError(f"{name}: read occtool's features channel on its own, not with other topics")
            return _read_occtool_channel(reader, chosen[0].topic, name)

        static_topics = [r.topic for r in rows if r.kind == TF and r.topic.endswith("tf_static")]
        tf_topics = [r.topic for r in rows if r.kind == TF and r.topic not in static_topics]
        odom_topics = [r.topic for r in rows if r.kind == ODOMETRY]

        frames = _FrameTree()
        if static_topics:
            for _, static_channel, _, message in reader.messages(static_topics):
                for parent, child, rigid in _transforms_of(message, f"{name}, {static_channel.topic}"):
                    frames.add(parent, child, rigid)
        base = _strip_frame(base_frame) if base_frame else None
        if base is not None and base not in frames and not tf_topics and not odom_topics and sensor_frame is None:
            raise InputError(f"{name}: base frame '{base}' appears in no transform of the log")
        base_name = base or "base_link"

        options = _Options(evidence_field, evidence, use_intensities, skip_invalid, no_return_range)
        scans: list[Scan] = []
        tf_pose: Pose | None = None
        odom_pose: Pose | None = None
        scan_tf_poses: list[Pose | None] = []
        scan_odom_poses: list[Pose | None] = []
        mounting_cache: dict[str, _Rigid | None] = {}
        unmounted: set[str] = set()
        dropped_nan = 0
        dropped_origin = 0
        scan_count = 0
        for schema, channel, mcap_message, message in reader.messages([r.topic for r in chosen] + tf_topics + odom_topics):
            topic = channel.topic
            if topic in tf_topics:
                for parent, child, rigid in _transforms_of(message, f"{name}, {topic}"):
                    if child == base_name:
                        tf_pose = _planar_pose(rigid)
                continue
            if topic in odom_topics:
                child = _strip_frame(_get(message, "child_frame_id", ""))
                if not child or child == base_name:
                    pose = _get(_get(message, "pose"), "pose")
                    odom_pose = _planar_pose(_checked_rigid(
                        _get(pose, "orientation"), _get(pose, "position"),
                        f"{name}, {topic}, message {mcap_message.sequence}: the odometry pose"))
                continue
            where = f"{name}, topic {topic}, message {mcap_message.sequence or scan_count}"
            try:
                decoded = _DECODERS[kinds[topic]](message, options, where)  # type: ignore[index]  # chosen topics have a kind
            except (AttributeError, TypeError, KeyError, ValueError) as exc:
                if isinstance(exc, InputError):
                    raise
                raise InputError(f"{where}: malformed {schema.name} message ({exc!r})") from None
            scan_count += 1
            dropped_nan += decoded.dropped_nan
            points, values = decoded.points, decoded.evidence
            bad = ~np.isfinite(values) | (values < 0.0) | (values > 1.0)
            if bad.any():
                if not skip_invalid:
                    i = int(np.argmax(bad))
                    raise InputError(f"{where}: evidence value {float(values[i])!r} is not in [0, 1] (pass --skip-invalid to drop such points)")
                options.skipped_invalid += int(bad.sum())
                points, values = points[~bad], values[~bad]
            # Mounting: message frame (or --sensor-frame) into the base frame, from /tf_static.
            frame = _strip_frame(sensor_frame) if sensor_frame else decoded.frame
            if frame not in mounting_cache:
                mounting_cache[frame] = frames.lookup(frame, base_name) if frame else None
                # A message without a frame id is taken to be in the base frame already.
                if mounting_cache[frame] is None and frame and frame != base_name:
                    unmounted.add(frame)
            mounting = decoded.origin.then(mounting_cache[frame] or _IDENTITY)
            if not np.allclose(mounting.rotation, np.eye(3)):
                points = points @ mounting.rotation.T
            at_origin = ~(np.abs(points) > 0.0).any(axis=1)
            if at_origin.any():
                dropped_origin += int(at_origin.sum())
                points, values = points[~at_origin], values[~at_origin]
            stamp = decoded.stamp if decoded.stamp else mcap_message.log_time * 1e-9
            scans.append(Scan(points, values, None, stamp, topic))
            scan_tf_poses.append(_compose_sensor(tf_pose, mounting.translation))
            scan_odom_poses.append(_compose_sensor(odom_pose, mounting.translation))

    notes: list[str] = []
    if scan_count == 0:
        raise InputError(f"{name} holds no messages on {', '.join(r.topic for r in chosen)}")
    if any(p is not None for p in scan_tf_poses):
        poses, pose_source = scan_tf_poses, f"/tf (parent of {base_name})"
    elif any(p is not None for p in scan_odom_poses):
        poses, pose_source = scan_odom_poses, "odometry"
    else:
        poses, pose_source = [None] * len(scans), None
    if pose_source:
        notes.append(f"poses from {pose_source}")
        missing = sum(p is None for p in poses)
        if missing:
            notes.append(f"{missing} scan(s) before the first pose joined the first position")
    scans = [Scan(s.points, s.evidence, p, s.stamp, s.source) for s, p in zip(scans, poses)]
    if unmounted:
        notes.append(
            f"no /tf_static transform from {', '.join(sorted(unmounted))} to {base_name}: "
            "points kept in the sensor frame's axes"
        )
    if options.constant_for:
        value = DEFAULT_CONSTANT_EVIDENCE if evidence is None else evidence
        notes.append(f"constant evidence {value} (--evidence) for {' and '.join(sorted(options.constant_for))}")
    if options.no_return:
        if no_return_range is None:
            notes.append(f"dropped {options.no_return} of {options.beams} laser beam(s) with no return "
                         "(+inf or above range_max)")
        else:
            reach = sorted(options.free_reach)
            at = f"{reach[0]:g} m" if len(reach) == 1 else f"{reach[0]:g} to {reach[-1]:g} m"
            notes.append(f"kept {options.no_return} of {options.beams} laser beam(s) with no return "
                         f"(+inf or above range_max) as free rays at {at} with evidence 0 "
                         f"(--no-return-range {no_return_range:g})")
    if options.invalid_beams:
        notes.append(f"dropped {options.invalid_beams} of {options.beams} invalid laser beam(s) "
                     "(NaN, -inf, <= 0 or below range_min)")
    if dropped_nan:
        notes.append(f"dropped {dropped_nan} point(s) with NaN coordinates (no return)")
    if dropped_origin:
        notes.append(f"dropped {dropped_origin} point(s) at the sensor origin (no return)")
    if options.skipped_invalid:
        notes.append(f"skipped {options.skipped_invalid} point(s) with evidence outside [0, 1] or NaN")
    if not any(s.points.shape[0] for s in scans):
        raise InputError(f"{name}: the {scan_count} range message(s) hold no valid points")
    return build_log(scans, source=name, tolerance=position_tolerance, group_by=group_by, notes=notes)



def _read_occtool_channel(reader: _Reader, topic: str, name: str) -> RangeLog:
    found: list[tuple[int, int, Features, Pose | None, float | None]] = []
    notes: list[str] = []
    for k, (_, _, _, message) in enumerate(reader.messages([topic])):
        where = f"{name}, topic {topic}, message {k}"
        if not isinstance(message, dict):
            raise InputError(f"{where}: expected a JSON object")
        index, points, evidence, pose, stamp = _decode_occtool(message, where)
        try:
            features = Features(points, evidence)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        found.append((index, k, features, pose, stamp))
    # Messages are stored in time order; the position field restores the written order.
    found.sort(key=lambda item: (item[0], item[1]))
    positions = [
        Position(i, features, pose, stamp, f"{name} position {i}")
        for i, (_, _, features, pose, stamp) in enumerate(found)
    ]
    if not positions:
        raise InputError(f"{name} holds no messages on {topic}")
    return RangeLog(positions=positions, source=name, notes=notes)

