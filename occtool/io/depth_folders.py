"""Folders of depth images with camera poses: TUM RGB-D and 3DMatch / 7-Scenes.

``tum``
    The TUM RGB-D benchmark's layout: ``depth.txt`` (lines ``timestamp filename``, ``#``
    comments) naming 16-bit PNGs of depth times 5000 (0 = no measurement), and
    ``groundtruth.txt`` (``timestamp tx ty tz qx qy qz qw``, the camera's optical frame
    in the motion-capture world, z up). Each depth frame takes the ground-truth pose
    nearest in time within 0.02 s (TUM's ``associate.py``); frames without one are
    dropped (noted). Intrinsics: ``camera-intrinsics.txt`` beside ``depth.txt`` if there is
    one (a 3x3 K), else TUM's published values for a folder named ``*freiburg1*``,
    ``*freiburg2*`` or ``*freiburg3*``, else the ROS default 525, 525, 319.5, 239.5 (noted).
    freiburg1's and freiburg2's published distortion is ignored (one warning).
``3dmatch``
    3DMatch and 7-Scenes: ``frame-NNNNNN.depth.png`` (16-bit millimetres, 0 and 65535 =
    no measurement) with ``frame-NNNNNN.pose.txt`` (the camera-to-world 4x4), in the
    folder or in its ``seq-*`` sub-folders, and ``camera-intrinsics.txt`` (3x3 K) in the
    folder or its parent; without one, 7-Scenes' Kinect 585, 585, 320, 240 (noted). Their
    world frame is the first camera's (KinectFusion), not level: "up" is estimated from
    the floor plane (noted, with a warning when no floor is found).

The log's path is the folder, or (so that every command accepts it as a file) its
``depth.txt`` or ``camera-intrinsics.txt``. Each frame is a scan (:func:`occtool.io.depth.back_project`,
then :func:`occtool.io.depth.camera_scan`), grouped into positions like any log's.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Note, RangeLog
from occtool.io.depth import (
    DEFAULT_DEPTH_MIN_RANGE,
    DepthCounts,
    PinholeCamera,
    back_project,
    camera_scan,
    check_image_size,
    check_rigid,
    decode_png,
    estimate_floor,
    level_rotation,
    rotation_from_quaternion,
)
from occtool.io.positions import Scan, build_log, check_pose
from occtool.io.read_options import ReadOptions, as_read_options, options_as_keywords

FloatArray = NDArray[np.float64]

#: TUM RGB-D's depth PNGs hold metres times this.
TUM_DEPTH_FACTOR = 5000.0
#: Largest time difference between a depth frame and its ground-truth pose, seconds.
TUM_MAX_POSE_GAP = 0.02
#: TUM's published intrinsics per camera (fx, fy, cx, cy), and the ROS default.
TUM_INTRINSICS = {
    "freiburg1": (517.3, 516.5, 318.6, 255.3),
    "freiburg2": (520.9, 521.0, 325.1, 249.7),
    "freiburg3": (535.4, 539.2, 320.1, 247.6),
}
ROS_DEFAULT_INTRINSICS = (525.0, 525.0, 319.5, 239.5)
#: TUM's cameras whose published calibration has lens distortion (freiburg3's images are undistorted).
TUM_DISTORTED = ("freiburg1", "freiburg2")
#: 7-Scenes' Kinect (fx, fy, cx, cy), for a folder without ``camera-intrinsics.txt``.
SEVEN_SCENES_INTRINSICS = (585.0, 585.0, 320.0, 240.0)
#: Most depth frames one folder may name.
MAX_FRAMES = 1_000_000
DEPTH_FORMATS = ("tum", "3dmatch")

_FRAME = re.compile(r"^frame-(\d+)\.depth\.png$")


def _frames_in(folder: Path) -> list[Path]:
    """``frame-*.depth.png`` in the folder, or else in its ``seq-*`` sub-folders, in order."""
    if not folder.is_dir():
        return []
    own = sorted(p for p in folder.iterdir() if _FRAME.match(p.name))
    if own:
        return own
    found: list[Path] = []
    for sub in sorted(p for p in folder.iterdir() if p.is_dir() and p.name.startswith("seq")):
        found.extend(sorted(p for p in sub.iterdir() if _FRAME.match(p.name)))
    return found


def _has_frames(folder: Path) -> bool:
    if not folder.is_dir():
        return False
    for p in folder.iterdir():
        if _FRAME.match(p.name):
            return True
    for sub in folder.iterdir():
        if sub.is_dir() and sub.name.startswith("seq") and any(_FRAME.match(p.name) for p in sub.iterdir()):
            return True
    return False


def depth_layout(path: str | os.PathLike[str]) -> str | None:
    """``"tum"`` or ``"3dmatch"`` when ``path`` is such a folder (or its ``depth.txt`` /
    ``camera-intrinsics.txt``), else ``None``. Looks at names only; a ``camera-intrinsics.txt``
    outside such a folder is an :class:`InputError` (it is no log)."""
    target = Path(path)
    try:
        if target.is_dir():
            if (target / "depth.txt").is_file():
                return "tum"
            return "3dmatch" if _has_frames(target) else None
        if target.name == "depth.txt":
            return "tum"
        if target.name == "camera-intrinsics.txt":
            if (target.parent / "depth.txt").is_file():
                return "tum"
            if _has_frames(target.parent):
                return "3dmatch"
    except OSError:
        return None
    if target.name == "camera-intrinsics.txt":
        # Read as a log, its nine numbers would be taken as points.
        raise InputError(f"{target} holds a depth camera's intrinsics, not range data, and lies in no depth "
                         "folder: give the folder of depth frames, or a TUM folder's depth.txt")
    return None


def read_depth_png(path: Path) -> NDArray[np.generic]:
    """A single-channel depth PNG (16-bit, or 32-bit integer or float) as an array, through Pillow.

    The size is read from the PNG's header and checked before the file is read whole and
    decoded (:func:`occtool.io.depth.check_png`: at most :data:`~occtool.io.depth.MAX_IMAGE_PIXELS`
    pixels, every row present, IEND at the end).

    Raises
    ------
    MissingDependencyError
        Without Pillow (the ``depth`` extra).
    InputError
        For a truncated or corrupt file, a size beyond the limits, or an image that is not one
        greyscale depth channel.
    """
    import struct

    where = f"{path} is not a readable depth image"
    try:
        with open(path, "rb") as handle:
            head = handle.read(33)
            if len(head) >= 24 and head[12:16] == b"IHDR":
                width, height = struct.unpack(">II", head[16:24])
                check_image_size(width, height, where)
                # 16-bit RGBA is 8 bytes a pixel; zlib's worst case and ancillary chunks fit in the MB.
                limit = width * height * 8 + (1 << 20)
            else:
                limit = 64  # check_png refuses it: no need to read on
            data = head + handle.read(limit + 1 - len(head))
    except FileNotFoundError:
        raise InputError(f"{path}: the depth image does not exist") from None
    except OSError as exc:
        raise InputError(f"{where} ({exc.strerror or exc})") from None
    if len(data) > limit:
        raise InputError(f"{where}: a PNG larger than its pixels could fill (over {limit:,} bytes)")
    return decode_png(data, where)


def _numbers(path: Path) -> FloatArray:
    """A small text matrix (numpy's loadtxt; an empty file is a (0, ...) array, not a warning)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return np.loadtxt(path, dtype=np.float64, ndmin=2)


def _matrix(path: Path, size: int, what: str) -> FloatArray:
    """The ``size`` x ``size`` matrix of numbers in ``path``; ``what`` names it in the error."""
    shape = f"{size}x{size}"
    try:
        values = _numbers(path)
    except (ValueError, OSError) as exc:
        raise InputError(f"{path}: {what} must be a {shape} matrix of numbers ({exc})") from None
    if values.shape != (size, size):
        raise InputError(f"{path}: {what} must be a {shape} matrix of numbers, got shape {values.shape}")
    return values


def _read_k(path: Path) -> FloatArray:
    """The 3x3 K of ``camera-intrinsics.txt``, checked to be a pinhole's (fx, fy > 0, no skew,
    last row 0 0 1): any other matrix would place every point wrongly."""
    k = _matrix(path, 3, "camera intrinsics")
    _check_pinhole(k, path)
    return k


def _inside(folder: Path, name: str, where: str) -> Path:
    candidate = (folder / name).resolve()
    if not candidate.is_relative_to(folder.resolve()):
        raise InputError(f"{where}: {name!r} lies outside the dataset's folder")
    return candidate


@dataclass
class _Frame:
    image: Path
    pose: FloatArray | None  # camera (optical) to world, 4x4
    stamp: float | None
    source: str


def _tum_frames(folder: Path, notes: list[str]) -> tuple[list[_Frame], tuple[float, float, float, float], bool]:
    listing = folder / "depth.txt"
    frames: list[tuple[float, Path, str]] = []
    with open(listing, encoding="utf-8", errors="replace") as handle:
        for number, line in enumerate(handle, 1):
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            where = f"{listing}, line {number}"
            parts = text.split()
            try:
                stamp = float(parts[0])
            except (ValueError, IndexError):
                raise InputError(f"{where}: expected 'timestamp filename', got {text[:60]!r}") from None
            if len(parts) != 2 or not math.isfinite(stamp):
                raise InputError(f"{where}: expected 'timestamp filename', got {text[:60]!r}")
            frames.append((stamp, _inside(folder, parts[1], where), where))
            if len(frames) > MAX_FRAMES:
                raise InputError(f"{listing} names more than {MAX_FRAMES:,} frames")
    if not frames:
        raise InputError(f"{listing} names no depth frames")
    truth = folder / "groundtruth.txt"
    poses: list[tuple[float, FloatArray]] = []
    if truth.is_file():
        with open(truth, encoding="utf-8", errors="replace") as handle:
            for number, line in enumerate(handle, 1):
                text = line.strip()
                if not text or text.startswith("#"):
                    continue
                where = f"{truth}, line {number}"
                try:
                    values = [float(v) for v in text.split()]
                except ValueError:
                    raise InputError(f"{where}: expected 'timestamp tx ty tz qx qy qz qw'") from None
                if len(values) != 8 or not all(math.isfinite(v) for v in values):
                    raise InputError(f"{where}: expected 8 finite numbers 'timestamp tx ty tz qx qy qz qw'")
                check_pose(where, values[1:4], quaternion=values[4:8])
                rotation = rotation_from_quaternion(*values[4:8])
                matrix = np.eye(4)
                matrix[:3, :3] = rotation
                matrix[:3, 3] = values[1:4]
                poses.append((values[0], matrix))
    else:
        notes.append(Note.warn(f"{folder} has no groundtruth.txt: the frames have no poses"))
    result: list[_Frame] = []
    if poses:
        poses.sort(key=lambda item: item[0])
        times = np.array([t for t, _ in poses])
        unposed = 0
        for stamp, image, where in frames:
            i = int(np.searchsorted(times, stamp))
            best = min((j for j in (i - 1, i) if 0 <= j < len(times)), key=lambda j: abs(times[j] - stamp))
            if abs(times[best] - stamp) > TUM_MAX_POSE_GAP:
                unposed += 1
                continue
            result.append(_Frame(image, poses[best][1], stamp, where))
        if unposed:
            notes.append(Note.warn(f"dropped {unposed} depth frame(s) without a ground-truth pose within "
                                   f"{TUM_MAX_POSE_GAP:g} s"))
        if not result:
            raise InputError(f"{folder}: no depth frame has a ground-truth pose within {TUM_MAX_POSE_GAP:g} s")
    else:
        result = [_Frame(image, None, stamp, where) for stamp, image, where in frames]
    own = folder / "camera-intrinsics.txt"
    if own.is_file():
        k = _read_k(own)
        intrinsics = (k[0, 0], k[1, 1], k[0, 2], k[1, 2])
    else:
        name = folder.resolve().name.lower()
        key = next((key for key in TUM_INTRINSICS if key in name), None)
        if key is not None:
            intrinsics = TUM_INTRINSICS[key]
            notes.append(f"intrinsics: TUM's {key} camera {intrinsics} (fx, fy, cx, cy; from the folder's name)")
            if key in TUM_DISTORTED:
                notes.append(Note.warn(
                    f"warning: TUM's {key} camera has lens distortion (its published d0-d4), ignored: "
                    "the images are back-projected through the pinhole K alone (undistorting them "
                    "needs OpenCV, not a dependency)"))
        else:
            intrinsics = ROS_DEFAULT_INTRINSICS
            notes.append(Note.warn(
                f"no camera-intrinsics.txt: the ROS default intrinsics {intrinsics} (fx, fy, cx, cy) "
                "were taken"))
    return result, intrinsics, True


def _match_frames(folder: Path, notes: list[str]) -> tuple[list[_Frame], tuple[float, float, float, float], bool]:
    images = _frames_in(folder)
    if not images:
        raise InputError(f"{folder} holds no frame-NNNNNN.depth.png")
    if len(images) > MAX_FRAMES:
        raise InputError(f"{folder} holds more than {MAX_FRAMES:,} frames")
    frames: list[_Frame] = []
    for image in images:
        pose_file = image.with_name(image.name.replace(".depth.png", ".pose.txt"))
        where = str(pose_file)
        if not pose_file.is_file():
            raise InputError(f"{image}: its pose file {pose_file.name} is missing")
        values = _matrix(pose_file, 4, "a pose")
        if not np.isfinite(values).all():
            # 7-Scenes and 3DMatch mark a frame whose tracking failed with -inf or NaN poses.
            notes.append(Note.warn(f"{pose_file.name}: the pose is not finite (tracking lost): frame dropped"))
            continue
        check_pose(where, values[:3, 3], rotation=values[:3, :3])
        frames.append(_Frame(image, check_rigid(values, where), None, f"{image.parent.name}/{image.name}"))
    intrinsics_file = next((p for p in (folder / "camera-intrinsics.txt", folder.parent / "camera-intrinsics.txt")
                            if p.is_file()), None)
    if intrinsics_file is not None:
        k = _read_k(intrinsics_file)
        intrinsics = (k[0, 0], k[1, 1], k[0, 2], k[1, 2])
    else:
        intrinsics = SEVEN_SCENES_INTRINSICS
        notes.append(f"no camera-intrinsics.txt: 7-Scenes' Kinect intrinsics {intrinsics} (fx, fy, cx, cy) were taken")
    if not frames:
        raise InputError(f"{folder}: no frame has a finite pose")
    return frames, intrinsics, False


def _check_pinhole(k: FloatArray, where: Path) -> None:
    try:
        PinholeCamera.from_matrix(1, 1, k)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None


class DepthFolderScans:
    """The frames of a TUM RGB-D or 3DMatch / 7-Scenes folder as scans, read one frame at a
    time (an iterable of :class:`~occtool.io.positions.Scan`, for
    :func:`occtool.io.iter_positions`; :func:`read_depth_folder` gathers them).

    :meth:`prepare` lists the frames and their poses, reads the intrinsics and the first
    frame (the image size), and levels the world from the floor in up to 40 frames; each
    iteration then reads every frame's PNG again, holding one frame at a time. ``notes``
    is complete after a full iteration. Parameters are those of :func:`read_depth_folder`.
    """

    def __init__(self, path: str | os.PathLike[str], options: ReadOptions | None = None, **keywords: Any) -> None:
        settings = self.settings = as_read_options(options, **keywords)
        self.target = Path(path)
        self.name = str(path)
        self.folder = self.target if self.target.is_dir() else self.target.parent
        self.layout = settings.format or depth_layout(self.target)
        if self.layout not in DEPTH_FORMATS:
            raise InputError(f"{self.target} is neither a TUM RGB-D folder (depth.txt) nor a 3DMatch / 7-Scenes "
                             "folder (frame-NNNNNN.depth.png with .pose.txt)")
        self.skip_invalid = settings.skip_invalid
        self.no_return_range = settings.no_return_range
        self.features, self.noise, self.max_range = settings.depth_features, settings.depth_noise, settings.depth_max_range
        self.notes: list[str] = []
        self._prepared = False

    def _image(self, frame: _Frame) -> NDArray[np.generic] | None:
        """The frame's depth image, checked against the camera; ``None`` for an unreadable one with skip_invalid."""
        try:
            image = read_depth_png(frame.image)
        except InputError as exc:
            if not self.skip_invalid:
                raise InputError(f"{exc} (pass skip_invalid=True to drop such frames)") from None
            return None
        if image.dtype == np.uint16:
            image = np.where(image == np.iinfo(np.uint16).max, np.uint16(0), image)  # 7-Scenes' invalid
        camera = getattr(self, "camera", None)
        if camera is not None and image.shape != (camera.height, camera.width):
            raise InputError(f"{frame.image}: depth image of {image.shape[1] if image.ndim > 1 else '?'}x"
                             f"{image.shape[0]} pixels, where the folder's first is {camera.width}x{camera.height}")
        return image

    def _project(self, image: NDArray[np.generic], index: int, budget: int, counts: DepthCounts | None
                 ) -> tuple[FloatArray, FloatArray]:
        return back_project(image, self.camera, scale=self.scale, min_range=DEFAULT_DEPTH_MIN_RANGE,
                            max_range=self.max_range, no_return_range=self.no_return_range, noise=self.noise,
                            budget=budget, phase=index, counts=counts)

    def prepare(self) -> None:
        """Frames, poses, intrinsics, image size and the levelled world (see the class)."""
        if self._prepared:
            return
        notes: list[str] = []
        if self.layout == "tum":
            self.frames, intrinsics, z_up = _tum_frames(self.folder, notes)
            self.scale = 1.0 / TUM_DEPTH_FACTOR
        else:
            self.frames, intrinsics, z_up = _match_frames(self.folder, notes)
            self.scale = 1e-3
        first = None
        for frame in self.frames:
            first = self._image(frame)
            if first is not None:
                break
        if first is None:
            raise InputError(f"{self.target} holds no readable depth frame")
        height, width = first.shape[:2] if first.ndim >= 2 else (0, 0)
        self.camera = PinholeCamera(width, height, *intrinsics)
        if first.ndim != 2:
            raise InputError(f"{self.target}: a depth image must be one channel, got shape {first.shape}")
        self.level, self.floor_offset = np.eye(4), 0.0
        posed = [(i, f) for i, f in enumerate(self.frames) if f.pose is not None]
        if posed:
            picks = np.linspace(0, len(posed) - 1, min(40, len(posed))).astype(int)
            sample = []
            for k in picks:
                index, frame = posed[k]
                image = self._image(frame)
                if image is not None:
                    points, evidence = self._project(image, index, 2000, None)
                    sample.append((points, evidence, frame))
            if sample:
                self.level, self.floor_offset, floor_notes = _level_world(sample, z_up)
                notes += floor_notes
        self.unposed: tuple[FloatArray | None, tuple[FloatArray, float, float] | None] | None = None
        unposed = next((f for f in self.frames if f.pose is None), None)
        if unposed is not None:
            from occtool.io.depth import OPTICAL_TO_BODY, floor_mounting

            image = self._image(unposed)
            found = None
            if image is not None:
                points, evidence = self._project(image, 0, 100_000, None)
                found = floor_mounting((points @ OPTICAL_TO_BODY)[evidence > 0.0])
            self.unposed = (None if found is None else found[0] @ OPTICAL_TO_BODY.T, found)
            if found is None:
                notes.append(Note.warn(
                    "warning: frames without a pose, and no floor plane in the first: the camera taken as "
                    "level (optical axis horizontal)"))
            else:
                notes.append(Note.warn(
                    f"warning: frames without a pose: the camera's tilt ({found[2]:.1f} degrees) and "
                    f"height ({found[1]:.2f} m) estimated from the floor plane in the first; give the fit "
                    f"--sensor-height {found[1]:.2f}"))
        self._notes = notes
        self._prepared = True

    @property
    def to_log_frame(self) -> FloatArray:
        """``(4, 4)``: the rigid transform from the folder's own poses' frame to the levelled
        frame its scans are placed in (the floor at z = 0)."""
        self.prepare()
        moved = np.array(self.level, dtype=np.float64)
        moved[2, 3] -= self.floor_offset
        return moved

    def __iter__(self) -> Iterator[Scan]:
        self.prepare()
        self.notes.clear()
        counts = DepthCounts()
        heights: list[float] = []
        unreadable = 0
        for index, frame in enumerate(self.frames):
            image = self._image(frame)
            if image is None:
                unreadable += 1
                continue
            points, evidence = self._project(image, index, self.features, counts)
            if frame.pose is None:
                rotation = self.unposed[0] if self.unposed is not None else None
                yield Scan(points if rotation is None else points @ rotation.T, evidence, None, frame.stamp,
                           frame.source)
                continue
            world = self.level @ frame.pose
            world[2, 3] -= self.floor_offset
            moved, pose = camera_scan(points, world)
            heights.append(pose.z)
            yield Scan(moved, evidence, pose, frame.stamp, frame.source)
        notes = list(self._notes)
        if unreadable:
            notes.append(Note.warn(f"skipped {unreadable} depth frame(s) whose image could not be read"))
        if heights and self.floor_offset != 0.0:
            notes.append(f"camera heights above the floor: median {np.median(heights):.2f} m "
                         f"({min(heights):.2f} to {max(heights):.2f} m); give the fit --sensor-height "
                         f"{np.median(heights):.2f}")
        notes += counts.notes(self.no_return_range, self.max_range)
        self.notes.extend(notes)


def read_depth_folder(path: str | os.PathLike[str], options: ReadOptions | None = None, **keywords: Any) -> RangeLog:
    """Read a TUM RGB-D or 3DMatch / 7-Scenes folder (see the module) into positions.

    ``options`` and ``keywords`` are those of :func:`occtool.io.read_log` (a
    :class:`~occtool.io.ReadOptions` and its fields by name): ``format`` (``"tum"`` or
    ``"3dmatch"``; by default from the folder), ``position_tolerance``, ``group_by``,
    ``no_return_range``, the ``depth_*`` options, and ``skip_invalid``, which drops frames
    whose image cannot be read (counted in a note) instead of failing.
    """
    scans = DepthFolderScans(path, options, **keywords)
    listed = list(scans)
    log = build_log(listed, source=scans.name, tolerance=scans.settings.position_tolerance,
                    group_by=scans.settings.group_by, notes=scans.notes)
    if any(scan.pose is not None for scan in listed):
        log.to_log_frame = scans.to_log_frame
    return log


options_as_keywords(read_depth_folder)
options_as_keywords(DepthFolderScans)


def _level_world(posed: list[tuple[FloatArray, FloatArray, _Frame]], z_up: bool
                 ) -> tuple[FloatArray, float, list[str]]:
    """The rotation (4x4) levelling the world, the floor's height in the levelled world, notes."""
    notes: list[str] = []
    first = posed[0][2].pose
    assert first is not None
    guess = np.array([0.0, 0.0, 1.0]) if z_up else -(first[:3, :3] @ np.array([0.0, 1.0, 0.0]))
    # Up to 40 frames' returns, 2,000 each, in world coordinates.
    picks = np.linspace(0, len(posed) - 1, min(40, len(posed))).astype(int)
    clouds = []
    from occtool.io.depth import OPTICAL_TO_BODY

    for i in picks:
        points, evidence, frame = posed[i]
        assert frame.pose is not None
        hits = points[evidence > 0.0]
        if hits.shape[0] > 2000:
            hits = hits[np.linspace(0, hits.shape[0] - 1, 2000).astype(int)]
        optical = hits @ OPTICAL_TO_BODY  # body -> optical (OPTICAL_TO_BODY is orthonormal)
        clouds.append(optical @ frame.pose[:3, :3].T + frame.pose[:3, 3])
    cloud = np.concatenate(clouds) if clouds else np.empty((0, 3))
    # Each frame is a position of its own: the floor is the lowest large layer many frames
    # see below their camera, not the plane of most returns (a table top seen from above).
    groups = np.repeat(np.arange(len(clouds)), [c.shape[0] for c in clouds])
    origins = np.array([posed[i][2].pose[:3, 3] for i in picks]).reshape(-1, 3)
    floor = estimate_floor(cloud, guess, groups=groups, origins=origins)
    if floor is None:
        if z_up:
            notes.append("no floor plane found in the frames: the world's z is taken as up and heights as given")
            return np.eye(4), 0.0, notes
        notes.append(Note.warn("warning: the poses' world is not level and no floor plane was found: up taken as the "
                               "first camera's -y axis (give level poses, or frames that see the floor)"))
        level = np.eye(4)
        level[:3, :3] = level_rotation(guess)
        return level, 0.0, notes
    normal, offset, inliers = floor
    tilt = math.degrees(math.acos(min(1.0, float(normal @ guess) / float(np.linalg.norm(guess)))))
    if z_up:
        notes.append(f"floor plane found ({inliers:,} of {cloud.shape[0]:,} sampled returns, {tilt:.1f} degrees "
                     f"from the world's z): heights measured from it")
        if tilt > 5.0:
            notes.append(Note.warn(
                "warning: the floor is tilted more than 5 degrees from the world's z; the world's z is "
                "kept as up"))
        return np.eye(4), float(offset / normal[2]), notes
    notes.append(Note.warn(f"warning: the poses' world (3DMatch / 7-Scenes: the first camera's) is not level: up "
                           f"estimated from the floor plane ({inliers:,} of {cloud.shape[0]:,} sampled returns, "
                           f"{tilt:.1f} degrees from the first camera's -y axis)"))
    level = np.eye(4)
    level[:3, :3] = level_rotation(normal)
    return level, offset, notes


__all__ = ["DEPTH_FORMATS", "DepthFolderScans", "TUM_DEPTH_FACTOR", "depth_layout", "estimate_floor", "read_depth_folder",
           "read_depth_png"]
