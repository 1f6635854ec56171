"""Rigid transforms: quaternions, TF messages, the static frame tree, planar poses."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Pose
from occtool.io.mcap._channels import _get, _stamp_seconds
from occtool.io.positions import check_pose


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


def _checked_rigid(rotation: Any, translation: Any, what: str, at: str = "") -> _Rigid:
    """The transform of a quaternion and a translation, refusing ones that are no rigid motion
    (``at`` names the message, as `` (message at 12.5 s)``, in :func:`check_pose`'s refusals)."""
    q = (tuple(float(_get(rotation, k, 0.0 if k != "w" else 1.0)) for k in ("x", "y", "z", "w"))
         if rotation is not None else (0.0, 0.0, 0.0, 1.0))
    t = _vector(translation)
    if not (np.isfinite(q).all() and np.isfinite(t).all()):
        raise InputError(f"{what} is not finite (rotation {q}, translation {tuple(float(v) for v in t)})")
    if not any(q):
        raise InputError(f"{what} has the zero quaternion (0, 0, 0, 0), which is no rotation")
    check_pose(what + at, t, quaternion=q)  # bounded, and a quaternion of unit length
    return _Rigid(_rotation_from_quaternion(rotation), t)


def _at(item: Any) -> str:
    """`` (message at 12.5 s)``: a transform's message named by its stamp (the reader passes the topic alone)."""
    try:
        header = _get(item, "header")
        stamp = _stamp_seconds(_get(item, "timestamp") if header is None else _get(header, "stamp"))
    except (TypeError, ValueError, AttributeError):
        return ""
    return f" (message at {stamp:.9g} s)" if stamp is not None and math.isfinite(stamp) else ""


def _transforms_of(message: Any, topic: str = "tf") -> list[tuple[str, str, _Rigid]]:
    """``(parent, child, child-to-parent transform)`` for each transform in a TF message.

    Raises
    ------
    InputError
        For a transform with a NaN or infinite value, a zero quaternion, or one that
        :func:`occtool.io.positions.check_pose` refuses (past the world's bounds, a
        quaternion not of unit length).
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
        rigid = _checked_rigid(rotation, translation, f"{topic}: the transform {parent} -> {child}", _at(item))
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

