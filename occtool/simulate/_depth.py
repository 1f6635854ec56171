"""A pinhole depth camera over a scene's truth: :func:`render_depth_frames`, and writing the
frames as a TUM RGB-D or 3DMatch folder (:func:`write_depth_folder`).

The camera sits at the sensor (the scene's origin, ``sensor_height`` above the floor) and
turns in place: frame ``i`` looks along pan ``yaws[i]`` with the camera tilted by
``tilt`` (negative looks down). Each pixel's ray is cast against the prisms and the floor
(:func:`~occtool.simulate.cast_rays`); its depth is the hit's distance along the optical
axis with Gaussian noise ``k z**2`` (a structured-light camera sees untextured surfaces
too), and pixels whose ray meets nothing within ``max_range`` read 0, as a depth camera's
do. The world frame of the poses has z up and its origin on the floor below the sensor.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.io.depth import OPTICAL_TO_BODY, PinholeCamera
from occtool.simulate._catalogue import build_scene
from occtool.simulate._rays import NOTHING, cast_rays
from occtool.simulate._scene import Scene

FloatArray = NDArray[np.float64]

#: The rendered camera by default: 160x120 pixels, 60 degrees wide (fx = fy = 138.56).
DEFAULT_CAMERA = PinholeCamera(160, 120, 80.0 / math.tan(math.radians(30.0)), 80.0 / math.tan(math.radians(30.0)),
                               79.5, 59.5)


@dataclass(frozen=True)
class DepthFrame:
    """One rendered frame: depth in metres (0 = no measurement) and the camera's pose."""

    depth: NDArray[np.float32]
    camera_to_world: FloatArray  # the optical frame's pose, 4x4
    stamp: float


def camera_rotation(yaw: float, tilt: float) -> FloatArray:
    """World-from-optical rotation of a camera turned by ``yaw`` and tilted by ``tilt`` (down < 0)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    ct, st = math.cos(tilt), math.sin(tilt)
    turn = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    # A tilt of `tilt` about the body's y axis (y left): positive lifts the view.
    pitch = np.array([[ct, 0.0, -st], [0.0, 1.0, 0.0], [st, 0.0, ct]])
    return turn @ pitch @ OPTICAL_TO_BODY


def render_depth_frames(
    scene: str | Scene,
    *,
    camera: PinholeCamera = DEFAULT_CAMERA,
    yaws: Sequence[float] | None = None,
    tilt: float = math.radians(-25.0),
    noise: float = 0.0015,
    max_range: float = 6.0,
    seed: int = 0,
    positions: Sequence[tuple[float, float]] | None = None,
) -> tuple[list[DepthFrame], Scene]:
    """Depth frames of ``scene`` from a camera turning in place at the sensor.

    ``yaws`` defaults to 8 frames 45 degrees apart (a full turn). ``positions`` moves the
    camera of each frame to ``(x, y)`` (scene frame, at the sensor's height): a hand-held
    or driving camera. Returns the frames and the scene.

    Examples
    --------
    >>> frames, scene = render_depth_frames("office", yaws=[0.0])
    >>> frames[0].depth.shape, bool(frames[0].depth.max() > 0)
    ((120, 160), True)
    """
    scene = build_scene(scene) if isinstance(scene, str) else scene
    if yaws is None:
        yaws = [i * math.pi / 4.0 for i in range(8)]
    if not (math.isfinite(noise) and noise >= 0.0):
        raise InputError(f"depth noise must be a finite number >= 0, got {noise!r}")
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    optical = np.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones_like(u)], axis=-1)
    optical = optical.reshape(-1, 3)
    frames: list[DepthFrame] = []
    height = scene.robot.sensor_height
    if positions is not None and len(positions) != len(yaws):
        raise InputError(f"{len(positions)} camera positions for {len(yaws)} yaws")
    for index, yaw in enumerate(yaws):
        rotation = camera_rotation(float(yaw), tilt)
        directions = optical @ rotation.T  # not unit: z_optical = 1
        x, y = (0.0, 0.0) if positions is None else (float(positions[index][0]), float(positions[index][1]))
        seen = scene if (x, y) == (0.0, 0.0) else _shifted(scene, x, y)
        ranges, surface = cast_rays(seen, directions, max_range=max_range)
        depth = ranges / np.linalg.norm(optical, axis=1)
        with np.errstate(invalid="ignore"):  # inf * 0 where nothing is hit
            depth = depth + rng.standard_normal(depth.shape[0]) * noise * depth**2
        depth[(surface == NOTHING) | ~np.isfinite(depth) | (depth <= 0.0)] = 0.0
        pose = np.eye(4)
        pose[:3, :3] = rotation
        pose[:3, 3] = (x, y, height)
        frames.append(DepthFrame(depth.reshape(camera.height, camera.width).astype(np.float32), pose,
                                 1000.0 + index / 30.0))
    return frames, scene


def _shifted(scene: Scene, x: float, y: float) -> Scene:
    """The scene seen from ``(x, y)``: every obstacle moved by ``(-x, -y)``."""
    from dataclasses import replace

    return replace(scene, obstacles=tuple(
        replace(o, footprint=tuple((px - x, py - y) for px, py in o.footprint)) for o in scene.obstacles))


def walk(n: int = 120, *, radius: float = 0.6, centre: tuple[float, float] = (0.9, -0.9)
         ) -> tuple[list[float], list[tuple[float, float]]]:
    """Yaws and positions of a camera carried once round a circle, looking ahead and outward
    (a hand-held sweep of a room): ``render_depth_frames(..., yaws=, positions=)``."""
    angles = [2.0 * math.pi * i / n for i in range(n)]
    positions = [(centre[0] + radius * math.cos(a), centre[1] + radius * math.sin(a)) for a in angles]
    yaws = [a + math.pi / 4.0 for a in angles]  # between the path's heading and the outward normal
    return yaws, positions


def _write_png(path: Path, values: NDArray[np.uint16]) -> None:
    try:
        from PIL import Image
    except ImportError:
        from occtool.errors import MissingDependencyError

        raise MissingDependencyError("Pillow", "depth", f"writing the depth image {path}") from None
    Image.fromarray(values).save(path, optimize=True)


def _quaternion(rotation: FloatArray) -> tuple[float, float, float, float]:
    """``(qx, qy, qz, qw)`` of a rotation matrix."""
    m = rotation
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        return (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s
    i = int(np.argmax([m[0, 0], m[1, 1], m[2, 2]]))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
    q = [0.0, 0.0, 0.0]
    q[i] = 0.25 * s
    q[j] = (m[j, i] + m[i, j]) / s
    q[k] = (m[k, i] + m[i, k]) / s
    return q[0], q[1], q[2], (m[k, j] - m[j, k]) / s


def write_depth_folder(frames: Sequence[DepthFrame], folder: str | os.PathLike[str], *, layout: str = "tum",
                       camera: PinholeCamera = DEFAULT_CAMERA, world: FloatArray | None = None) -> Path:
    """Write frames as a TUM RGB-D folder (``depth.txt``, ``groundtruth.txt``, ``depth/*.png``
    of metres x 5000, ``camera-intrinsics.txt``) or a 3DMatch one (``seq-01/frame-NNNNNN.depth.png``
    in millimetres, ``frame-NNNNNN.pose.txt``, ``camera-intrinsics.txt``).

    ``world`` (4x4) re-expresses the poses in another world frame (``world @ pose``): a
    3DMatch folder's world is its first camera's, as KinectFusion writes them.
    Returns the folder.
    """
    target = Path(folder)
    target.mkdir(parents=True, exist_ok=True)
    np.savetxt(target / "camera-intrinsics.txt", camera.matrix, fmt="%.6f")
    transform = np.eye(4) if world is None else np.asarray(world, dtype=np.float64)
    if layout == "tum":
        (target / "depth").mkdir(exist_ok=True)
        listing = ["# depth maps", "# rendered by occtool.simulate.write_depth_folder", "# timestamp filename"]
        truth = ["# ground truth trajectory", "# timestamp tx ty tz qx qy qz qw"]
        for frame in frames:
            name = f"depth/{frame.stamp:.6f}.png"
            _write_png(target / name, np.round(frame.depth.astype(np.float64) * 5000.0).clip(0, 65535)
                       .astype(np.uint16))
            listing.append(f"{frame.stamp:.6f} {name}")
            pose = transform @ frame.camera_to_world
            qx, qy, qz, qw = _quaternion(pose[:3, :3])
            t = pose[:3, 3]
            truth.append(f"{frame.stamp:.4f} {t[0]:.6f} {t[1]:.6f} {t[2]:.6f} {qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}")
        (target / "depth.txt").write_text("\n".join(listing) + "\n")
        (target / "groundtruth.txt").write_text("\n".join(truth) + "\n")
        return target
    if layout != "3dmatch":
        raise InputError(f"layout must be 'tum' or '3dmatch', got {layout!r}")
    sequence = target / "seq-01"
    sequence.mkdir(exist_ok=True)
    for index, frame in enumerate(frames):
        _write_png(sequence / f"frame-{index:06d}.depth.png",
                   np.round(frame.depth.astype(np.float64) * 1000.0).clip(0, 65534).astype(np.uint16))
        np.savetxt(sequence / f"frame-{index:06d}.pose.txt", transform @ frame.camera_to_world, fmt="%.9f")
    return target




_SEP = "=" * 80 + "\n"
_HEADER_DEF = (_SEP + "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
               + _SEP + "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n")
_IMAGE_DEF = ("std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n"
              "uint32 step\nuint8[] data\n" + _HEADER_DEF)
_COMPRESSED_DEF = "std_msgs/Header header\nstring format\nuint8[] data\n" + _HEADER_DEF
_CAMERA_INFO_DEF = (
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\n"
    "float64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nsensor_msgs/RegionOfInterest roi\n"
    + _HEADER_DEF + _SEP + "MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\n"
    "uint32 width\nbool do_rectify\n")
_TF_DEF = (
    "geometry_msgs/TransformStamped[] transforms\n"
    + _SEP + "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\n"
    "geometry_msgs/Transform transform\n"
    + _SEP + "MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n"
    + _SEP + "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
    + _SEP + "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n" + _HEADER_DEF)
#: Depth image topic of the logs :func:`depth_log_messages` makes.
DEPTH_TOPIC = "/camera/depth/image_rect_raw"


def _frame_name(index: int) -> str:
    return f"camera_{index}_depth_optical_frame"


def compressed_depth_png(depth_mm: NDArray[np.uint16]) -> bytes:
    """image_transport's ``compressedDepth`` payload of a 16UC1 image: a 12-byte header, then a PNG."""
    import io
    import struct

    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(depth_mm).save(buffer, format="PNG")
    return struct.pack("<iff", 0, 0.0, 0.0) + buffer.getvalue()


def depth_log_messages(frames: Sequence[DepthFrame], *, camera: PinholeCamera = DEFAULT_CAMERA,
                       encoding: str = "16UC1") -> list[tuple[str, str, dict[str, Any], float]]:
    """``(topic, type, message, seconds)`` of a ROS 2 log of the frames: a ring of depth cameras
    (one optical frame a frame) on a robot standing at the world's origin.

    ``/tf_static`` mounts each camera on ``base_link`` (the floor below the sensor), ``/tf``
    gives ``odom -> base_link`` at every image, each camera has a ``CameraInfo``, and the
    images are on :data:`DEPTH_TOPIC` in ``encoding``: ``16UC1`` (millimetres), ``32FC1``
    (metres) or ``compressedDepth`` (16UC1 in image_transport's PNG form).
    """

    def header(t: float, frame: str) -> dict[str, Any]:
        return {"stamp": {"sec": int(t), "nanosec": int(round((t - int(t)) * 1e9)) % 10**9}, "frame_id": frame}

    def transform(t: float, parent: str, child: str, pose: FloatArray) -> dict[str, Any]:
        qx, qy, qz, qw = _quaternion(pose[:3, :3])
        x, y, z = (float(v) for v in pose[:3, 3])
        return {"header": header(t, parent), "child_frame_id": child,
                "transform": {"translation": {"x": x, "y": y, "z": z},
                              "rotation": {"x": qx, "y": qy, "z": qz, "w": qw}}}

    start = frames[0].stamp if frames else 0.0
    messages: list[tuple[str, str, dict[str, Any], float]] = [
        ("/tf_static", "tf2_msgs/msg/TFMessage",
         {"transforms": [transform(start, "base_link", _frame_name(i), f.camera_to_world)
                         for i, f in enumerate(frames)]},
         start)]
    k = camera.matrix.reshape(-1).tolist()
    for i in range(len(frames)):
        messages.append(("/camera/depth/camera_info", "sensor_msgs/msg/CameraInfo", {
            "header": header(start, _frame_name(i)), "height": camera.height, "width": camera.width,
            "distortion_model": "plumb_bob", "d": [0.0] * 5, "k": k, "r": [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
            "p": [k[0], 0.0, k[2], 0.0, 0.0, k[4], k[5], 0.0, 0.0, 0.0, 1.0, 0.0], "binning_x": 0, "binning_y": 0,
            "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False}}, start))
    for i, frame in enumerate(frames):
        t = frame.stamp
        messages.append(("/tf", "tf2_msgs/msg/TFMessage",
                         {"transforms": [transform(t, "odom", "base_link", np.eye(4))]}, t))
        if encoding == "32FC1":
            data, step = frame.depth.astype("<f4").tobytes(), camera.width * 4
        else:
            mm = np.round(frame.depth.astype(np.float64) * 1000.0).clip(0, 65534).astype("<u2")
            data, step = mm.tobytes(), camera.width * 2
        if encoding == "compressedDepth":
            messages.append((DEPTH_TOPIC.replace("image_rect_raw", "image_rect_raw/compressedDepth"),
                             "sensor_msgs/msg/CompressedImage",
                             {"header": header(t, _frame_name(i)), "format": "16UC1; compressedDepth png",
                              "data": compressed_depth_png(mm)}, t))
            continue
        if encoding not in ("16UC1", "32FC1"):
            raise InputError(f"encoding must be 16UC1, 32FC1 or compressedDepth, got {encoding!r}")
        messages.append((DEPTH_TOPIC, "sensor_msgs/msg/Image", {
            "header": header(t, _frame_name(i)), "height": camera.height, "width": camera.width,
            "encoding": encoding, "is_bigendian": 0, "step": step, "data": data}, t))
    return messages


def write_depth_mcap(frames: Sequence[DepthFrame], path: str | os.PathLike[str], *,
                     camera: PinholeCamera = DEFAULT_CAMERA, encoding: str = "16UC1") -> Path:
    """The frames as a ROS 2 MCAP (:func:`depth_log_messages`), with mcap_ros2's writer."""
    from mcap_ros2.writer import Writer

    definitions = {"sensor_msgs/msg/Image": _IMAGE_DEF, "sensor_msgs/msg/CompressedImage": _COMPRESSED_DEF,
                   "sensor_msgs/msg/CameraInfo": _CAMERA_INFO_DEF, "tf2_msgs/msg/TFMessage": _TF_DEF}
    target = Path(path)
    with open(target, "wb") as handle:
        writer = Writer(handle)
        schemas: dict[str, Any] = {}
        for topic, kind, message, t in depth_log_messages(frames, camera=camera, encoding=encoding):
            if kind not in schemas:
                schemas[kind] = writer.register_msgdef(kind, definitions[kind])
            stamp = int(round(t * 1e9))
            writer.write_message(topic, schemas[kind], message, log_time=stamp, publish_time=stamp)
        writer.finish()
    return target


def write_depth_bag(frames: Sequence[DepthFrame], path: str | os.PathLike[str], *,
                    camera: PinholeCamera = DEFAULT_CAMERA, encoding: str = "16UC1") -> Path:
    """The frames as a ROS 1 bag (``*.bag``, rosbags' writer: the ``bags`` extra), as :func:`write_depth_mcap`."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    types = store.types
    Header, Time = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]

    def header(h: dict[str, Any]) -> Any:
        stamp = h["stamp"]
        assert isinstance(stamp, dict)
        return Header(0, Time(stamp["sec"], stamp["nanosec"]), h["frame_id"])

    def build(kind: str, m: dict[str, Any]) -> Any:
        if kind == "tf2_msgs/msg/TFMessage":
            items = []
            for tr in m["transforms"]:
                t, q = tr["transform"]["translation"], tr["transform"]["rotation"]
                items.append(types["geometry_msgs/msg/TransformStamped"](
                    header(tr["header"]), tr["child_frame_id"], types["geometry_msgs/msg/Transform"](
                        types["geometry_msgs/msg/Vector3"](t["x"], t["y"], t["z"]),
                        types["geometry_msgs/msg/Quaternion"](q["x"], q["y"], q["z"], q["w"]))))
            return types[kind](items)
        if kind == "sensor_msgs/msg/CameraInfo":
            roi = types["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
            return types[kind](header(m["header"]), m["height"], m["width"], m["distortion_model"],
                               np.array(m["d"]), np.array(m["k"]), np.array(m["r"]), np.array(m["p"]), 0, 0, roi)
        if kind == "sensor_msgs/msg/CompressedImage":
            return types[kind](header(m["header"]), m["format"],
                               np.frombuffer(m["data"], dtype=np.uint8))
        return types[kind](header(m["header"]), m["height"], m["width"], m["encoding"], m["is_bigendian"],
                           m["step"], np.frombuffer(m["data"], dtype=np.uint8))

    target = Path(path)
    if target.exists():
        target.unlink()
    with Writer(target) as writer:
        connections: dict[str, Any] = {}
        for topic, kind, message, t in depth_log_messages(frames, camera=camera, encoding=encoding):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, kind, typestore=store)
            writer.write(connections[topic], int(round(t * 1e9)),
                         store.serialize_ros1(build(kind, message), kind))
    return target


__all__ = ["DEFAULT_CAMERA", "DEPTH_TOPIC", "DepthFrame", "camera_rotation", "compressed_depth_png",
           "depth_log_messages", "render_depth_frames", "walk", "write_depth_bag", "write_depth_folder",
           "write_depth_mcap"]
