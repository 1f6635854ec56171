"""Decoding one range message into sensor-frame points and evidence.

The decoders are shared by every container: MCAP here, ROS bags through
:mod:`occtool.io.rosbag` (both yield messages with the same fields).
"""

from __future__ import annotations

import base64
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Pose
from occtool.io.mcap._channels import (
    FOXGLOVE_LASERSCAN,
    FOXGLOVE_POINTCLOUD,
    LASERSCAN,
    OCCTOOL_FORMAT_VERSION,
    POINTCLOUD2,
    _get,
    _stamp_seconds,
)
from occtool.io.mcap._transforms import _IDENTITY, _Rigid, _rotation_from_quaternion, _strip_frame, _vector
from occtool.io.read_options import DEFAULT_CONSTANT_EVIDENCE, ReadOptions

# ROS sensor_msgs/PointField datatypes and foxglove PackedElementField numeric types.
_ROS_DATATYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
_FOXGLOVE_TYPES = {1: "u1", 2: "i1", 3: "u2", 4: "i2", 5: "u4", 6: "i4", 7: "f4", 8: "f8"}
_FOXGLOVE_TYPE_NAMES = {
    "UINT8": 1, "INT8": 2, "UINT16": 3, "INT16": 4, "UINT32": 5, "INT32": 6, "FLOAT32": 7, "FLOAT64": 8,
}


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
    """The reading options (:class:`~occtool.io.ReadOptions`, whose fields read through:
    ``options.evidence_field``) and what decoding counts into them for the notes."""

    def __init__(self, settings: ReadOptions):
        self.settings = settings
        self.constant_for: set[str] = set()
        self.skipped_invalid = 0
        # Laser beams: all of them, the no-return ones (dropped, or kept as free rays out to
        # the ranges in free_reach) and the invalid ones (NaN, -inf, below range_min).
        self.beams = 0
        self.no_return = 0
        self.invalid_beams = 0
        self.free_reach: set[float] = set()
        self.depth: Any = None  # DepthSettings for a log with depth images (occtool.io.mcap._depth)

    def __getattr__(self, name: str) -> Any:
        # Only for names not set above: the reading options' fields, so a new option reaches
        # the decoders without a line here.
        return getattr(self.settings, name)


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


def _scan_evidence(
    intensities: Any, count: int, valid: NDArray[np.bool_], options: _Options, where: str
) -> NDArray[np.float64]:
    if options.use_intensities:
        values = np.asarray(intensities if intensities is not None else [], dtype=np.float64)
        if values.size != count:
            raise InputError(
                f"{where}: use_intensities=True given but the scan has {values.size} intensities for {count} ranges"
            )
        values = values[valid]
        finite = values[np.isfinite(values)]
        top = float(finite.max()) if finite.size else 0.0
        # Intensities already in [0, 1] are taken as evidence; others are scaled by the scan's largest.
        if top > 1.0:
            values = values / top
        return values
    options.constant_for.add("laser scans (no use_intensities=True)")
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
    frame, stamp = _strip_frame(_get(message, "frame_id")), _stamp_seconds(_get(message, "timestamp"))
    return _Decoded(points, evidence, frame, stamp, _foxglove_origin(message), dropped)


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
    listed = list(intensities) if intensities is not None else None
    evidence = _scan_evidence(listed, ranges.size, valid, options, where)
    reach = options.no_return_range if options.no_return_range is not None else np.inf
    points, evidence = _scan_points(ranges, angles, valid, missing, reach, evidence, options)
    frame, stamp = _strip_frame(_get(message, "frame_id")), _stamp_seconds(_get(message, "timestamp"))
    return _Decoded(points, evidence, frame, stamp, _foxglove_origin(message))


_DECODERS = {
    POINTCLOUD2: _decode_pointcloud2,
    LASERSCAN: _decode_laserscan,
    FOXGLOVE_POINTCLOUD: _decode_foxglove_pointcloud,
    FOXGLOVE_LASERSCAN: _decode_foxglove_laserscan,
}


def _decode_occtool(
    message: Any, where: str
) -> tuple[int, NDArray[np.float64], NDArray[np.float64], Pose | None, float | None]:
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
        raise InputError(f"{where}: message says {count} features but holds {points.size // 3} points "
                         f"and {evidence.size} evidence values")
    seconds = None if stamp is None else float(stamp)
    return position, points.reshape(count, 3).astype(np.float64), evidence.astype(np.float64), pose, seconds

