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
) -> tuple[list[DepthFrame], Scene]:
    """Depth frames of ``scene`` from a camera turning in place at the sensor.

    ``yaws`` defaults to 8 frames 45 degrees apart (a full turn). Returns the frames and the scene.

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
    for index, yaw in enumerate(yaws):
        rotation = camera_rotation(float(yaw), tilt)
        directions = optical @ rotation.T  # not unit: z_optical = 1
        ranges, surface = cast_rays(scene, directions, max_range=max_range)
        depth = ranges / np.linalg.norm(optical, axis=1)
        with np.errstate(invalid="ignore"):  # inf * 0 where nothing is hit
            depth = depth + rng.standard_normal(depth.shape[0]) * noise * depth**2
        depth[(surface == NOTHING) | ~np.isfinite(depth) | (depth <= 0.0)] = 0.0
        pose = np.eye(4)
        pose[:3, :3] = rotation
        pose[:3, 3] = (0.0, 0.0, height)
        frames.append(DepthFrame(depth.reshape(camera.height, camera.width).astype(np.float32), pose,
                                 1000.0 + index / 30.0))
    return frames, scene


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


__all__ = ["DEFAULT_CAMERA", "DepthFrame", "camera_rotation", "render_depth_frames", "write_depth_folder"]
