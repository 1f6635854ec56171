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

The parts, one concept a module (private; everything public is imported from here):

===============  ======================================================================
``_channels``    channel kinds, occtool's channel schema, decoder factories, field access
``_transforms``  rigid transforms, quaternions, TF messages, the static frame tree
``_decode``      one message to sensor-frame points (PointCloud2, LaserScan, foxglove,
                 occtool's channel) and the reading options they count into
``_file``        the open MCAP file: summary, channels, CRC checks, ``describe_channels``
``_reader``      ``read_mcap``: choose channels, static frames, scans, poses, notes
``_writer``      ``write_mcap``
===============  ======================================================================

:mod:`occtool.io.rosbag` reads ROS bags through :func:`read_mcap` (its ``opener``), so
bags share the decoders, frames and poses.
"""

from occtool.io.mcap._channels import (
    FOXGLOVE_LASERSCAN,
    FOXGLOVE_POINTCLOUD,
    LASERSCAN,
    OCCTOOL,
    OCCTOOL_FORMAT_VERSION,
    OCCTOOL_JSON_SCHEMA,
    OCCTOOL_SCHEMA_NAME,
    OCCTOOL_TOPIC,
    ODOMETRY,
    POINTCLOUD2,
    RANGE_KINDS,
    TF,
    channel_kind,
)
from occtool.io.mcap._file import ChannelRow, describe_channels
from occtool.io.mcap._reader import read_mcap
from occtool.io.mcap._writer import write_mcap
from occtool.io.read_options import DEFAULT_CONSTANT_EVIDENCE

__all__ = [
    "DEFAULT_CONSTANT_EVIDENCE",
    "FOXGLOVE_LASERSCAN",
    "FOXGLOVE_POINTCLOUD",
    "LASERSCAN",
    "OCCTOOL",
    "OCCTOOL_FORMAT_VERSION",
    "OCCTOOL_JSON_SCHEMA",
    "OCCTOOL_SCHEMA_NAME",
    "OCCTOOL_TOPIC",
    "ODOMETRY",
    "POINTCLOUD2",
    "RANGE_KINDS",
    "TF",
    "ChannelRow",
    "channel_kind",
    "describe_channels",
    "read_mcap",
    "write_mcap",
]
