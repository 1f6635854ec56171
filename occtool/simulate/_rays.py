"""Rays from the sensor against a scene's prisms and the floor: :func:`cast_rays`."""

from __future__ import annotations

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.simulate._scene import Scene

FloatArray = NDArray[np.float64]

# Index marking a ray that hit the floor or nothing at all in :func:`cast_rays`.
FLOOR = -1
NOTHING = -2


def _cross(ax: FloatArray | float, ay: FloatArray | float, bx: FloatArray | float,
           by: FloatArray | float) -> FloatArray:
    return ax * by - ay * bx  # type: ignore[return-value]  # an array whenever one argument is


def cast_rays(
    scene: Scene, directions: ArrayLike, *, max_range: float = np.inf
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Cast rays from the sensor against the scene's prisms and the floor.

    Parameters
    ----------
    scene
        The scene; the sensor sits at ``scene.robot.sensor_height`` above the floor at x = y = 0.
    directions
        ``(N, 3)`` ray directions in the sensor frame (need not be unit length).
    max_range
        Rays hitting nothing closer than this report ``inf``.

    Returns
    -------
    ranges
        ``(N,)`` distance from the sensor to the first surface along each unit ray, or ``inf``.
    surface
        ``(N,)`` index into ``scene.obstacles`` of the surface hit, :data:`FLOOR` (-1) for the
        floor, :data:`NOTHING` (-2) when nothing is hit within ``max_range``.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    norm = np.linalg.norm(d, axis=1)
    if not (np.isfinite(norm) & (norm > 0)).all():
        raise InputError("every ray direction must be a finite, non-zero vector")
    d = d / norm[:, None]
    height = scene.robot.sensor_height
    n = d.shape[0]
    best = np.full(n, np.inf)
    surface = np.full(n, NOTHING, dtype=np.int64)
    eps = 1e-12

    with np.errstate(divide="ignore", invalid="ignore"):
        floor_t = np.where(d[:, 2] < -eps, -height / d[:, 2], np.inf)
    hit = floor_t < best
    best[hit], surface[hit] = floor_t[hit], FLOOR

    for index, obstacle in enumerate(scene.obstacles):
        z_lo, z_hi = obstacle.z_min - height, obstacle.z_max - height  # sensor frame
        vertices = np.asarray(obstacle.footprint)
        edges = np.roll(vertices, -1, axis=0) - vertices
        # Side faces: solve t * d_xy = a + u * e (a vertex, e its edge) for the range t and
        # the edge fraction u, for all rays at once.
        for (ax, ay), (ex, ey) in zip(vertices, edges):
            denom = _cross(d[:, 0], d[:, 1], ex, ey)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = _cross(ax, ay, ex, ey) / denom
                u = _cross(ax, ay, d[:, 0], d[:, 1]) / denom
                z = t * d[:, 2]
            ok = (np.abs(denom) > eps) & (t > eps) & (u >= 0.0) & (u <= 1.0) & (z >= z_lo) & (z <= z_hi) & (t < best)
            best[ok], surface[ok] = t[ok], index
        # Top and bottom caps: horizontal polygons at z_hi and z_lo.
        polygon = obstacle.polygon
        shapely.prepare(polygon)
        for z_cap in (z_hi, z_lo):
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(np.abs(d[:, 2]) > eps, z_cap / d[:, 2], np.inf)
            candidate = (t > eps) & (t < best)
            if not candidate.any():
                continue
            idx = np.flatnonzero(candidate)
            inside = shapely.contains_xy(polygon, t[idx] * d[idx, 0], t[idx] * d[idx, 1])
            idx = idx[inside]
            best[idx], surface[idx] = t[idx], index

    beyond = best > max_range
    best[beyond], surface[beyond] = np.inf, NOTHING
    return best, surface
