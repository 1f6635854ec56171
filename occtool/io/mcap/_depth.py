"""Depth images in MCAP and ROS bags: ``sensor_msgs/msg/Image`` (16UC1, mono16, 32FC1),
``sensor_msgs/msg/CompressedImage`` in ``compressedDepth`` PNG form, ``foxglove.RawImage``,
with the intrinsics of ``sensor_msgs/msg/CameraInfo`` or ``foxglove.CameraCalibration``.

Each image is back-projected by :func:`occtool.io.depth.back_project` (invalid depth,
no returns, noise evidence and the feature budget as there) and returned in its optical
frame (the message's ``frame_id``), so the mounting from ``/tf_static`` turns it into the
base frame as it does a point cloud. The camera whose ``frame_id`` matches the image's
gives the intrinsics (the first message of each); distortion coefficients are ignored
(noted): read the rectified topic (``image_rect``), whose are zero.
"""

from __future__ import annotations

import base64
import math
import struct
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Note
from occtool.io.depth import (
    DEFAULT_DEPTH_FEATURES,
    DEFAULT_DEPTH_MAX_RANGE,
    DEFAULT_DEPTH_MIN_RANGE,
    DEFAULT_DEPTH_NOISE,
    OPTICAL_TO_BODY,
    DepthCounts,
    PinholeCamera,
    back_project,
    check_image_size,
    decode_png,
)
from occtool.io.mcap._channels import COMPRESSED_DEPTH, FOXGLOVE_RAWIMAGE, _get, _stamp_seconds
from occtool.io.mcap._transforms import _strip_frame

#: Encodings read as depth: unsigned 16-bit millimetres, or 32-bit float metres (REP 118).
MILLIMETRE_ENCODINGS = ("16UC1", "mono16")
METRE_ENCODINGS = ("32FC1",)


@dataclass
class DepthSettings:
    """The depth reading options and what was found, for the notes."""

    features: int = DEFAULT_DEPTH_FEATURES
    noise: float = DEFAULT_DEPTH_NOISE
    max_range: float = DEFAULT_DEPTH_MAX_RANGE
    cameras: dict[str, PinholeCamera] = field(default_factory=dict)
    distorted: set[str] = field(default_factory=set)
    counts: DepthCounts = field(default_factory=DepthCounts)
    level_frames: set[str] = field(default_factory=set)
    #: Per image frame without a mounting: (rotation, height, tilt) from the floor in its first image.
    from_floor: dict[str, tuple[NDArray[np.float64], float, float] | None] = field(default_factory=dict)


def add_camera_info(settings: DepthSettings, message: Any, where: str) -> None:
    """Keep the intrinsics of a CameraInfo / CameraCalibration message's frame (its first)."""
    frame = _strip_frame(_get(message, "frame_id", None) or _get(_get(message, "header"), "frame_id", ""))
    if frame in settings.cameras:
        return
    k = _get(message, "k", None)
    if k is None:
        k = _get(message, "K", None)
    d = _get(message, "d", None)
    if d is None:
        d = _get(message, "D", None)
    try:
        camera = PinholeCamera.from_matrix(int(_get(message, "width", 0)), int(_get(message, "height", 0)),
                                           list(k) if k is not None else [])
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where}: malformed camera info ({exc})") from None
    settings.cameras[frame] = camera
    if d is not None and len(d) and np.any(np.asarray(list(d), dtype=np.float64) != 0.0):
        settings.distorted.add(frame)


def _raw_array(data: Any, encoding: str, height: int, width: int, step: int, big_endian: bool, where: str
               ) -> tuple[NDArray[Any], float]:
    if isinstance(data, str):
        try:
            data = base64.b64decode(data, validate=True)
        except ValueError as exc:
            raise InputError(f"{where}: image data is not valid base64 ({exc})") from None
    if not isinstance(data, (bytes, bytearray, memoryview)):
        data = bytes(bytearray(data))
    if encoding in MILLIMETRE_ENCODINGS:
        code, scale = "u2", 1e-3
    elif encoding in METRE_ENCODINGS:
        code, scale = "f4", 1.0
    else:
        raise InputError(f"{where}: the image's encoding is {encoding!r}, not depth ({', '.join(MILLIMETRE_ENCODINGS + METRE_ENCODINGS)}): "
                         "pick the depth topic with topics=")
    size = np.dtype(code).itemsize
    check_image_size(width, height, where)
    step = step or width * size
    raw = np.frombuffer(data, dtype=np.uint8)
    if step < width * size:
        raise InputError(f"{where}: a row step of {step} bytes is shorter than a row of {width} {encoding} pixels")
    if raw.size != height * step:
        # Longer data is no image of this header either: the rows would be taken from the wrong bytes.
        raise InputError(f"{where}: {raw.size:,} data bytes where {height} rows of step {step} are "
                         f"{height * step:,} ({width}x{height} {encoding} pixels)")
    rows = raw.reshape(height, step)[:, : width * size]
    image = np.ascontiguousarray(rows).view((">" if big_endian else "<") + code).reshape(height, width)
    return image, scale


def _compressed_depth(message: Any, where: str) -> tuple[NDArray[Any], float]:
    """``compressedDepth`` (image_transport's plugin): a 12-byte header, then a PNG."""
    fmt = str(_get(message, "format", ""))
    if "compresseddepth" not in fmt.lower().replace(" ", ""):
        raise InputError(f"{where}: a compressed image of format {fmt!r}, not compressedDepth: pick the depth "
                         "topic with topics=")
    if "rvl" in fmt.lower():
        raise InputError(f"{where}: compressedDepth in RVL form is not read (no maintained Python decoder): "
                         "record the PNG form")
    data = bytes(bytearray(_get(message, "data", b"")))
    if len(data) < 12:
        raise InputError(f"{where}: a compressedDepth message of {len(data)} bytes (its header alone is 12)")
    _, quant_a, quant_b = struct.unpack("<iff", data[:12])
    # The PNG's size and completeness are checked from its header and chunks before Pillow
    # decodes it (a header claiming 20000x20000 is refused without allocating anything).
    values = decode_png(data[12:], f"{where}: the compressedDepth PNG cannot be decoded")
    if values.ndim != 2:
        raise InputError(f"{where}: the compressedDepth PNG is not one channel")
    if fmt.split(";")[0].strip() in METRE_ENCODINGS:
        # 32FC1: inverse depth quantised as depthQuantA / (depth) + depthQuantB; 0 is invalid.
        quantised = values.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = np.where(quantised > 0, quant_a / (quantised - quant_b), np.nan)
        return depth, 1.0
    return values.astype(np.uint16, copy=False), 1e-3


def decode_depth(kind: str, message: Any, settings: DepthSettings, no_return_range: float | None, where: str
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], str, float | None]:
    """A depth image message to optical-frame points, evidence, its frame and stamp."""
    if kind == FOXGLOVE_RAWIMAGE:
        frame = _strip_frame(_get(message, "frame_id", ""))
        stamp = _stamp_seconds(_get(message, "timestamp"))
        image, scale = _raw_array(_get(message, "data", b""), str(_get(message, "encoding", "")),
                                  int(_get(message, "height", 0)), int(_get(message, "width", 0)),
                                  int(_get(message, "step", 0)), False, where)
    else:
        header = _get(message, "header")
        frame = _strip_frame(_get(header, "frame_id", ""))
        stamp = _stamp_seconds(_get(header, "stamp"))
        if kind == COMPRESSED_DEPTH:
            image, scale = _compressed_depth(message, where)
        else:
            image, scale = _raw_array(_get(message, "data", b""), str(_get(message, "encoding", "")),
                                      int(_get(message, "height", 0)), int(_get(message, "width", 0)),
                                      int(_get(message, "step", 0)), bool(_get(message, "is_bigendian", 0)), where)
    camera = settings.cameras.get(frame)
    if camera is None:
        known = ", ".join(sorted(settings.cameras)) or "none"
        raise InputError(f"{where}: no camera info for the image's frame '{frame}' (a sensor_msgs/msg/CameraInfo "
                         f"or foxglove.CameraCalibration with that frame_id; frames with one: {known})")
    if image.shape != (camera.height, camera.width):
        raise InputError(f"{where}: a {image.shape[1]}x{image.shape[0]} depth image where the camera info of "
                         f"'{frame}' says {camera.width}x{camera.height}")
    if not math.isfinite(settings.max_range):
        raise InputError(f"{where}: depth max range must be finite")
    points, evidence = back_project(
        image, camera, scale=scale, min_range=DEFAULT_DEPTH_MIN_RANGE, max_range=settings.max_range,
        no_return_range=no_return_range, noise=settings.noise, budget=settings.features,
        phase=settings.counts.frames, counts=settings.counts)
    # Body (REP-103 at the camera) back to the optical frame the message is in: p_opt = B^T p_body.
    return points @ OPTICAL_TO_BODY, evidence, frame, stamp


def depth_notes(settings: DepthSettings, no_return_range: float | None) -> list[str]:
    notes = settings.counts.notes(no_return_range, settings.max_range)
    if settings.distorted & set(settings.cameras):
        notes.append(Note.warn(f"distortion coefficients of {', '.join(sorted(settings.distorted))} ignored "
                               "(a rectified image_rect topic has none)"))
    for frame, found in sorted(settings.from_floor.items()):
        if found is not None:
            notes.append(Note.warn(
                f"warning: no /tf_static transform from {frame} to the base frame: the camera's tilt "
                f"({found[2]:.1f} degrees) and height ({found[1]:.2f} m) estimated from the floor plane "
                "in its first image"))
    level = settings.level_frames - {f for f, found in settings.from_floor.items() if found is not None}
    if level:
        notes.append(Note.warn(f"warning: no /tf_static transform from {', '.join(sorted(level))} to the base "
                               "frame and no floor plane in its first image: the depth camera taken as level, looking "
                               "along the base's x axis (optical z)"))
    return notes


__all__ = ["DepthSettings", "add_camera_info", "decode_depth", "depth_notes"]
