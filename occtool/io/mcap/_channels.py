"""Channel kinds: what occtool makes of an MCAP channel, and how its messages are decoded.

Also occtool's own channel (schema name, topic, format version, JSON schema) and the
field access shared by every decoded message (a JSON dict, a CDR or protobuf object).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

OCCTOOL_SCHEMA_NAME = "occtool.RangeFeatures"
OCCTOOL_TOPIC = "/occtool/features"
OCCTOOL_FORMAT_VERSION = 1

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
DEPTH_IMAGE = "depth Image"
COMPRESSED_DEPTH = "compressedDepth"
FOXGLOVE_RAWIMAGE = "foxglove RawImage"
#: Depth images: back-projected with their camera's intrinsics (:mod:`occtool.io.depth`).
DEPTH_KINDS = (DEPTH_IMAGE, COMPRESSED_DEPTH, FOXGLOVE_RAWIMAGE)
RANGE_KINDS = (POINTCLOUD2, LASERSCAN, FOXGLOVE_POINTCLOUD, FOXGLOVE_LASERSCAN, OCCTOOL, *DEPTH_KINDS)
TF = "transforms"
ODOMETRY = "odometry"
CAMERA_INFO = "camera info"

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
    ("sensor_msgs/msg/Image", "cdr"): DEPTH_IMAGE,
    ("sensor_msgs/msg/CompressedImage", "cdr"): COMPRESSED_DEPTH,
    ("foxglove.RawImage", "json"): FOXGLOVE_RAWIMAGE,
    ("foxglove.RawImage", "protobuf"): FOXGLOVE_RAWIMAGE,
    ("sensor_msgs/msg/CameraInfo", "cdr"): CAMERA_INFO,
    ("foxglove.CameraCalibration", "json"): CAMERA_INFO,
    ("foxglove.CameraCalibration", "protobuf"): CAMERA_INFO,
}


def channel_kind(schema_name: str, message_encoding: str) -> str | None:
    """What occtool makes of a channel: one of the kinds above, or ``None``."""
    return _SCHEMA_KINDS.get((schema_name, message_encoding.lower()))


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
