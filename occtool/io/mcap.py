"""Read range data from MCAP recordings, and write occtool's own MCAP channel.

Supported range channels (schema name, message encoding):

* ``sensor_msgs/msg/PointCloud2`` (ROS 2, CDR): fields decoded from the message's
  ``fields``/``point_step``/``row_step``, evidence from a named field or a constant;
  points with a NaN coordinate are dropped.
* ``sensor_msgs/msg/LaserScan`` (ROS 2, CDR): each valid beam (finite and within
  ``[range_min, range_max]``) is a point in the scan plane, ``z = 0``. Following REP 117,
  a beam at +inf or above ``range_max`` returned nothing within range: it is dropped, or
  with ``no_return_range`` R kept as a *free ray*, a feature at ``min(R, range_max)``
  with evidence 0; -inf, NaN and ranges below ``range_min`` are invalid and dropped.
* ``foxglove.PointCloud`` and ``foxglove.LaserScan``, JSON or protobuf (a foxglove scan
  has no range limits: +inf is its no-return value, kept at R as a free ray).
* ``occtool.RangeFeatures`` (JSON): occtool's own channel, one message per position.

Poses come from ``/tf`` (``tf2_msgs/msg/TFMessage`` or ``foxglove.FrameTransform(s)``,
the transform whose child is the base frame), else ``nav_msgs/msg/Odometry``; each
scan takes the latest pose at or before its time. ``/tf_static`` gives the sensor's
mounting on the base: points are rotated into the base frame's axes but stay centred
at the sensor, as occtool's features are; the sensor's offset goes into the pose.

The file is streamed message by message through :mod:`mcap`'s reader, never loaded
whole; a corrupt or truncated file is an :class:`~occtool.errors.InputError`.
"""

from __future__ import annotations

import base64
import json
import logging
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Features, Pose, Position, RangeLog
from occtool.io.positions import DEFAULT_POSITION_TOLERANCE, Scan, build_log

logger = logging.getLogger(__name__)

OCCTOOL_SCHEMA_NAME = "occtool.RangeFeatures"
OCCTOOL_TOPIC = "/occtool/features"
OCCTOOL_FORMAT_VERSION = 1
DEFAULT_CONSTANT_EVIDENCE = 0.9

OCCTOOL_JSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": OCCTOOL_SCHEMA_NAME,
    "description": (
        "Range features of one robot position: points in the sensor-centred robot frame "
        "(REP-103, metres) with evidence in [0, 1], and the position's world pose."
    ),
    "type": "object",
    "required": ["version", "position", "count", "points", "evidence"],
    "properties": {
        "version": {"type": "integer", "const": OCCTOOL_FORMAT_VERSION},
        "position": {"type": "integer", "minimum": 0},
        "stamp": {"type": ["number", "null"], "description": "seconds"},
        "frame": {"type": "string"},
        "pose": {
            "type": ["object", "null"],
            "properties": {k: {"type": "number"} for k in ("x", "y", "z", "yaw")},
        },
        "count": {"type": "integer", "minimum": 0},
        "points": {
            "type": "string",
            "contentEncoding": "base64",
            "description": "count*3 float64 little-endian values x0 y0 z0 x1 ...",
        },
        "evidence": {
            "type": "string",
            "contentEncoding": "base64",
            "description": "count float64 little-endian values",
        },
    },
}

# Kinds of channel occtool reads.
POINTCLOUD2 = "PointCloud2"
LASERSCAN = "LaserScan"
FOXGLOVE_POINTCLOUD = "foxglove PointCloud"
FOXGLOVE_LASERSCAN = "foxglove LaserScan"
OCCTOOL = "occtool features"
RANGE_KINDS = (POINTCLOUD2, LASERSCAN, FOXGLOVE_POINTCLOUD, FOXGLOVE_LASERSCAN, OCCTOOL)
TF = "transforms"
ODOMETRY = "odometry"

_SCHEMA_KINDS = {
    ("sensor_msgs/msg/PointCloud2", "cdr"): POINTCLOUD2,
    ("sensor_msgs/msg/LaserScan", "cdr"): LASERSCAN,
    ("foxglove.PointCloud", "json"): FOXGLOVE_POINTCLOUD,
    ("foxglove.PointCloud", "protobuf"): FOXGLOVE_POINTCLOUD,
    ("foxglove.LaserScan", "json"): FOXGLOVE_LASERSCAN,
    ("foxglove.LaserScan", "protobuf"): FOXGLOVE_LASERSCAN,
    (OCCTOOL_SCHEMA_NAME, "json"): OCCTOOL,
    ("tf2_msgs/msg/TFMessage", "cdr"): TF,
    ("foxglove.FrameTransform", "json"): TF,
    ("foxglove.FrameTransform", "protobuf"): TF,
    ("foxglove.FrameTransforms", "json"): TF,
    ("foxglove.FrameTransforms", "protobuf"): TF,
    ("nav_msgs/msg/Odometry", "cdr"): ODOMETRY,
}

# ROS sensor_msgs/PointField datatypes and foxglove PackedElementField numeric types.
_ROS_DATATYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
_FOXGLOVE_TYPES = {1: "u1", 2: "i1", 3: "u2", 4: "i2", 5: "u4", 6: "i4", 7: "f4", 8: "f8"}
_FOXGLOVE_TYPE_NAMES = {"UINT8": 1, "INT8": 2, "UINT16": 3, "INT16": 4, "UINT32": 5, "INT32": 6, "FLOAT32": 7, "FLOAT64": 8}


def channel_kind(schema_name: str, message_encoding: str) -> str | None:
    """What occtool makes of a channel: one of the kinds above, or ``None``."""
    return _SCHEMA_KINDS.get((schema_name, message_encoding.lower()))


# --- decoding helpers ---------------------------------------------------------------------


class _JsonDecoderFactory:
    """Decode ``json`` messages (the core mcap library has no JSON decoder)."""

    def decoder_for(self, message_encoding: str, schema: Any) -> Callable[[bytes], Any] | None:
        if message_encoding != "json":
            return None
        return lambda data: json.loads(data)


def _decoder_factories() -> list[Any]:
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

    factories: list[Any] = [Ros2DecoderFactory(), _JsonDecoderFactory()]
    try:
        from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
    except ImportError:  # the protobuf extra is optional; its channels are reported unreadable
        pass
    else:
        factories.append(ProtobufDecoderFactory())
    return factories


def _protobuf_available() -> bool:
    try:
        import mcap_protobuf.decoder  # noqa: F401
    except ImportError:
        return False
    return True


def _get(message: Any, name: str, default: Any = None) -> Any:
    """A field of a decoded message: a dict (JSON) or an object (CDR, protobuf)."""
    if isinstance(message, dict):
        return message.get(name, default)
    return getattr(message, name, default)


def _stamp_seconds(stamp: Any) -> float | None:
    """Seconds from a ROS ``Time`` (sec/nanosec), a foxglove JSON time or a protobuf Timestamp."""
    if stamp is None:
        return None
    if isinstance(stamp, (int, float)):
        return float(stamp)
    sec = _get(stamp, "sec", None)
    if sec is None:
        sec = _get(stamp, "seconds", 0)
    nsec = _get(stamp, "nanosec", None)
    if nsec is None:
        nsec = _get(stamp, "nsec", None)
    if nsec is None:
        nsec = _get(stamp, "nanos", 0)
    return float(sec) + float(nsec) * 1e-9


def _rotation_from_quaternion(q: Any) -> NDArray[np.float64]:
    if q is None:
        return np.eye(3)
    x, y, z, w = (float(_get(q, k, 0.0 if k != "w" else 1.0)) for k in ("x", "y", "z", "w"))
    if not np.isfinite([x, y, z, w]).all():
        raise InputError(f"the orientation quaternion ({x}, {y}, {z}, {w}) is not finite")
    norm = np.sqrt(x * x + y * y + z * z + w * w)
    if norm == 0.0:
        return np.eye(3)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _vector(v: Any) -> NDArray[np.float64]:
    if v is None:
        return np.zeros(3)
    return np.array([float(_get(v, k, 0.0)) for k in ("x", "y", "z")])


def _strip_frame(frame: str | None) -> str:
    return (frame or "").lstrip("/")


@dataclass
class _Rigid:
    """A rigid transform ``p' = R p + t``."""

    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]

    def then(self, outer: _Rigid) -> _Rigid:
        """This transform followed by ``outer``."""
        return _Rigid(outer.rotation @ self.rotation, outer.rotation @ self.translation + outer.translation)

    def inverse(self) -> _Rigid:
        return _Rigid(self.rotation.T, -self.rotation.T @ self.translation)


_IDENTITY = _Rigid(np.eye(3), np.zeros(3))


def _checked_rigid(rotation: Any, translation: Any, what: str) -> _Rigid:
    """The transform of a quaternion and a translation, refusing ones that are no rigid motion."""
    q = tuple(float(_get(rotation, k, 0.0 if k != "w" else 1.0)) for k in ("x", "y", "z", "w")) if rotation is not None else (0.0, 0.0, 0.0, 1.0)
    t = _vector(translation)
    if not (np.isfinite(q).all() and np.isfinite(t).all()):
        raise InputError(f"{what} is not finite (rotation {q}, translation {tuple(float(v) for v in t)})")
    if not any(q):
        raise InputError(f"{what} has the zero quaternion (0, 0, 0, 0), which is no rotation")
    return _Rigid(_rotation_from_quaternion(rotation), t)


def _transforms_of(message: Any, topic: str = "tf") -> list[tuple[str, str, _Rigid]]:
    """``(parent, child, child-to-parent transform)`` for each transform in a TF message.

    Raises
    ------
    InputError
        For a transform with a NaN or infinite value or a zero quaternion.
    """
    out = []
    if _get(message, "transforms") is not None and _get(message, "parent_frame_id") is None:
        items = list(_get(message, "transforms"))
    else:
        items = [message]
    for item in items:
        if _get(item, "transform") is not None:  # geometry_msgs/TransformStamped
            parent = _get(_get(item, "header"), "frame_id", "")
            child = _get(item, "child_frame_id", "")
            transform = _get(item, "transform")
            rotation, translation = _get(transform, "rotation"), _get(transform, "translation")
        else:  # foxglove.FrameTransform
            parent = _get(item, "parent_frame_id", "")
            child = _get(item, "child_frame_id", "")
            rotation, translation = _get(item, "rotation"), _get(item, "translation")
        parent, child = _strip_frame(parent), _strip_frame(child)
        rigid = _checked_rigid(rotation, translation, f"{topic}: the transform {parent} -> {child}")
        out.append((parent, child, rigid))
    return out


class _FrameTree:
    """Static transforms, looked up between any two connected frames."""

    def __init__(self) -> None:
        self.parent: dict[str, tuple[str, _Rigid]] = {}

    def add(self, parent: str, child: str, rigid: _Rigid) -> None:
        self.parent[child] = (parent, rigid)

    def _to_root(self, frame: str) -> tuple[str, _Rigid]:
        rigid = _IDENTITY
        seen = {frame}
        while frame in self.parent:
            frame, step = self.parent[frame]
            rigid = rigid.then(step)
            if frame in seen:
                raise InputError(f"/tf_static has a loop through frame '{frame}'")
            seen.add(frame)
        return frame, rigid

    def lookup(self, source: str, target: str) -> _Rigid | None:
        """The transform taking points in ``source`` into ``target``, or ``None``."""
        if source == target:
            return _IDENTITY
        root_s, source_to_root = self._to_root(source)
        root_t, target_to_root = self._to_root(target)
        if root_s != root_t:
            return None
        return source_to_root.then(target_to_root.inverse())

    def __contains__(self, frame: str) -> bool:
        return frame in self.parent or any(p == frame for p, _ in self.parent.values())


# --- per-message decoding ------------------------------------------------------------------


@dataclass
class _Decoded:
    """One range message: sensor-frame points with the pose of the sensor in ``frame``."""

    points: NDArray[np.float64]
    evidence: NDArray[np.float64]
    frame: str
    stamp: float | None
    origin: _Rigid  # the cloud/scan origin within `frame` (foxglove messages carry one)
    dropped_nan: int = 0


class _Options:
    def __init__(self, evidence_field: str, evidence: float | None, use_intensities: bool, skip_invalid: bool,
                 no_return_range: float | None = None):
        self.evidence_field = evidence_field
        self.evidence = evidence
        self.use_intensities = use_intensities
        self.skip_invalid = skip_invalid
        self.no_return_range = no_return_range
        self.constant_for: set[str] = set()
        self.skipped_invalid = 0
        # Laser beams: all of them, the no-return ones (dropped, or kept as free rays out to
        # the ranges in free_reach) and the invalid ones (NaN, -inf, below range_min).
        self.beams = 0
        self.no_return = 0
        self.invalid_beams = 0
        self.free_reach: set[float] = set()


def _structured_points(
    data: bytes | bytearray | memoryview,
    fields: list[tuple[str, int, str, int]],
    stride: int,
    count: int,
    big_endian: bool,
    where: str,
) -> dict[str, NDArray[np.float64]]:
    """Decode named scalar fields of ``count`` packed records of ``stride`` bytes."""
    raw = np.frombuffer(data, dtype=np.uint8)
    if stride <= 0:
        raise InputError(f"{where}: point step must be positive, got {stride}")
    if raw.size < count * stride:
        raise InputError(f"{where}: {raw.size} data bytes hold fewer than {count} points of {stride} bytes")
    order = ">" if big_endian else "<"
    names, formats, offsets = [], [], []
    for name, offset, code, _ in fields:
        if name in names:
            continue
        size = np.dtype(code).itemsize
        if offset < 0 or offset + size > stride:
            raise InputError(f"{where}: field '{name}' at offset {offset} lies outside the {stride}-byte point")
        names.append(name)
        formats.append(order + code)
        offsets.append(offset)
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": stride})
    records = raw[: count * stride].view(dtype)
    return {name: records[name].astype(np.float64) for name in names}


def _cloud_to_arrays(
    columns: dict[str, NDArray[np.float64]], options: _Options, where: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    missing = [c for c in ("x", "y", "z") if c not in columns]
    if missing:
        raise InputError(f"{where}: the point cloud has no field {', '.join(missing)} (fields: {', '.join(columns)})")
    points = np.column_stack([columns["x"], columns["y"], columns["z"]])
    if options.evidence_field in columns:
        evidence = columns[options.evidence_field]
    else:
        options.constant_for.add(f"point clouds without a field '{options.evidence_field}'")
        evidence = np.full(points.shape[0], DEFAULT_CONSTANT_EVIDENCE if options.evidence is None else options.evidence)
    # NaN coordinates are ROS's way of saying "no return" in a dense cloud: drop them.
    finite = np.isfinite(points).all(axis=1)
    dropped = int((~finite).sum())
    points, evidence = points[finite], evidence[finite]
    return points, evidence, dropped


def _decode_pointcloud2(message: Any, options: _Options, where: str) -> _Decoded:
    fields = []
    for f in _get(message, "fields"):
        code = _ROS_DATATYPES.get(int(f.datatype))
        if code is None:
            raise InputError(f"{where}: field '{f.name}' has unknown datatype {f.datatype}")
        fields.append((f.name, int(f.offset), code, int(f.count)))
    width, height = int(message.width), int(message.height)
    step, row_step = int(message.point_step), int(message.row_step)
    data = message.data
    if not isinstance(data, (bytes, bytearray, memoryview)):
        data = bytes(bytearray(data))
    if height > 1 and row_step != width * step:
        # Rows may be padded: take each row's first width*step bytes.
        raw = np.frombuffer(data, dtype=np.uint8)
        if raw.size < height * row_step:
            raise InputError(f"{where}: {raw.size} data bytes hold fewer than {height} rows of {row_step} bytes")
        data = raw[: height * row_step].reshape(height, row_step)[:, : width * step].tobytes()
    columns = _structured_points(data, fields, step, width * height, bool(message.is_bigendian), where)
    points, evidence, dropped = _cloud_to_arrays(columns, options, where)
    header = message.header
    return _Decoded(points, evidence, _strip_frame(header.frame_id), _stamp_seconds(header.stamp), _IDENTITY, dropped)


def _scan_evidence(intensities: Any, count: int, valid: NDArray[np.bool_], options: _Options, where: str) -> NDArray[np.float64]:
    if options.use_intensities:
        values = np.asarray(intensities if intensities is not None else [], dtype=np.float64)
        if values.size != count:
            raise InputError(f"{where}: --intensities given but the scan has {values.size} intensities for {count} ranges")
        values = values[valid]
        finite = values[np.isfinite(values)]
        top = float(finite.max()) if finite.size else 0.0
        # Intensities already in [0, 1] are taken as evidence; others are scaled by the scan's largest.
        if top > 1.0:
            values = values / top
        return values
    options.constant_for.add("laser scans (no --intensities)")
    return np.full(int(valid.sum()), DEFAULT_CONSTANT_EVIDENCE if options.evidence is None else options.evidence)


def _scan_points(
    ranges: NDArray[np.float64], angles: NDArray[np.float64], valid: NDArray[np.bool_], missing: NDArray[np.bool_],
    reach: float, evidence: NDArray[np.float64], options: _Options,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Points and evidence of a laser scan's valid beams (``evidence`` is theirs) and, with
    ``no_return_range``, of its no-return beams as free rays at ``reach`` with evidence 0,
    in beam order; the beams are counted for the notes."""
    options.beams += int(ranges.size)
    options.no_return += int(missing.sum())
    options.invalid_beams += int(ranges.size - valid.sum() - missing.sum())
    if options.no_return_range is None or not missing.any():
        r, a, values = ranges[valid], angles[valid], evidence
    else:
        options.free_reach.add(reach)
        kept = valid | missing
        all_values = np.zeros(ranges.size)
        all_values[valid] = evidence
        r, a, values = np.where(missing, reach, ranges)[kept], angles[kept], all_values[kept]
    return np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros(r.size)]), values


def _check_finite_fields(message: Any, names: tuple[str, ...], where: str) -> None:
    """A laser scan's geometry must be numbers: a NaN angle puts every beam nowhere."""
    for field_name in names:
        value = float(_get(message, field_name, 0.0))
        if not np.isfinite(value) and not (field_name == "range_max" and value == np.inf):
            raise InputError(f"{where}: the scan's {field_name} is {value}, not a finite number")


def _decode_laserscan(message: Any, options: _Options, where: str) -> _Decoded:
    ranges = np.asarray(message.ranges, dtype=np.float64)
    _check_finite_fields(message, ("angle_min", "angle_increment", "range_min", "range_max"), where)
    angles = float(message.angle_min) + float(message.angle_increment) * np.arange(ranges.size)
    range_min, range_max = float(message.range_min), float(message.range_max)
    # REP 117: +inf is "no object within range" (as is a value above range_max); -inf
    # (too close), NaN (erroneous) and values below range_min are invalid and dropped.
    top = range_max if range_max > 0.0 else np.inf  # a scan without a usable range_max: +inf only
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(ranges) & (ranges >= range_min) & (ranges <= range_max) & (ranges > 0)
        missing = np.isposinf(ranges) | (np.isfinite(ranges) & (ranges > top))
    intensities = message.intensities  # a list (mcap-ros2) or a numpy array (rosbags): no truth value
    evidence = _scan_evidence(intensities if intensities is not None and len(intensities) else None, ranges.size,
                              valid, options, where)
    reach = min(options.no_return_range, top) if options.no_return_range is not None else np.inf
    points, evidence = _scan_points(ranges, angles, valid, missing, reach, evidence, options)  # type: ignore[arg-type]  # angles are float64
    header = message.header
    return _Decoded(points, evidence, _strip_frame(header.frame_id), _stamp_seconds(header.stamp), _IDENTITY)


def _foxglove_origin(message: Any) -> _Rigid:
    pose = _get(message, "pose")
    if pose is None:
        return _IDENTITY
    return _Rigid(_rotation_from_quaternion(_get(pose, "orientation")), _vector(_get(pose, "position")))


def _decode_foxglove_pointcloud(message: Any, options: _Options, where: str) -> _Decoded:
    data = _get(message, "data", b"")
    if isinstance(data, str):
        try:
            data = base64.b64decode(data, validate=True)
        except ValueError as exc:
            raise InputError(f"{where}: point data is not valid base64 ({exc})") from None
    fields = []
    for f in _get(message, "fields", []) or []:
        kind = _get(f, "type")
        if isinstance(kind, str):
            kind = _FOXGLOVE_TYPE_NAMES.get(kind.upper(), 0)
        code = _FOXGLOVE_TYPES.get(int(kind or 0))
        if code is None:
            raise InputError(f"{where}: field '{_get(f, 'name')}' has unknown numeric type {kind}")
        fields.append((_get(f, "name"), int(_get(f, "offset", 0)), code, 1))
    stride = int(_get(message, "point_stride", 0))
    count = len(data) // stride if stride > 0 else 0
    columns = _structured_points(data, fields, stride, count, False, where)
    if "z" not in columns and "x" in columns:
        columns["z"] = np.zeros_like(columns["x"])
    points, evidence, dropped = _cloud_to_arrays(columns, options, where)
    return _Decoded(points, evidence, _strip_frame(_get(message, "frame_id")), _stamp_seconds(_get(message, "timestamp")),
                    _foxglove_origin(message), dropped)


def _decode_foxglove_laserscan(message: Any, options: _Options, where: str) -> _Decoded:
    ranges = np.asarray(_get(message, "ranges", []) or [], dtype=np.float64)
    _check_finite_fields(message, ("start_angle", "end_angle"), where)
    start, end = float(_get(message, "start_angle", 0.0)), float(_get(message, "end_angle", 0.0))
    # foxglove spaces the beams evenly from start_angle to end_angle, both included.
    angles = np.linspace(start, end, ranges.size) if ranges.size > 1 else np.full(ranges.size, start)
    valid = np.isfinite(ranges) & (ranges > 0)
    # foxglove.LaserScan has no range limits: +inf is the only "no return".
    missing = np.isposinf(ranges)
    intensities = _get(message, "intensities")
    evidence = _scan_evidence(list(intensities) if intensities is not None else None, ranges.size, valid, options, where)
    reach = options.no_return_range if options.no_return_range is not None else np.inf
    points, evidence = _scan_points(ranges, angles, valid, missing, reach, evidence, options)
    return _Decoded(points, evidence, _strip_frame(_get(message, "frame_id")), _stamp_seconds(_get(message, "timestamp")),
                    _foxglove_origin(message))


_DECODERS = {
    POINTCLOUD2: _decode_pointcloud2,
    LASERSCAN: _decode_laserscan,
    FOXGLOVE_POINTCLOUD: _decode_foxglove_pointcloud,
    FOXGLOVE_LASERSCAN: _decode_foxglove_laserscan,
}


def _decode_occtool(message: Any, where: str) -> tuple[int, NDArray[np.float64], NDArray[np.float64], Pose | None, float | None]:
    try:
        version = int(message.get("version", 0))
        if version > OCCTOOL_FORMAT_VERSION:
            raise InputError(f"{where}: written by a newer occtool (format version {version})")
        count = int(message["count"])
        points = np.frombuffer(base64.b64decode(message["points"], validate=True), dtype="<f8")
        evidence = np.frombuffer(base64.b64decode(message["evidence"], validate=True), dtype="<f8")
        pose = Pose.from_dict(message["pose"]) if message.get("pose") else None
        stamp = message.get("stamp")
        position = int(message.get("position", 0))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{where}: malformed occtool features message ({exc!r})") from None
    if points.size != 3 * count or evidence.size != count:
        raise InputError(f"{where}: message says {count} features but holds {points.size // 3} points and {evidence.size} evidence values")
    return position, points.reshape(count, 3).astype(np.float64), evidence.astype(np.float64), pose, (None if stamp is None else float(stamp))


# --- reading --------------------------------------------------------------------------------


@dataclass
class ChannelRow:
    """One channel of an MCAP file as ``occtool info`` shows it."""

    topic: str
    schema: str
    encoding: str
    messages: int | None
    kind: str | None
    support: str


def _mcap_errors() -> tuple[type[BaseException], ...]:
    import struct
    import zlib

    from mcap.exceptions import McapError

    errors: list[type[BaseException]] = [McapError, struct.error, EOFError, zlib.error, UnicodeDecodeError, json.JSONDecodeError]
    try:
        from google.protobuf.message import DecodeError

        errors.append(DecodeError)
    except ImportError:
        pass
    try:  # a corrupt zstd chunk
        from zstandard import ZstdError

        errors.append(ZstdError)
    except ImportError:
        pass
    # A damaged chunk or index also surfaces as a plain error inside the mcap library: a
    # channel id missing from the summary (KeyError), a corrupt lz4 frame (RuntimeError).
    # A corrupt record length can ask for more memory than there is (MemoryError).
    errors += [KeyError, IndexError, ValueError, OverflowError, RuntimeError, MemoryError]
    return tuple(errors)


class _Reader:
    """An open MCAP file with its summary, turning library errors into InputError."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = str(path)
        self.handle = open(path, "rb")

    def __enter__(self) -> _Reader:
        from mcap.reader import make_reader

        try:
            self.reader = make_reader(self.handle, validate_crcs=True, decoder_factories=_decoder_factories())
            self.reader.get_header()
            self.summary = self.reader.get_summary()
        except (*_mcap_errors(), OSError) as exc:  # type: ignore[misc]  # OSError: a seek to a corrupt summary offset
            self.handle.close()
            raise self.corrupt(exc) from None
        return self

    def __exit__(self, *exc: object) -> None:
        self.handle.close()

    def corrupt(self, exc: BaseException) -> InputError:
        detail = str(exc) or type(exc).__name__
        if isinstance(exc, MemoryError):
            detail = "a record's length exceeds the memory available"
        return InputError(f"{self.path} is not a readable MCAP file (corrupt or truncated): {detail}")

    def channels(self) -> list[tuple[int, str, str, str, int | None]]:
        """``(id, topic, schema, encoding, message count)`` of each channel."""
        if self.summary is None:
            return self._scan_channels()
        counts = self.summary.statistics.channel_message_counts if self.summary.statistics else {}
        out = []
        for cid, channel in sorted(self.summary.channels.items()):
            schema = self.summary.schemas.get(channel.schema_id)
            out.append((cid, channel.topic, schema.name if schema else "", channel.message_encoding, counts.get(cid)))
        return out

    def _scan_channels(self) -> list[tuple[int, str, str, str, int | None]]:
        """Without a summary section, list channels by streaming the file once."""
        from mcap.reader import NonSeekingReader

        counts: dict[int, list[Any]] = {}
        with open(self.path, "rb") as handle:
            try:
                for schema, channel, _ in NonSeekingReader(handle, validate_crcs=True).iter_messages():
                    entry = counts.setdefault(channel.id, [channel.topic, schema.name if schema else "", channel.message_encoding, 0])
                    entry[3] += 1
            except _mcap_errors() as exc:
                raise self.corrupt(exc) from None
        return [(cid, *entry) for cid, entry in sorted(counts.items())]

    def messages(self, topics: Sequence[str]) -> Iterator[tuple[Any, Any, Any, Any]]:
        try:
            yield from self.reader.iter_decoded_messages(topics=list(topics), log_time_order=True)
        except InputError:
            raise
        except _mcap_errors() as exc:
            raise self.corrupt(exc) from None


def describe_channels(path: str | os.PathLike[str]) -> tuple[list[ChannelRow], dict[str, str]]:
    """The channels of an MCAP file and what occtool can read, from its summary.

    Returns
    -------
    rows, extra
        One :class:`ChannelRow` per channel, and further facts (message count,
        duration) to show.
    """
    rows = []
    protobuf = _protobuf_available()
    with _Reader(path) as reader:
        for _, topic, schema, encoding, count in reader.channels():
            kind = channel_kind(schema, encoding)
            if kind in RANGE_KINDS:
                support = "yes: range data"
            elif kind == TF:
                support = "yes: static frames" if topic.endswith("tf_static") else "yes: poses"
            elif kind == ODOMETRY:
                support = "yes: poses"
            else:
                support = "no"
            if encoding == "protobuf" and kind is not None and not protobuf:
                support = "needs occtool[protobuf]"
            rows.append(ChannelRow(topic, schema, encoding, count, kind, support))
        extra: dict[str, str] = {}
        stats = reader.summary.statistics if reader.summary else None
        if stats is not None:
            extra["messages"] = f"{stats.message_count:,}"
            if stats.message_count:
                extra["duration"] = f"{(stats.message_end_time - stats.message_start_time) * 1e-9:.3f} s"
        else:
            extra["summary"] = "none (channels counted by reading the file)"
        extra["checksums"] = _describe_checksums(reader)
    return rows, extra


def _describe_checksums(reader: _Reader) -> str:
    """Whether the file's chunks carry CRC32s (read back from each chunk's record header)."""
    import struct

    indexes = reader.summary.chunk_indexes if reader.summary is not None else []
    if not indexes:
        return "unknown: no chunk index (the data section's CRC, if any, is checked on a full read)"
    missing = 0
    for index in indexes:
        # Chunk record: opcode (1), length (8), start time (8), end time (8), uncompressed
        # size (8), then the uncompressed data's CRC32 (4); 0 means "not computed".
        reader.handle.seek(index.chunk_start_offset + 33)
        raw = reader.handle.read(4)
        if len(raw) < 4 or struct.unpack("<I", raw)[0] == 0:
            missing += 1
    if missing == len(indexes):
        return f"none: its {len(indexes):,} chunk(s) carry no CRC32, so corrupt data cannot be detected"
    if missing:
        return f"{len(indexes) - missing:,} of {len(indexes):,} chunks carry a CRC32 (checked on read); {missing:,} do not"
    return f"CRC32 on all {len(indexes):,} chunk(s), checked on read"


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


def _planar_pose(rigid: _Rigid) -> Pose:
    """The planar (x, y, z, yaw) part of a 3D transform."""
    r = rigid.rotation
    yaw = float(np.arctan2(r[1, 0], r[0, 0]))
    x, y, z = (float(v) for v in rigid.translation)
    return Pose(x, y, z, yaw)


def _compose_sensor(base_pose: Pose | None, sensor_offset: NDArray[np.float64]) -> Pose | None:
    """World pose of the sensor-centred frame: the base pose moved by the sensor's mounting offset."""
    if base_pose is None:
        return None
    dx, dy, dz = (float(v) for v in sensor_offset)
    if dx == 0.0 and dy == 0.0 and dz == 0.0:
        return base_pose
    c, s = np.cos(base_pose.yaw), np.sin(base_pose.yaw)
    return Pose(base_pose.x + c * dx - s * dy, base_pose.y + s * dx + c * dy, base_pose.z + dz, base_pose.yaw)


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


# --- writing ----------------------------------------------------------------------------------


def write_mcap(log: RangeLog | Features, path: str | os.PathLike[str]) -> None:
    """Write a log as MCAP on occtool's JSON channel ``/occtool/features``.

    One message per position, holding its features (base64 float64, so values round
    trip exactly), pose and stamp; the channel's JSON schema documents the layout.
    The file is written atomically.

    Parameters
    ----------
    log
        The positions to write (a bare :class:`Features` is one position without pose).
    path
        Output ``.mcap`` file.
    """
    from mcap.writer import CompressionType, Writer

    from occtool import __version__
    from occtool.io._atomic import atomic_write

    if isinstance(log, Features):
        log = RangeLog(positions=[Position(0, log)])
    if str(path) == "-":
        raise InputError("MCAP output needs a file name, not standard output")
    with atomic_write(path, "wb") as handle:
        writer = Writer(handle, compression=CompressionType.ZSTD if _has_zstd() else CompressionType.NONE)
        writer.start(profile="", library=f"occtool {__version__}")
        schema_id = writer.register_schema(
            name=OCCTOOL_SCHEMA_NAME, encoding="jsonschema", data=json.dumps(OCCTOOL_JSON_SCHEMA).encode()
        )
        channel_id = writer.register_channel(
            topic=OCCTOOL_TOPIC, message_encoding="json", schema_id=schema_id,
            metadata={"frame": "sensor-centred robot frame (REP-103)"},
        )
        for k, position in enumerate(log.positions):
            f = position.features
            payload = {
                "version": OCCTOOL_FORMAT_VERSION,
                "position": k,
                "stamp": position.stamp,
                "frame": "sensor-centred robot frame (REP-103)",
                "pose": position.pose.to_dict() if position.pose is not None else None,
                "count": len(f),
                "points": base64.b64encode(np.ascontiguousarray(f.points, dtype="<f8").tobytes()).decode("ascii"),
                "evidence": base64.b64encode(np.ascontiguousarray(f.evidence, dtype="<f8").tobytes()).decode("ascii"),
            }
            # log_time orders messages: the stamp when known, else the position index.
            time_ns = int(round(position.stamp * 1e9)) if position.stamp is not None and position.stamp >= 0 else k
            writer.add_message(channel_id, log_time=time_ns, publish_time=time_ns, sequence=k,
                               data=json.dumps(payload).encode())
        writer.finish()


def _has_zstd() -> bool:
    try:
        import zstandard  # noqa: F401
    except ImportError:
        return False
    return True

