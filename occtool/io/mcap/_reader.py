"""Reading range channels into a :class:`~occtool.features.RangeLog`, step by step."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

from occtool.errors import InputError
from occtool.features import Features, Note, Pose, Position, RangeLog
from occtool.io.mcap._channels import (
    CAMERA_INFO,
    DEPTH_KINDS,
    OCCTOOL,
    ODOMETRY,
    RANGE_KINDS,
    TF,
    _get,
    _protobuf_available,
    channel_kind,
)
from occtool.io.mcap._decode import _DECODERS, _decode_occtool, _Decoded, _Options
from occtool.io.mcap._depth import DepthSettings, add_camera_info, decode_depth, depth_notes
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
from occtool.io.positions import Scan, build_log
from occtool.io.read_options import DEFAULT_CONSTANT_EVIDENCE, ReadOptions, as_read_options, options_as_keywords


def _choose_channels(rows: list[ChannelRow], topics: Sequence[str] | None, path: str) -> list[ChannelRow]:
    """The range channels to read: the ``topics`` asked for, else the log's only range channel."""

    def listing(items: list[ChannelRow]) -> str:
        return "; ".join(
            f"{r.topic} ({r.schema or 'no schema'}, {r.messages if r.messages is not None else '?'} messages)"
            for r in items
        )

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
                    "foxglove.PointCloud, foxglove.LaserScan, occtool.RangeFeatures and depth images: "
                    "sensor_msgs/msg/Image, sensor_msgs/msg/CompressedImage (compressedDepth), foxglove.RawImage)"
                )
            chosen.append(row)
        return chosen
    candidates = [r for r in rows if r.kind in RANGE_KINDS]
    if not candidates:
        raise InputError(f"{path} holds no range data occtool can read; its channels: {listing(rows) or 'none'}")
    if len(candidates) > 1 and all(r.kind in DEPTH_KINDS for r in candidates):
        # Image channels hold colour as well as depth: a camera's one "depth" topic is the one.
        named = [r for r in candidates if "depth" in r.topic.lower()]
        if len(named) == 1:
            return named
    if len(candidates) > 1:
        raise InputError(f"{path} has several range channels, pick one or more (topics=): {listing(candidates)}")
    return candidates


def read_mcap(
    path: str | os.PathLike[str],
    options: ReadOptions | None = None,
    *,
    opener: Callable[[str | os.PathLike[str]], Any] | None = None,
    **keywords: Any,
) -> RangeLog:
    """Read the range channels of an MCAP file into positions of features.

    ``options`` and ``keywords`` are those of :func:`occtool.io.read_log` (a
    :class:`~occtool.io.ReadOptions` and its fields by name); ``opener`` opens another
    container with the same ``channels``/``messages`` interface (ROS bags,
    :mod:`occtool.io.rosbag`).

    Raises
    ------
    InputError
        For a corrupt or truncated file, a missing topic, an unsupported schema, a log
        without range data, or invalid evidence values (unless ``skip_invalid``).
    """
    settings = as_read_options(options, **keywords)
    name = str(path)
    with (opener or _Reader)(path) as reader:
        rows = _channel_rows(reader, settings.topics)
        chosen = _choose_channels(rows, settings.topics, name)
        kinds = {r.topic: r.kind for r in chosen}
        if any(k == OCCTOOL for k in kinds.values()):
            if len(chosen) > 1:
                raise InputError(f"{name}: read occtool's features channel on its own, not with other topics")
            return _read_occtool_channel(reader, chosen[0].topic, name)

        static_topics = [r.topic for r in rows if r.kind == TF and r.topic.endswith("tf_static")]
        tf_topics = [r.topic for r in rows if r.kind == TF and r.topic not in static_topics]
        odom_topics = [r.topic for r in rows if r.kind == ODOMETRY]
        frames = _static_frames(reader, static_topics, name)
        base = _strip_frame(settings.base_frame) if settings.base_frame else None
        if (base is not None and base not in frames and not tf_topics and not odom_topics
                and settings.sensor_frame is None):
            raise InputError(f"{name}: base frame '{base}' appears in no transform of the log")

        decoding = _Options(settings)
        decoding.depth = _depth_settings(reader, rows, kinds, name, settings)
        scans = _Scans(name, base or "base_link", settings.sensor_frame, frames, decoding)
        for schema, channel, record, message in reader.messages([r.topic for r in chosen] + tf_topics + odom_topics):
            if channel.topic in tf_topics:
                scans.add_transforms(message, channel.topic)
            elif channel.topic in odom_topics:
                scans.add_odometry(message, channel.topic, record)
            else:
                scans.add_range(kinds[channel.topic], schema, channel.topic, record, message)  # type: ignore[arg-type]  # chosen topics have a kind

    if scans.count == 0:
        raise InputError(f"{name} holds no messages on {', '.join(r.topic for r in chosen)}")
    posed, notes = scans.posed()
    notes += _reading_notes(scans)
    if not any(s.points.shape[0] for s in posed):
        raise InputError(f"{name}: the {scans.count} range message(s) hold no valid points")
    return build_log(posed, source=name, tolerance=settings.position_tolerance, group_by=settings.group_by,
                     notes=notes)


def _channel_rows(reader: Any, topics: Sequence[str] | None) -> list[ChannelRow]:
    """The container's channels with their kinds; a protobuf channel without the extra has none.

    Raises
    ------
    MissingDependencyError
        When a protobuf channel that would be read (asked for, or the range channel to
        choose) needs the ``protobuf`` extra.
    """
    protobuf = _protobuf_available()
    rows = []
    for _, topic, schema, encoding, count in reader.channels():
        kind = channel_kind(schema, encoding)
        if encoding == "protobuf" and kind is not None and not protobuf:
            if topics and topic in topics or kind in RANGE_KINDS and not topics:
                from occtool.errors import MissingDependencyError

                raise MissingDependencyError("mcap-protobuf-support", "protobuf", f"reading {topic} (protobuf)")
            kind = None
        rows.append(ChannelRow(topic, schema, encoding, count, kind, ""))
    return rows


def _depth_settings(reader: Any, rows: list[ChannelRow], kinds: dict[str, str | None], name: str,
                    options: ReadOptions) -> DepthSettings | None:
    """For depth channels: the settings (checked by ReadOptions), with every camera's intrinsics read first."""
    if not any(k in DEPTH_KINDS for k in kinds.values()):
        return None
    settings = DepthSettings(options.depth_features, options.depth_noise, options.depth_max_range)
    info_topics = [r.topic for r in rows if r.kind == CAMERA_INFO]
    if not info_topics:
        raise InputError(f"{name}: depth images need their camera's intrinsics, and the log has no "
                         "sensor_msgs/msg/CameraInfo or foxglove.CameraCalibration channel")
    for k, (_, channel, _, message) in enumerate(reader.messages(info_topics)):
        add_camera_info(settings, message, f"{name}, topic {channel.topic}, message {k}")
    return settings


def _static_frames(reader: Any, static_topics: list[str], name: str) -> _FrameTree:
    """The frame tree of every transform on the ``/tf_static`` topics."""
    frames = _FrameTree()
    if static_topics:
        for _, static_channel, _, message in reader.messages(static_topics):
            for parent, child, rigid in _transforms_of(message, f"{name}, {static_channel.topic}"):
                frames.add(parent, child, rigid)
    return frames


class _Scans:
    """The range messages read so far, each with the latest ``/tf`` and odometry pose.

    A scan's points are rotated into the base frame's axes by the sensor's mounting (from
    the static frames) and stay centred at the sensor; the mounting's offset moves the
    pose. The counts feed the log's notes.
    """

    def __init__(self, name: str, base_name: str, sensor_frame: str | None, frames: _FrameTree, options: _Options,
                 *, keep: bool = True):
        self.keep = keep  # hold every scan (read_mcap), or only count (a stream's passes)
        self.name = name
        self.base_name = base_name
        self.sensor_frame = sensor_frame
        self.frames = frames
        self.options = options
        self.scans: list[Scan] = []
        self.tf_pose: Pose | None = None
        self.odom_pose: Pose | None = None
        self.tf_poses: list[Pose | None] = []
        self.odom_poses: list[Pose | None] = []
        self.mountings: dict[str, _Rigid | None] = {}
        self.unmounted: set[str] = set()
        self.dropped_nan = 0
        self.dropped_origin = 0
        self.count = 0

    def add_transforms(self, message: Any, topic: str) -> None:
        """A ``/tf`` message: the base frame's pose, if it holds one."""
        for _, child, rigid in _transforms_of(message, f"{self.name}, {topic}"):
            if child == self.base_name:
                self.tf_pose = _planar_pose(rigid)

    def add_odometry(self, message: Any, topic: str, record: Any) -> None:
        """An odometry message: the base frame's pose (a message without a child frame is the base's)."""
        child = _strip_frame(_get(message, "child_frame_id", ""))
        if not child or child == self.base_name:
            pose = _get(_get(message, "pose"), "pose")
            self.odom_pose = _planar_pose(_checked_rigid(
                _get(pose, "orientation"), _get(pose, "position"),
                f"{self.name}, {topic}, message {record.sequence}: the odometry pose"))

    def add_range(self, kind: str, schema: Any, topic: str, record: Any, message: Any
                  ) -> tuple[Scan, Pose | None, Pose | None]:
        """A range message: decoded, its evidence checked, mounted; with its /tf and odometry poses."""
        where = f"{self.name}, topic {topic}, message {record.sequence or self.count}"
        try:
            if kind in DEPTH_KINDS:
                decoded = self._depth(kind, message, where)
            else:
                decoded = _DECODERS[kind](message, self.options, where)
        except (AttributeError, TypeError, KeyError, ValueError) as exc:
            if isinstance(exc, InputError):
                raise
            raise InputError(f"{where}: malformed {schema.name} message ({exc!r})") from None
        self.count += 1
        self.dropped_nan += decoded.dropped_nan
        points, values = decoded.points, decoded.evidence
        bad = ~np.isfinite(values) | (values < 0.0) | (values > 1.0)
        if bad.any():
            if not self.options.skip_invalid:
                i = int(np.argmax(bad))
                raise InputError(f"{where}: evidence value {float(values[i])!r} is not in [0, 1] "
                                 "(pass skip_invalid=True to drop such points)")
            self.options.skipped_invalid += int(bad.sum())
            points, values = points[~bad], values[~bad]
        mounting = decoded.origin.then(self._mounting(decoded.frame) or _IDENTITY)
        if not np.allclose(mounting.rotation, np.eye(3)):
            points = points @ mounting.rotation.T
        at_origin = ~(np.abs(points) > 0.0).any(axis=1)
        if at_origin.any():
            self.dropped_origin += int(at_origin.sum())
            points, values = points[~at_origin], values[~at_origin]
        stamp = decoded.stamp if decoded.stamp else record.log_time * 1e-9
        scan = Scan(points, values, None, stamp, topic)
        tf_pose = _compose_sensor(self.tf_pose, mounting.translation)
        odom_pose = _compose_sensor(self.odom_pose, mounting.translation)
        if self.keep:
            self.scans.append(scan)
            self.tf_poses.append(tf_pose)
            self.odom_poses.append(odom_pose)
        return scan, tf_pose, odom_pose

    def _depth(self, kind: str, message: Any, where: str) -> _Decoded:
        """A depth image: optical-frame points; a camera without a mounting is taken as level."""
        settings = self.options.depth
        assert settings is not None  # set up for every log with a depth channel
        points, evidence, frame, stamp = decode_depth(kind, message, settings, self.options.no_return_range, where)
        decoded = _Decoded(points, evidence, frame, stamp, _IDENTITY)
        if self._mounting(frame) is None:
            from occtool.io.depth import OPTICAL_TO_BODY, floor_mounting

            if frame not in settings.from_floor:
                settings.from_floor[frame] = floor_mounting(points[evidence > 0.0])
            found = settings.from_floor[frame]
            if found is None:
                decoded.origin = _Rigid(OPTICAL_TO_BODY, np.zeros(3))
            else:
                decoded.origin = _Rigid(found[0], np.array([0.0, 0.0, found[1]]))
            self.unmounted.discard(frame)
            settings.level_frames.add(frame)
        return decoded

    def _mounting(self, message_frame: str) -> _Rigid | None:
        """The message frame (or ``sensor_frame``) into the base frame, from ``/tf_static``."""
        frame = _strip_frame(self.sensor_frame) if self.sensor_frame else message_frame
        if frame not in self.mountings:
            self.mountings[frame] = self.frames.lookup(frame, self.base_name) if frame else None
            # A message without a frame id is taken to be in the base frame already.
            if self.mountings[frame] is None and frame and frame != self.base_name:
                self.unmounted.add(frame)
        return self.mountings[frame]

    def posed(self) -> tuple[list[Scan], list[str]]:
        """The scans with their poses, from ``/tf`` if any scan has one, else odometry, and notes saying which."""
        notes: list[str] = []
        poses: list[Pose | None]
        if any(p is not None for p in self.tf_poses):
            poses, pose_source = self.tf_poses, f"/tf (parent of {self.base_name})"
        elif any(p is not None for p in self.odom_poses):
            poses, pose_source = self.odom_poses, "odometry"
        else:
            poses, pose_source = [None] * len(self.scans), None
        if pose_source:
            notes += _pose_notes(pose_source, sum(p is None for p in poses))
        return [Scan(s.points, s.evidence, p, s.stamp, s.source) for s, p in zip(self.scans, poses)], notes


def _pose_notes(pose_source: str, missing: int) -> list[str]:
    notes = [f"poses from {pose_source}"]
    if missing:
        notes.append(f"{missing} scan(s) before the first pose joined the first position")
    return notes


def _reading_notes(scans: _Scans) -> list[str]:
    """What the reading assumed or dropped: mountings, constant evidence, beams and points."""
    options = scans.options
    evidence, no_return_range = options.settings.evidence, options.settings.no_return_range
    notes: list[str] = []
    if scans.unmounted:
        notes.append(Note.warn(
            f"no /tf_static transform from {', '.join(sorted(scans.unmounted))} to {scans.base_name}: "
            "points kept in the sensor frame's axes"
        ))
    if options.constant_for:
        value = DEFAULT_CONSTANT_EVIDENCE if evidence is None else evidence
        notes.append(f"constant evidence {value} (evidence=) for {' and '.join(sorted(options.constant_for))}")
    if options.no_return:
        if no_return_range is None:
            notes.append(f"dropped {options.no_return} of {options.beams} laser beam(s) with no return "
                         "(+inf or above range_max)")
        else:
            reach = sorted(options.free_reach)
            at = f"{reach[0]:g} m" if len(reach) == 1 else f"{reach[0]:g} to {reach[-1]:g} m"
            notes.append(f"kept {options.no_return} of {options.beams} laser beam(s) with no return "
                         f"(+inf or above range_max) as free rays at {at} with evidence 0 "
                         f"(no_return_range={no_return_range:g})")
    if options.invalid_beams:
        notes.append(Note.warn(f"dropped {options.invalid_beams} of {options.beams} invalid laser beam(s) "
                               "(NaN, -inf, <= 0 or below range_min)"))
    if scans.dropped_nan:
        notes.append(f"dropped {scans.dropped_nan} point(s) with NaN coordinates (no return)")
    if scans.dropped_origin:
        notes.append(f"dropped {scans.dropped_origin} point(s) at the sensor origin (no return)")
    if options.skipped_invalid:
        notes.append(Note.warn(f"skipped {options.skipped_invalid} point(s) with evidence outside [0, 1] or NaN"))
    if options.depth is not None:
        notes += depth_notes(options.depth, no_return_range)
    return notes


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



class McapScans:
    """The range messages of an MCAP file (or a ROS bag, through ``opener``) as scans, read
    message by message: an iterable of :class:`~occtool.io.positions.Scan` holding one
    message at a time, for :func:`occtool.io.iter_positions`.

    Whether the poses come from ``/tf`` or odometry depends on the whole file (``/tf`` if
    any scan has one), so :meth:`prepare` reads every message once first, keeping only
    counts: every error :func:`read_mcap` raises is raised there, before the first scan.
    Each iteration then reads the file again. occtool's own feature channel is not
    streamed (its messages are sorted by position): :meth:`prepare` says so and the caller
    reads it with :func:`read_mcap`. Parameters are those of :func:`read_mcap`; ``notes``
    is complete after a full iteration.
    """

    def __init__(self, path: str | os.PathLike[str], options: ReadOptions | None = None, *,
                 opener: Callable[[str | os.PathLike[str]], Any] | None = None, **keywords: Any) -> None:
        self.path = path
        self.name = str(path)
        self.settings = as_read_options(options, **keywords)
        self.opener = opener or _Reader
        self.notes: list[str] = []
        self.own_channel = False
        self._pose_source: str | None = None
        self._notes: list[str] | None = None

    def _messages(self) -> Iterator[tuple[Scan, Pose | None, Pose | None]]:
        """Each range message's scan with its /tf and odometry poses (the loop of read_mcap)."""
        name = self.name
        with self.opener(self.path) as reader:
            rows = _channel_rows(reader, self.settings.topics)
            chosen = _choose_channels(rows, self.settings.topics, name)
            self.chosen_topics = [r.topic for r in chosen]
            kinds = {r.topic: r.kind for r in chosen}
            if any(k == OCCTOOL for k in kinds.values()):
                if len(chosen) > 1:
                    raise InputError(f"{name}: read occtool's features channel on its own, not with other topics")
                self.own_channel = True
                return
            static_topics = [r.topic for r in rows if r.kind == TF and r.topic.endswith("tf_static")]
            tf_topics = [r.topic for r in rows if r.kind == TF and r.topic not in static_topics]
            odom_topics = [r.topic for r in rows if r.kind == ODOMETRY]
            frames = _static_frames(reader, static_topics, name)
            base = _strip_frame(self.settings.base_frame) if self.settings.base_frame else None
            if (base is not None and base not in frames and not tf_topics and not odom_topics
                    and self.settings.sensor_frame is None):
                raise InputError(f"{name}: base frame '{base}' appears in no transform of the log")
            options = _Options(self.settings)
            options.depth = _depth_settings(reader, rows, kinds, name, self.settings)
            scans = self.state = _Scans(name, base or "base_link", self.settings.sensor_frame, frames, options,
                                        keep=False)
            for schema, channel, record, message in reader.messages(self.chosen_topics + tf_topics + odom_topics):
                if channel.topic in tf_topics:
                    scans.add_transforms(message, channel.topic)
                elif channel.topic in odom_topics:
                    scans.add_odometry(message, channel.topic, record)
                else:
                    yield scans.add_range(kinds[channel.topic], schema, channel.topic, record, message)  # type: ignore[arg-type]

    def prepare(self) -> bool:
        """Read the file once (counts only); ``False`` for occtool's own channel, which is not streamed."""
        if self._notes is not None:
            return True
        tf_missing = odom_missing = count = 0
        with_points = False
        for scan, tf_pose, odom_pose in self._messages():
            count += 1
            tf_missing += tf_pose is None
            odom_missing += odom_pose is None
            with_points = with_points or scan.points.shape[0] > 0
        if self.own_channel:
            return False
        if count == 0:
            raise InputError(f"{self.name} holds no messages on {', '.join(self.chosen_topics)}")
        notes: list[str] = []
        if tf_missing < count:
            self._pose_source = "tf"
            notes += _pose_notes(f"/tf (parent of {self.state.base_name})", tf_missing)
        elif odom_missing < count:
            self._pose_source = "odometry"
            notes += _pose_notes("odometry", odom_missing)
        notes += _reading_notes(self.state)
        if not with_points:
            raise InputError(f"{self.name}: the {count} range message(s) hold no valid points")
        self._notes = notes
        return True

    def __iter__(self) -> Iterator[Scan]:
        if not self.prepare():
            raise InputError(f"{self.name}: occtool's own channel is read whole (read_mcap), not streamed")
        self.notes.clear()
        for scan, tf_pose, odom_pose in self._messages():
            pose = tf_pose if self._pose_source == "tf" else odom_pose if self._pose_source == "odometry" else None
            yield Scan(scan.points, scan.evidence, pose, scan.stamp, scan.source)
        self.notes.extend(self._notes or [])


options_as_keywords(read_mcap)
options_as_keywords(McapScans)
