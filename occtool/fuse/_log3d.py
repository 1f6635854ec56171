"""The 3D world map of a log: whether a log is 3D, its rays in the world, its cell size chosen
and its :class:`~occtool.fuse.WorldMap3D` built (what ``occtool map`` does for a depth camera
or a 3D lidar; :mod:`occtool.fuse._world3d` holds the map itself)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.formats.occmap3d import rigid
from occtool.fuse._inner_split import choose_resolution
from occtool.fuse._world3d import WorldMap3D, build_world_map_3d

FloatArray = NDArray[np.float64]


#: Share of a log's returns that must lie off the sensor's plane for it to be 3D.
OFF_PLANE_SHARE = 0.1
#: How far off the plane (metres): farther than a 2D laser's mounting tilt puts its returns.
OFF_PLANE = 0.05


def is_3d_log(log: Any, sample: int = 200_000) -> bool:
    """Whether a log's returns spread above and below its sensor (a depth camera, a 3D lidar)
    rather than lying in its plane (a 2D laser): :data:`OFF_PLANE_SHARE` of them more than
    :data:`OFF_PLANE` from it (every position's returns, up to ``sample`` in all)."""
    heights = [np.asarray(p.features.points, dtype=np.float64).reshape(-1, 3)[:, 2][
        np.asarray(p.features.evidence, dtype=np.float64).reshape(-1) > 0.0] for p in log.positions]
    every = np.concatenate(heights) if heights else np.zeros(0)
    if every.size > sample:
        every = every[np.linspace(0, every.size - 1, sample).astype(np.int64)]
    return bool(every.size) and float(np.mean(np.abs(every) > OFF_PLANE)) >= OFF_PLANE_SHARE


def sensor_positions(log: Any) -> FloatArray:
    """``(N, 3)``: each posed position's sensor in the world frame (a single position without
    a pose: the origin, its own frame, as :func:`rays_of_log` takes it)."""
    if len(log.positions) == 1 and log.positions[0].pose is None:
        return np.zeros((1, 3))
    return np.array([p.pose.translation for p in log.positions if p.pose is not None], dtype=np.float64).reshape(-1, 3)


def rays_of_log(log: Any) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], NDArray[np.intp]]:
    """Each feature of a :class:`~occtool.features.RangeLog` as a world-frame ray: origins (its
    scan's sensor where the position gathers several scans, else the position's pose), end
    points (its sensor-centred robot-frame point turned by the yaw and moved by the pose),
    hits (evidence above 0; 0 is a free-only ray) and the number of its scan in the log (0, 1,
    ...; a position's own number where it keeps no scans apart)."""
    from occtool.features import Pose, scans_apart

    origins, ends, hits = [], [], []
    sizes: list[int] = []
    # One position and no pose (a single scan): its own frame is the world's, as in 2D.
    alone = len(log.positions) == 1 and log.positions[0].pose is None
    for position in log.positions:
        if position.pose is None and not alone:
            raise InputError(f"{log.source or 'the log'}: position {position.index} has no pose; "
                             "a world map needs poses")
        points = np.asarray(position.features.points, dtype=np.float64).reshape(-1, 3)
        pose = position.pose or Pose(0.0, 0.0, 0.0, 0.0)
        ends.append(points @ pose.rotation.T + pose.translation)
        scan_sizes = scans_apart(position)
        if scan_sizes is not None:
            # Merged scans: a ray from the first scan's sensor would cross space the camera's
            # own ray did not (up to the position tolerance, 0.25 m, off).
            origins.append(np.repeat(np.asarray(position.scan_origins, dtype=np.float64), scan_sizes, axis=0)
                           @ pose.rotation.T + pose.translation)
            sizes.extend(int(size) for size in scan_sizes)
        else:
            origins.append(np.broadcast_to(pose.translation, points.shape))
            sizes.append(points.shape[0])
        hits.append(np.asarray(position.features.evidence, dtype=np.float64).reshape(-1) > 0.0)
    if not ends:
        raise InputError(f"{log.source or 'the log'}: no positions to map")
    groups = np.repeat(np.arange(len(sizes)), sizes)
    return np.concatenate(origins), np.concatenate(ends), np.concatenate(hits), groups


def map_log_3d(log: Any, resolution: float | None = None, *, to_map: ArrayLike | None = None, seed: int = 0,
               **options: Any) -> WorldMap3D:
    """The :class:`WorldMap3D` of a :class:`~occtool.features.RangeLog`, in the frame of its poses.

    ``resolution`` ``None``: chosen on an inner split of the log's own positions
    (:func:`occtool.fuse._inner_split.choose_resolution`, seeded by ``seed``, with the free
    space's saturation; the choice and its scores in the map's :attr:`WorldMap3D.choice`).
    ``to_map`` ``(4, 4)``: where a reader moved the poses (a depth folder levels its world on the floor it finds,
    :attr:`occtool.features.RangeLog.to_log_frame`), the rigid transform from the frame the
    user's poses are in to the log's; it is stored in the map and applied to every query.
    ``options`` are :func:`build_world_map_3d`'s.
    """
    origins, ends, hits, groups = rays_of_log(log)
    choice: dict[str, Any] = {"chosen": resolution, "why": "given"}
    if resolution is None:
        resolution, choice = choose_resolution(origins, ends, hits, groups, seed=seed, **options)
        if "saturation" in choice:
            options = {**options, "saturation": choice["saturation"]}
    world = build_world_map_3d(origins, ends, hits, resolution=resolution, **options)
    world.choice = choice
    if to_map is not None:
        world.to_map = rigid(to_map)
    return world


__all__ = ["OFF_PLANE", "OFF_PLANE_SHARE", "is_3d_log", "map_log_3d", "rays_of_log", "sensor_positions"]
