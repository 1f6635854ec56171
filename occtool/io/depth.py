"""Depth images to range features: pinhole back-projection, frames, noise and budget.

A depth camera (RGB-D or stereo: RealSense, ZED, OAK-D, Kinect) logs images whose pixel
``(u, v)`` holds the depth ``z`` along the optical axis. With the pinhole intrinsics
``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` the pixel's point in the camera's *optical*
frame (z forward, x right, y down; REP-103's ``_optical`` frames) is

    x = (u - cx) z / fx,    y = (v - cy) z / fy,    z = z.

:data:`OPTICAL_TO_BODY` turns it into REP-103 axes (x forward, y left, z up). Everything
here is vectorised over the image; :func:`back_project` does one frame:

* **Invalid depth**, following REP 118: 0 and NaN are "no valid measurement" (too near,
  a shadow of the projector, no texture) and are dropped, always: a free ray through a
  shadow beside an obstacle would clear the obstacle. ``+inf`` ("too far") and depths
  beyond the sensor's ``max_range`` are *no return*: dropped, or with ``no_return_range``
  R kept as free rays (evidence 0) at ``min(R, max_range)`` metres along their pixel's ray,
  as ``--no-return-range`` does for laser beams. Depths below ``min_range`` (and -inf)
  are invalid and dropped.
* **Evidence** per pixel from the sensor's depth noise, quadratic in depth for
  structured light and stereo: ``sigma(z) = k z**2`` metres. The evidence is the
  probability that the measured range lies within the sensor model's hit band
  ``r (1 -+ 0.03)`` (:class:`occtool.sensor.SensorModel`'s ``depth_error``) of the true
  one, ``m = erf(0.03 / (sqrt(2) k z))``, clipped to [0.05, 1] (0 is a free ray's).
  :data:`DEFAULT_DEPTH_NOISE` ``k = 0.0015`` is a Kinect-class structured-light camera
  (Khoshelham and Elberink 2012: 1.4-1.9e-3); a stereo camera's is larger
  (``k = sigma_d / (f b)``: about 0.005-0.01 for a RealSense D435 at 640x480).
* **Feature budget**: a frame keeps at most ``budget`` features. The valid pixels are
  counted and the image is sampled on a regular pixel grid of stride ``s`` (the smallest
  whose grid holds no more than the budget), so every surface keeps its share of the
  view by solid angle, as the simulated pan-tilt camera's uniform directions do; a grid
  still over budget is thinned evenly. Only the sampled pixels are back-projected
  (640x480 frames: see docs/formats.md for the rate measured).

:func:`camera_scan` places a frame's points by the camera's pose in a gravity-aligned
world frame: they are rotated into a frame centred at the camera with z up and x along
the camera's heading, and the pose keeps x, y, z and that heading (yaw), as every
reader's scans do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.features import Pose
from occtool.io._png import MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE, check_image_size, check_png, decode_png
from occtool.io.read_options import (  # the checks live with the defaults: read_log needs them, not this module
    DEFAULT_DEPTH_FEATURES,
    DEFAULT_DEPTH_MAX_RANGE,
    DEFAULT_DEPTH_MIN_RANGE,
    DEFAULT_DEPTH_NOISE,
    check_depth_features,
    check_depth_max_range,
    check_depth_noise,
)

FloatArray = NDArray[np.float64]


#: ``p_body = OPTICAL_TO_BODY @ p_optical``: optical (z forward, x right, y down) to REP-103
#: (x forward, y left, z up), the rotation ROS puts between ``camera_link`` and
#: ``camera_optical_frame``.
OPTICAL_TO_BODY = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
#: Nearest depth taken as a measurement, metres (below: invalid).
#: The sensor model's relative hit band (``SensorModel.depth_error``'s default).
HIT_BAND = 0.03
#: Lowest evidence a depth return gets (evidence 0 is a free-only ray).
MIN_EVIDENCE = 0.05


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics of a depth image: size in pixels, focal lengths and principal point.

    Raises
    ------
    InputError
        For a size that is not a whole number in [1, :data:`MAX_IMAGE_SIDE`], or a focal
        length or principal point that is not finite (focal lengths must be > 0).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or not 1 <= int(value) <= MAX_IMAGE_SIDE:
                raise InputError(f"camera {name} must be a whole number of pixels in [1, {MAX_IMAGE_SIDE}], "
                                 f"got {value!r}")
            object.__setattr__(self, name, int(value))
        for name in ("fx", "fy", "cx", "cy"):
            value = float(getattr(self, name))
            if not math.isfinite(value) or (name in ("fx", "fy") and value <= 0.0):
                raise InputError(f"camera intrinsics: {name} must be finite{' and > 0' if name[0] == 'f' else ''}, "
                                 f"got {value!r}")
            object.__setattr__(self, name, value)

    @classmethod
    def from_matrix(cls, width: int, height: int, k: ArrayLike) -> PinholeCamera:
        """From a 3x3 (or 9-value, row-major) K matrix; its skew and last row must be those of a pinhole."""
        try:
            matrix = np.asarray(k, dtype=np.float64).reshape(3, 3)
        except (TypeError, ValueError):
            raise InputError("camera intrinsics: K must be 9 numbers (a 3x3 matrix)") from None
        if not np.isfinite(matrix).all():
            raise InputError("camera intrinsics: K holds a value that is NaN or infinite")
        if not np.allclose(matrix[2], [0.0, 0.0, 1.0]) or abs(matrix[0, 1]) > 1e-6 * max(abs(matrix[0, 0]), 1.0) \
                or matrix[1, 0] != 0.0:
            raise InputError(f"camera intrinsics: K is not a pinhole matrix [[fx 0 cx] [0 fy cy] [0 0 1]]: "
                             f"{matrix.tolist()}")
        return cls(width, height, matrix[0, 0], matrix[1, 1], matrix[0, 2], matrix[1, 2])

    @property
    def matrix(self) -> FloatArray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@lru_cache(maxsize=16)
def _pixel_rays(camera: PinholeCamera) -> tuple[FloatArray, FloatArray]:
    """``(u - cx) / fx`` over the columns and ``(v - cy) / fy`` over the rows (read-only)."""
    xs = (np.arange(camera.width, dtype=np.float64) - camera.cx) / camera.fx
    ys = (np.arange(camera.height, dtype=np.float64) - camera.cy) / camera.fy
    xs.setflags(write=False)
    ys.setflags(write=False)
    return xs, ys


def noise_evidence(depth: ArrayLike, noise: float = DEFAULT_DEPTH_NOISE) -> FloatArray:
    """Evidence of returns at ``depth`` metres from the noise ``sigma = noise * depth**2``.

    ``m = erf(0.03 / (sqrt(2) noise depth))``, the probability that a return falls within
    the sensor model's hit band of +-3 % of its range, clipped to [0.05, 1].

    Examples
    --------
    >>> noise_evidence([1.0, 4.0, 10.0], noise=0.01).round(3).tolist()
    [0.997, 0.547, 0.236]
    """
    from scipy.special import erf

    z = np.asarray(depth, dtype=np.float64)
    if noise <= 0.0:
        return np.ones_like(z)
    with np.errstate(divide="ignore"):
        m = erf(HIT_BAND / (math.sqrt(2.0) * noise * z))
    return np.clip(m, MIN_EVIDENCE, 1.0)


@dataclass
class DepthCounts:
    """What :func:`back_project` found in the frames it was given (summed over frames)."""

    pixels: int = 0
    returns: int = 0
    invalid: int = 0       # 0, NaN, -inf, below min_range
    no_return: int = 0     # +inf, beyond max_range
    kept: int = 0          # features kept after the budget (returns and free rays)
    free_rays: int = 0
    frames: int = 0
    free_reach: set[float] = field(default_factory=set)

    def notes(self, no_return_range: float | None, max_range: float) -> list[str]:
        """Sentences for a log's notes."""
        if not self.frames:
            return []
        notes = [f"{self.frames} depth frame(s) of {self.pixels:,} pixels: {self.returns:,} returns, "
                 f"{self.invalid:,} invalid (0, NaN or nearer than the minimum range: dropped), "
                 f"{self.no_return:,} with no return (+inf or beyond {max_range:g} m)"]
        if self.no_return:
            if no_return_range is None:
                notes.append(f"dropped {self.no_return:,} depth pixel(s) with no return (no_return_range= keeps "
                             "them as free rays)")
            else:
                notes.append(f"kept depth pixels with no return as free rays at {min(no_return_range, max_range):g} m "
                             f"with evidence 0 ({self.free_rays:,} after the feature budget)")
        notes.append(f"kept {self.kept:,} depth features after the budget")
        return notes


def _stride(valid: int, budget: int) -> int:
    """The smallest pixel-grid stride whose grid holds about ``budget`` of ``valid`` pixels or fewer."""
    if valid <= budget:
        return 1
    return max(1, math.ceil(math.sqrt(valid / budget)))


def back_project(
    depth: ArrayLike,
    camera: PinholeCamera,
    *,
    scale: float = 1.0,
    min_range: float = DEFAULT_DEPTH_MIN_RANGE,
    max_range: float = DEFAULT_DEPTH_MAX_RANGE,
    no_return_range: float | None = None,
    noise: float = DEFAULT_DEPTH_NOISE,
    budget: int | None = DEFAULT_DEPTH_FEATURES,
    phase: int = 0,
    counts: DepthCounts | None = None,
) -> tuple[FloatArray, FloatArray]:
    """One depth image to points in the camera's REP-103 body frame and their evidence.

    Parameters
    ----------
    depth
        ``(height, width)`` depth image: metres times ``1 / scale`` (``scale=0.001`` for
        16-bit millimetres, ``1 / 5000`` for TUM RGB-D's PNGs, 1 for float metres).
    camera
        The intrinsics; the image's shape must be ``(camera.height, camera.width)``.
    min_range, max_range
        Depths below ``min_range`` are invalid; beyond ``max_range`` they are no returns.
    no_return_range
        ``None`` drops no-return pixels; R keeps them as free rays (evidence 0) at
        depth ``min(R, max_range)``.
    noise
        ``k`` of the depth noise ``sigma = k z**2`` (:func:`noise_evidence`).
    budget
        Most features kept (``None``: every pixel).
    phase
        Offset of the sampling grid (successive frames of a sequence take successive
        phases, so they sample different pixels).
    counts
        Counts to add this frame's to.

    Returns
    -------
    points
        ``(N, 3)`` in the camera's body frame (REP-103: x forward, y left, z up).
    evidence
        ``(N,)``: the noise evidence of returns, 0 for free rays.
    """
    image = np.asarray(depth)
    if image.ndim != 2 or image.shape != (camera.height, camera.width):
        raise InputError(f"depth image of shape {image.shape} does not match the camera's "
                         f"{camera.height}x{camera.width} pixels (height x width)")
    if not (math.isfinite(scale) and scale > 0.0):
        raise InputError(f"depth scale must be a finite number > 0, got {scale!r}")
    counts = counts if counts is not None else DepthCounts()
    # Classify in the image's own units (integer images need no float copy).
    lo, hi = min_range / scale, max_range / scale
    with np.errstate(invalid="ignore"):  # NaN compares false: invalid, not far
        valid = (image >= lo) & (image <= hi)
        far = image > hi  # +inf too
    n_valid = int(np.count_nonzero(valid))
    n_far = int(np.count_nonzero(far))
    keep_free = no_return_range is not None and n_far > 0
    wanted = n_valid + (n_far if keep_free else 0)
    counts.frames += 1
    counts.pixels += image.size
    counts.returns += n_valid
    counts.no_return += n_far
    counts.invalid += image.size - n_valid - n_far
    step = 1 if budget is None else _stride(wanted, budget)
    if step > 1:
        row0 = (phase * 7) % step
        col0 = (phase * 3) % step
        sub_valid = valid[row0::step, col0::step]
        sub_far = far[row0::step, col0::step] if keep_free else None
        rows_v, cols_v = np.nonzero(sub_valid)
        rows_v = rows_v * step + row0
        cols_v = cols_v * step + col0
        if sub_far is not None:
            rows_f, cols_f = np.nonzero(sub_far)
            rows_f = rows_f * step + row0
            cols_f = cols_f * step + col0
    else:
        rows_v, cols_v = np.nonzero(valid)
        if keep_free:
            rows_f, cols_f = np.nonzero(far)
    if not keep_free:
        rows_f = cols_f = np.empty(0, dtype=np.intp)
    total = rows_v.size + rows_f.size
    if budget is not None and total > budget:
        # Thin the grid evenly, returns and free rays alike.
        pick = np.linspace(0, total - 1, budget).astype(np.intp)
        pick_v = pick[pick < rows_v.size]
        pick_f = pick[pick >= rows_v.size] - rows_v.size
        rows_v, cols_v = rows_v[pick_v], cols_v[pick_v]
        rows_f, cols_f = rows_f[pick_f], cols_f[pick_f]
    xs, ys = _pixel_rays(camera)
    z = image[rows_v, cols_v].astype(np.float64) * scale
    n_v, n_f = rows_v.size, rows_f.size
    points = np.empty((n_v + n_f, 3))
    evidence = np.empty(n_v + n_f)
    # Optical (x right, y down, z forward) written straight into body axes (x fwd, y left, z up).
    points[:n_v, 0] = z
    points[:n_v, 1] = -xs[cols_v] * z
    points[:n_v, 2] = -ys[rows_v] * z
    evidence[:n_v] = noise_evidence(z, noise)
    if n_f:
        reach = min(float(no_return_range), max_range)  # type: ignore[arg-type]  # keep_free: not None
        counts.free_reach.add(reach)
        # A free ray ends at the depth `reach` along its pixel's ray.
        points[n_v:, 0] = reach
        points[n_v:, 1] = -xs[cols_f] * reach
        points[n_v:, 2] = -ys[rows_f] * reach
        evidence[n_v:] = 0.0
    counts.kept += n_v + n_f
    counts.free_rays += n_f
    return points, evidence


def rotation_from_quaternion(qx: float, qy: float, qz: float, qw: float) -> FloatArray:
    """The rotation matrix of a quaternion (normalised here; a zero quaternion is an error)."""
    q = np.array([qw, qx, qy, qz], dtype=np.float64)
    norm = float(np.linalg.norm(q))
    if not (math.isfinite(norm) and norm > 1e-9):
        raise InputError(f"quaternion ({qx}, {qy}, {qz}, {qw}) is zero or not finite")
    w, x, y, z = q / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def check_rigid(matrix: ArrayLike, where: str) -> FloatArray:
    """A 4x4 rigid transform, checked: finite, a rotation block (orthonormal, det +1), last row 0 0 0 1."""
    try:
        m = np.asarray(matrix, dtype=np.float64).reshape(4, 4)
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected a 4x4 matrix (16 numbers)") from None
    if not np.isfinite(m).all():
        raise InputError(f"{where}: the pose holds a value that is NaN or infinite")
    if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0], atol=1e-6):
        raise InputError(f"{where}: the pose's last row is {m[3].tolist()}, not 0 0 0 1")
    r = m[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-3) or np.linalg.det(r) < 0.0:
        raise InputError(f"{where}: the pose's 3x3 block is not a rotation")
    return m


def level_rotation(up: ArrayLike) -> FloatArray:
    """The rotation taking the unit vector ``up`` (world frame) onto +z, turning about the
    axis ``up x z`` (the identity for ``up = z``)."""
    u = np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(u, z)
    s, c = float(np.linalg.norm(axis)), float(u @ z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * kx + (1 - c) * (kx @ kx)


def floor_mounting(points_optical: FloatArray) -> tuple[FloatArray, float, float] | None:
    """A camera's tilt, roll and height from the floor plane in its own points.

    ``points_optical`` are returns in the optical frame of a camera looking roughly
    level (its -y roughly up). Returns ``(rotation, height, tilt)``: the rotation taking
    optical coordinates into a frame with z up (the floor's normal) and x along the
    camera's heading, the camera's height above the floor plane in metres and its tilt in
    degrees (negative: looking down); ``None`` when no floor plane is found
    (:func:`estimate_floor`).
    """
    found = estimate_floor(points_optical, np.array([0.0, -1.0, 0.0]))
    if found is None:
        return None
    normal, offset, _ = found
    height = -offset  # the camera is at the origin, the floor below it
    if height <= 0.0:
        return None
    level = level_rotation(normal)
    forward = level @ np.array([0.0, 0.0, 1.0])
    yaw = math.atan2(forward[1], forward[0])
    c, s = math.cos(yaw), math.sin(yaw)
    rotation = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ level
    tilt = math.degrees(math.asin(max(-1.0, min(1.0, float((rotation @ np.array([0.0, 0.0, 1.0]))[2])))))
    return rotation, float(height), tilt


def camera_scan(points_body: FloatArray, camera_to_world: FloatArray) -> tuple[FloatArray, Pose]:
    """Camera-body points (REP-103 axes at the camera) and the camera's pose in a z-up world.

    ``camera_to_world`` is the 4x4 pose of the camera's *optical* frame in a world frame
    whose z points up. Returns the points rotated into the frame centred at the camera
    with z up and x along the camera's heading (the roll and tilt applied, the heading
    not), and the :class:`Pose` (camera position and heading).
    """
    r_world_body = camera_to_world[:3, :3] @ OPTICAL_TO_BODY.T
    return body_scan(points_body, r_world_body, camera_to_world[:3, 3])


def body_scan(points_body: FloatArray, r_world_body: FloatArray, translation: ArrayLike) -> tuple[FloatArray, Pose]:
    """Points in a sensor's body frame (REP-103: x forward, z up) and the body's rotation and
    position in a z-up world: the points rotated into the frame centred at the sensor with
    z up and x along its heading (its roll and pitch applied, its heading not), and the
    :class:`Pose` (position and heading) of that frame. A depth camera
    (:func:`camera_scan`) and a lidar scan with its scan-to-world transform
    (:mod:`occtool.io.scans`) are placed so.
    """
    forward = r_world_body[:, 0]
    if math.hypot(forward[0], forward[1]) > 1e-9:
        yaw = math.atan2(forward[1], forward[0])
    else:  # looking straight up or down: the heading is the body's y axis turned back
        left = r_world_body[:, 1]
        yaw = math.atan2(-left[0], left[1])
    c, s = math.cos(yaw), math.sin(yaw)
    unturn = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    rotation = unturn @ r_world_body
    t = np.asarray(translation, dtype=np.float64)
    return points_body @ rotation.T, Pose(float(t[0]), float(t[1]), float(t[2]), yaw)


def estimate_floor(points: FloatArray, up_guess: FloatArray, *, seed: int = 0, tolerance: float = 0.03,
                   groups: NDArray[np.intp] | None = None, origins: FloatArray | None = None
                   ) -> tuple[FloatArray, float, int] | None:
    """The floor plane of world points: the lowest large horizontal surface that many
    positions see, never merely the plane of most points (a table top seen from above holds
    more returns than the floor round it).

    The floor's normal comes first: the plane of most inliers (within ``tolerance``) whose
    normal lies within 30 degrees of ``up_guess``, among the lowest 40 % of the points (the
    floor or a table top: horizontal surfaces share their normal). Along it, each position
    (``groups``: a position index per point, all one position without) gives its lowest
    large layer below its sensor (``origins``: each position's sensor in the points' frame;
    without, every point counts) and the floor is where many of them agree
    (:func:`occtool._floor.lowest_layer`, :func:`occtool._floor.common_floor`). The plane
    is then fitted to the returns near that floor (within ``tolerance``, then half of it).

    Gravity is not in the poses of the folders read here (TUM's motion-capture world has z
    up but its floor is wherever the capture system's origin was; 3DMatch's world is the
    first camera's), so the floor sets both up and height.

    Returns ``(unit normal pointing up, offset d with n . p = d on the floor, inliers)``, or
    ``None`` when no horizontal plane holds 5 % of the points or no floor is supported.
    """
    from occtool._floor import LAYER, common_floor, lowest_layer

    if points.shape[0] < 50:
        return None
    up = up_guess / np.linalg.norm(up_guess)
    heights = points @ up
    low = points[heights <= np.quantile(heights, 0.4)]
    rng = np.random.default_rng(seed)
    best: tuple[FloatArray, float, int] | None = None
    cos_limit = math.cos(math.radians(30.0))
    for _ in range(300):
        a, b, c = low[rng.choice(low.shape[0], 3, replace=False)]
        normal = np.cross(b - a, c - a)
        length = float(np.linalg.norm(normal))
        if length < 1e-9:
            continue
        normal /= length
        if normal @ up < 0:
            normal = -normal
        if normal @ up < cos_limit:
            continue
        offset = float(normal @ a)
        inliers = int(np.count_nonzero(np.abs(points @ normal - offset) < tolerance))
        if best is None or inliers > best[2]:
            best = (normal, offset, inliers)
    if best is None or best[2] < 0.05 * points.shape[0]:
        return None
    # The height: each position's lowest large layer along that normal, where many agree.
    level = level_rotation(best[0])
    levelled = points @ level.T
    group = np.zeros(points.shape[0], dtype=np.intp) if groups is None else np.asarray(groups, dtype=np.intp)
    order = np.argsort(group, kind="stable")
    ids, first = np.unique(group[order], return_index=True)
    tops = (np.full(ids.size, np.inf) if origins is None
            else (np.asarray(origins, dtype=np.float64)[ids] @ level.T)[:, 2])
    layers = np.full(ids.size, np.nan)
    for k, part in enumerate(np.split(order, first[1:])):  # a loop over positions, not points
        found = lowest_layer(levelled[part], tops[k])
        if found is not None:
            layers[k] = found[0]
    floor = common_floor(layers)
    if floor is None:
        return None
    # Refine: the least-squares plane of the returns near that floor, in narrowing bands (the
    # normal of a small table top may tilt a wide floor out of a narrow band at first; the
    # narrowest leaves out what stands on the floor, the feet of walls and boxes).
    normal, offset = best[0], float(floor[0])  # levelled z is the height along best[0]
    for band in (max(tolerance, LAYER / 2.0), tolerance, tolerance / 2.0):
        inlier_points = points[np.abs(points @ normal - offset) < band]
        if inlier_points.shape[0] < 3:
            return None
        centre = inlier_points.mean(axis=0)
        _, _, vt = np.linalg.svd(inlier_points - centre, full_matrices=False)
        refined = vt[2] if vt[2] @ up > 0 else -vt[2]
        if refined @ up < cos_limit:
            return None
        normal, offset = refined, float(refined @ centre)
    return normal, offset, int(np.count_nonzero(np.abs(points @ normal - offset) < tolerance))


__all__ = [
    "DEFAULT_DEPTH_FEATURES",
    "DEFAULT_DEPTH_MAX_RANGE",
    "DEFAULT_DEPTH_MIN_RANGE",
    "DEFAULT_DEPTH_NOISE",
    "estimate_floor",
    "OPTICAL_TO_BODY",
    "DepthCounts",
    "MAX_IMAGE_PIXELS",
    "PinholeCamera",
    "back_project",
    "camera_scan",
    "check_depth_features",
    "check_depth_max_range",
    "check_depth_noise",
    "check_image_size",
    "check_png",
    "check_rigid",
    "decode_png",
    "floor_mounting",
    "level_rotation",
    "noise_evidence",
    "rotation_from_quaternion",
]
