"""An independent 3D held-out score of ``occtool map`` on depth cameras and 3D lidars (issue 35).

Written as a reviewer of a mapping paper would score a map, sharing no code with occtool's
model, fusion, grids or scoring: numpy and Pillow only (and pyoctomap for the OctoMap rows),
with its own readers (TUM RGB-D depth folders, PCD, KITTI poses), split, ray sampling, 3D
voxel traversal, log-odds grids, PGM reader and AUC. occtool is run as a user runs it,
``python -m occtool -q map TRAIN -o DIR ...`` in a subprocess, and its outputs are read
from disk. The only occtool names imported are ``occtool.errors.InputError`` (one-line
errors) and ``occtool.fuse.load_map`` (to read ``DIR/world.occmap``).

Protocol:

* Sequences (:data:`SEQUENCES`): the TUM cabinet (``fixtures/tum-fr3-cabinet``, 58 real
  Kinect frames) and the rendered depth office walk (``fixtures/depth-office``, 8 frames),
  TUM layout (``depth.txt``, 16-bit PNGs of metres x 5000, ``camera-intrinsics.txt``, the
  optical frame's pose in ``groundtruth.txt``, nearest stamp within 0.02 s); and two real
  3D lidar runs under the data folder (``../shared/data`` from the repository root):
  ``lidar_seosan01`` (21 scans, ~60k points each, outdoors) and ``lidar_livox_quickshack``
  (241 Livox scans of 3-5k points, hand-held, turning in place): binary PCD (the points, any
  padding after them ignored), ``optimized_poses.txt`` line i a row-major 3x4 scan-to-world
  transform of ``Scans/%06d.pcd`` i, lines beyond the scans ignored.
* Rays: one a valid depth pixel (depth 0 dropped) or a lidar point, from the frame's
  origin (the camera's optical centre; the scan pose's position); rays shorter than 0.1 m
  (lidar: 0.5 m) dropped; a ray longer than the sequence's max range (8 m depth, 20 m
  lidar; the same for every method and for scoring) is cut there as a free-only ray (no
  return). 20 m rather than 30 keeps the 0.05 m grids' traversal within the bench's CPU
  budget (Seosan: half its returns lie beyond 18 m).
* Split: blocks of consecutive frames (5 for the cabinet, 1 for the 8-frame office, 2 for
  Seosan, 10 for the Livox run), ``max(1, round(0.15 n / block))`` of them held out, picked
  by ``numpy.random.default_rng(seed)``. Every method gets the training frames only.
* Subsampling (so that the four sequences take a few minutes of CPU on one core): each
  training frame keeps ``train_rays`` rays drawn by the seeded generator (every method,
  occtool included: its depth budget ``--depth-features`` is set to the same number and the
  lidar CSV holds exactly these rays), each held-out frame ``test_rays``: 5,000 / 3,000 for
  the depth frames, 3,000 / 600 for Seosan's 60k-point scans, 600 / 250 for the Livox
  run's 3-5k-point scans (241 of them, 0.1 s apart).
* Test points, per kept held-out ray: the return is occupied (positive); points every 0.1 m
  from 0.1 m after the sensor to 0.1 m before the return (to the max range, for a cut ray)
  are free (negative).
* Floor and body band: depth, a flat floor the sequence's stated camera height below the
  training cameras' median z (the cabinet: 0.95 m, the median the TUM notes give; the
  office: 1.0 m, as rendered); lidar, the sensor's height H is the median over training
  positions of the position's z above its local ground (the lowest 0.1 m layer of training
  returns below the sensor within 5 m horizontally holding at least 30 % as many as the
  fullest such layer), and the floor under a point is the nearest (horizontally) training
  position's z less H (a sensor rigid on its vehicle follows a sloping road). The body band:
  test points 0.05 m up to the body height (the sensor's height: the robot that carries
  it) above the floor.
* Scores: AUC (probability that a random occupied point scores above a random free one,
  ranks with ties averaged, so a point a method does not know, 0.5, counts half) over all
  test points (3D) and over the body band; and the share of held-out returns on unknown
  (0.5 or unseen) space of each map.
* Rows: (a) ``world.occmap`` through ``occtool.fuse.load_map(path).predict(xyz)``: a 3D
  map (version 5 or 6 in the file's own header, read here) at the world x, y, z of the test
  points (it stores and applies the transform to the frame it levelled); a 2D map (version
  4) at (x, y, height above the floor above), the datum it answers in, 0.5 outside its band.
  (b) ``map.yaml`` + PGM (own reader; occupied 1, free 0, unknown 0.5) looked
  up at every point's x, y (moved into a 3D map's frame by the ``to_map`` of its header).
  (c) textbook 3D log-odds grids at 0.05 and 0.1 m (sparse voxel
  keys; each voxel updated at most once a frame: a hit where a return lands, else a miss
  where a ray crosses; clamped; unseen 0.5), ``l_occ``/``l_free``/clamp chosen over
  :data:`SETTINGS` by the AUC on an inner split of the training frames (the same block
  protocol on the training frames only); bytes: a byte a known voxel. (d) OctoMap through
  pyoctomap at 0.05 and 0.1 m, its default sensor model, ``insertPointCloud`` per frame
  with the frame's origin and the max range; bytes: the size of its own ``.bt`` file.
* occtool's input: the depth folder with a ``depth.txt`` listing the training frames only
  (the images and poses copied), ``--depth-features`` as above, ``--no-return-range 8``; lidar
  (``occtool map Scans/ --poses`` would read every point; the baselines get the kept rays
  only): the kept training rays as occtool's CSV (``x,y,z,m,pose_x,pose_y,pose_z,pose_yaw``:
  points in the sensor-centred frame turned by the scan's yaw, the pose the scan's world
  position and yaw, so that they put the points back exactly; ``m`` 0.9 for a return and 0
  for a ray cut at the max range, occtool's free-only ray); both with ``--sensor-height H
  --body-height H``, the map's kind and cell size left to occtool's defaults.
* Time: CPU seconds of each build (``time.process_time``; occtool the child's user+system
  CPU). Libraries run with one thread.

Standalone: ``python bench/heldout3d.py --sequence NAME [--seed S] [--json out.json]``;
``bench/run.py`` calls :func:`heldout3d_section`.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from occtool.errors import InputError  # noqa: E402

FloatArray = NDArray[np.float64]
DATA_DIR = ROOT.parent / "shared" / "data"

#: name -> kind, folder (relative to the repository or the data folder), block, max range,
#: rays kept per training / held-out frame, and (depth) the stated camera height.
SEQUENCES: dict[str, dict[str, Any]] = {
    "tum-fr3-cabinet": {"kind": "depth", "path": "fixtures/tum-fr3-cabinet", "block": 5, "max_range": 8.0,
                        "train_rays": 5000, "test_rays": 3000, "camera_height": 0.95},
    "depth-office": {"kind": "depth", "path": "fixtures/depth-office", "block": 1, "max_range": 8.0,
                     "train_rays": 5000, "test_rays": 3000, "camera_height": 1.0},
    "lidar_seosan01": {"kind": "lidar", "path": "lidar_seosan01", "block": 2, "max_range": 20.0,
                       "train_rays": 3000, "test_rays": 600},
    "lidar_livox_quickshack": {"kind": "lidar", "path": "lidar_livox_quickshack", "block": 10, "max_range": 20.0,
                               "train_rays": 600, "test_rays": 250},
}
HOLDOUT = 0.15
STEP = 0.1
MARGIN = 0.1
CLEARANCE = 0.05
RESOLUTIONS = (0.05, 0.1)
#: (l_occ, l_free, (clamp low, clamp high)) tried on the inner split.
SETTINGS = tuple((o, f, c) for o in (0.85, 1.5) for f in (-0.4, -0.1, -0.02) for c in ((-2.0, 3.5), (-1.0, 3.5)))
TUM_DEPTH_FACTOR = 5000.0
CHUNK_CROSSINGS = 4_000_000
#: Voxel keys: three 21-bit signed indices in one int64.
_BITS, _OFFSET = 21, 1 << 20


# ----------------------------------------------------------------------------- readers
def read_pcd(path: str | os.PathLike[str]) -> FloatArray:
    """``(N, 3)`` x, y, z of a PCD file (ascii or binary; bytes after the points ignored)."""
    path = Path(path)
    raw = path.read_bytes()
    header: dict[str, list[str]] = {}
    at = 0
    while True:
        end = raw.find(b"\n", at)
        if end < 0:
            raise InputError(f"{path}: PCD header without a DATA line")
        line = raw[at:end].decode("ascii", "replace").strip()
        at = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            break
    try:
        fields = header["FIELDS"]
        sizes = [int(v) for v in header["SIZE"]]
        types = header["TYPE"]
        counts = [int(v) for v in header.get("COUNT", ["1"] * len(fields))]
        n = int(header["POINTS"][0])
        data = header["DATA"][0].lower()
    except (KeyError, ValueError, IndexError):
        raise InputError(f"{path}: incomplete PCD header") from None
    if not {"x", "y", "z"} <= set(fields) or not len(fields) == len(sizes) == len(types) == len(counts):
        raise InputError(f"{path}: PCD fields must include x, y, z")
    if data == "ascii":
        table = np.loadtxt(raw[at:].decode("ascii").splitlines(), ndmin=2)[:n]
        column = np.cumsum([0, *counts])
        return np.column_stack([table[:, column[fields.index(a)]] for a in "xyz"]).astype(np.float64)
    if data != "binary":
        raise InputError(f"{path}: PCD DATA {data} is not read (ascii or binary only)")
    kinds = {"F": "f", "I": "i", "U": "u"}
    dtype = np.dtype([(f"{name}_{k}", f"<{kinds[t]}{s}", (c,)) for k, (name, s, t, c)
                      in enumerate(zip(fields, sizes, types, counts))])
    if len(raw) - at < n * dtype.itemsize:
        raise InputError(f"{path}: PCD holds fewer than its {n} points")
    records: Any = np.frombuffer(raw, dtype=dtype, count=n, offset=at)
    return np.column_stack([records[f"{a}_{fields.index(a)}"][:, 0] for a in "xyz"]).astype(np.float64)


def read_kitti_poses(path: str | os.PathLike[str]) -> FloatArray:
    """``(n, 4, 4)`` transforms from a KITTI-style file: 12 numbers a line, row-major 3x4."""
    rows = np.loadtxt(path, ndmin=2)
    if rows.shape[1] != 12:
        raise InputError(f"{path}: a KITTI pose line holds 12 numbers, not {rows.shape[1]}")
    out = np.tile(np.eye(4), (rows.shape[0], 1, 1))
    out[:, :3, :] = rows.reshape(-1, 3, 4)
    return out


def quaternion_matrix(q: FloatArray) -> FloatArray:
    """Rotation matrix of a quaternion ``(qx, qy, qz, qw)`` (normalised here)."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _table(path: Path) -> list[list[str]]:
    return [line.split() for line in path.read_text(encoding="utf-8").splitlines()
            if line.strip() and not line.lstrip().startswith("#")]


def read_tum(folder: str | os.PathLike[str]) -> tuple[list[tuple[str, Path, FloatArray]], FloatArray]:
    """A TUM RGB-D folder: ``(stamp text, depth PNG, 4x4 optical-to-world)`` per frame that has a
    ground-truth pose within 0.02 s, and the 3x3 intrinsics."""
    folder = Path(folder)
    truth = np.array([[float(v) for v in row[:8]] for row in _table(folder / "groundtruth.txt")])
    K = np.loadtxt(folder / "camera-intrinsics.txt").reshape(3, 3)
    frames = []
    for row in _table(folder / "depth.txt"):
        k = int(np.argmin(np.abs(truth[:, 0] - float(row[0]))))
        if abs(truth[k, 0] - float(row[0])) > 0.02:
            continue
        pose = np.eye(4)
        pose[:3, :3] = quaternion_matrix(truth[k, 4:8])
        pose[:3, 3] = truth[k, 1:4]
        frames.append((row[0], folder / row[1], pose))
    return frames, K


def depth_rays(png: Path, K: FloatArray, pose: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Origin and ``(N, 3)`` world end points of a depth PNG's valid pixels (0 dropped)."""
    from PIL import Image

    with Image.open(png) as image:
        z = np.asarray(image, dtype=np.float64) / TUM_DEPTH_FACTOR
    v, u = np.nonzero(z > 0.0)
    d = z[v, u]
    optical = np.column_stack([(u - K[0, 2]) * d / K[0, 0], (v - K[1, 2]) * d / K[1, 1], d])
    return pose[:3, 3].copy(), optical @ pose[:3, :3].T + pose[:3, 3]


@dataclass
class Frame:
    """One frame's rays: sensor ``origin`` (3,) and world ``end`` points (N, 3)."""

    origin: FloatArray
    end: FloatArray


def load_sequence(name: str, data_dir: Path) -> tuple[list[Frame], dict[str, Any]]:
    """The frames of a sequence of :data:`SEQUENCES`, every ray, in world coordinates."""
    spec = dict(SEQUENCES[name])
    if spec["kind"] == "depth":
        folder = ROOT / spec["path"]
        entries, K = read_tum(folder)
        frames = [Frame(*depth_rays(png, K, pose)) for _, png, pose in entries]
        spec.update(folder=folder, stamps=[stamp for stamp, _, _ in entries], min_range=0.1)
        return frames, spec
    folder = data_dir / spec["path"]
    scans = sorted((folder / "Scans").glob("*.pcd"))
    if not scans:
        raise InputError(f"{folder}: no Scans/*.pcd")
    poses = read_kitti_poses(folder / "optimized_poses.txt")
    frames = []
    for path in scans:
        pose = poses[int(path.stem)]
        points = read_pcd(path)
        points = points[np.isfinite(points).all(axis=1)]
        frames.append(Frame(pose[:3, 3].copy(), points @ pose[:3, :3].T + pose[:3, 3]))
    spec.update(folder=folder, min_range=0.5)
    return frames, spec


# ----------------------------------------------------------------------------- split and points
def held_out(n: int, block: int, seed: int, holdout: float = HOLDOUT) -> NDArray[np.bool_]:
    """``max(1, round(holdout n / block))`` random whole blocks of ``block`` frames."""
    blocks = math.ceil(n / block)
    take = max(1, round(holdout * n / block))
    if blocks < 2 or take >= blocks:
        raise InputError(f"{n} frames are too few to hold {holdout:.0%} out in blocks of {block}")
    out = np.zeros(n, dtype=bool)
    for b in np.random.default_rng(seed).choice(blocks, size=take, replace=False):
        out[b * block:(b + 1) * block] = True
    return out


def cut_rays(frame: Frame, keep: int, rng: np.random.Generator, min_range: float,
             max_range: float) -> tuple[FloatArray, NDArray[np.bool_]]:
    """At most ``keep`` of the frame's rays, drawn by ``rng``: end points, cut at ``max_range``
    (``hit`` False: a free-only ray), rays nearer than ``min_range`` dropped."""
    vector = frame.end - frame.origin
    length = np.linalg.norm(vector, axis=1)
    index = np.flatnonzero(length >= min_range)
    if index.size > keep:
        index = np.sort(rng.choice(index, size=keep, replace=False))
    vector, length = vector[index], length[index]
    hit = length <= max_range
    scale = np.where(hit, 1.0, max_range / np.maximum(length, 1e-12))
    return frame.origin + vector * scale[:, None], hit


def ray_points(origin: FloatArray, end: FloatArray, hit: NDArray[np.bool_]) -> tuple[FloatArray, FloatArray]:
    """Occupied (the returns) and free (every STEP m from STEP to MARGIN before the end) points."""
    vector = end - origin
    length = np.linalg.norm(vector, axis=1)
    count = np.maximum(np.floor((length - MARGIN) / STEP + 1e-9).astype(np.int64), 0)
    ray = np.repeat(np.arange(length.size), count)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count) + 1
    direction = vector / np.maximum(length, 1e-12)[:, None]
    return end[hit], origin + (k * STEP)[:, None] * direction[ray]


def auc(occupied: FloatArray, free: FloatArray) -> float:
    """ROC AUC: P(random occupied scores above random free), ties half (average ranks)."""
    occupied, free = np.asarray(occupied, float), np.asarray(free, float)
    if occupied.size == 0 or free.size == 0:
        return math.nan
    _, inverse, counts = np.unique(np.concatenate([occupied, free]), return_inverse=True, return_counts=True)
    ranks = (np.cumsum(counts) - (counts - 1) / 2.0)[inverse]
    n = occupied.size
    return float((ranks[:n].sum() - n * (n + 1) / 2.0) / (n * free.size))


def lidar_sensor_height(frames: list[Frame], train: NDArray[np.bool_]) -> float:
    """The sensor's height above the ground: the median, over the training positions, of the
    position's z above its local ground, the lowest 0.1 m layer of the training returns
    below the sensor within 5 m (horizontally) that holds at least 30 % as many as the
    fullest such layer (a third of each frame's returns used)."""
    points = np.concatenate([f.end[::3] for f, t in zip(frames, train) if t])
    heights = []
    for frame in (f for f, t in zip(frames, train) if t):
        o = frame.origin
        z = points[(np.hypot(points[:, 0] - o[0], points[:, 1] - o[1]) <= 5.0) & (points[:, 2] < o[2]), 2]
        if z.size < 100:
            continue
        low = math.floor(z.min() / 0.1)
        counts = np.bincount(np.floor(z / 0.1).astype(np.int64) - low)
        heights.append(o[2] - (low + int(np.flatnonzero(counts >= 0.3 * counts.max())[0]) + 0.5) * 0.1)
    if not heights:
        raise InputError("no ground found under the training positions")
    return float(np.median(heights))


def floor_under(xyz: FloatArray, positions: FloatArray, sensor_height: float) -> FloatArray:
    """The floor's z under world points: the nearest (horizontally) training position's z
    less the sensor height (a sensor rigid on its vehicle follows the ground's slope)."""
    from scipy.spatial import cKDTree

    _, nearest = cKDTree(positions[:, :2]).query(xyz[:, :2])
    return positions[nearest, 2] - sensor_height


# ----------------------------------------------------------------------------- voxels
def voxel_keys(index: NDArray[np.int64]) -> NDArray[np.int64]:
    """One int64 per ``(K, 3)`` voxel index."""
    shifted = index.astype(np.int64) + _OFFSET
    return (shifted[:, 0] << (2 * _BITS)) | (shifted[:, 1] << _BITS) | shifted[:, 2]


def crossed_voxels(start: FloatArray, end: FloatArray, resolution: float) -> tuple[NDArray[np.intp], NDArray[np.int64]]:
    """Ray number and ``(K, 3)`` voxel index of every voxel each segment crosses (the pieces
    between its crossings of the grid planes, each voxel found at the piece's middle)."""
    a, b = start / resolution, end / resolution
    delta = b - a
    ts, owners = [np.zeros(len(a)), np.ones(len(a))], [np.arange(len(a))] * 2
    for axis in range(3):
        low = np.floor(np.minimum(a[:, axis], b[:, axis])) + 1
        count = np.maximum(np.ceil(np.maximum(a[:, axis], b[:, axis])) - low, 0).astype(np.int64)
        ray = np.repeat(np.arange(len(a)), count)
        plane = np.repeat(low, count) + (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count))
        with np.errstate(divide="ignore", invalid="ignore"):
            ts.append((plane - a[ray, axis]) / delta[ray, axis])
        owners.append(ray)
    t, owner = np.concatenate(ts), np.concatenate(owners)
    order = np.lexsort((t, owner))
    t, owner = t[order], owner[order]
    piece = (owner[1:] == owner[:-1]) & (t[1:] - t[:-1] > 1e-12)
    mid = 0.5 * (t[1:] + t[:-1])[piece]
    ray = owner[:-1][piece]
    return ray, np.floor(a[ray] + mid[:, None] * delta[ray]).astype(np.int64)


def frame_updates(origin: FloatArray, end: FloatArray, hit: NDArray[np.bool_],
                  resolution: float) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """A frame's distinct voxel keys and whether each is a hit (a return lands there; wins
    over the misses of the frame's rays crossing it)."""
    length = np.linalg.norm(end - origin, axis=1) / resolution
    per_ray = np.ceil(length * 1.8 + 3).astype(np.int64)
    misses = []
    lo = 0
    while lo < len(end):
        hi = lo + max(1, int(np.searchsorted(np.cumsum(per_ray[lo:]), CHUNK_CROSSINGS)))
        _, voxel = crossed_voxels(np.broadcast_to(origin, end[lo:hi].shape), end[lo:hi], resolution)
        misses.append(np.unique(voxel_keys(voxel)))
        lo = hi
    hits = np.unique(voxel_keys(np.floor(end[hit] / resolution).astype(np.int64)))
    miss = np.setdiff1d(np.unique(np.concatenate(misses)) if misses else hits[:0], hits, assume_unique=True)
    keys = np.concatenate([hits, miss])
    return keys, np.arange(keys.size) < hits.size


@dataclass
class Updates:
    """Every training frame's voxel updates: ``voxel`` (index into the distinct ``keys``),
    ``hit``; frame ``f`` owns rows ``first[f]:first[f + 1]``."""

    resolution: float
    keys: NDArray[np.int64]
    voxel: NDArray[np.int64]
    hit: NDArray[np.bool_]
    first: NDArray[np.int64]

    @classmethod
    def build(cls, rays: list[tuple[FloatArray, FloatArray, NDArray[np.bool_]]], resolution: float) -> Updates:
        parts = [frame_updates(o, e, h, resolution) for o, e, h in rays]
        keys = np.concatenate([k for k, _ in parts])
        distinct, voxel = np.unique(keys, return_inverse=True)
        first = np.concatenate([[0], np.cumsum([k.size for k, _ in parts])]).astype(np.int64)
        return cls(resolution, distinct, voxel.astype(np.int64), np.concatenate([h for _, h in parts]), first)

    def log_odds(self, frames: NDArray[np.intp], l_occ: float, l_free: float,
                 clamp: tuple[float, float]) -> tuple[FloatArray, NDArray[np.bool_]]:
        """The grid (log-odds per distinct key) after replaying ``frames``, and which keys they saw."""
        grid = np.zeros(self.keys.size)
        seen = np.zeros(self.keys.size, dtype=bool)
        for f in frames:
            rows = slice(self.first[f], self.first[f + 1])
            voxel = self.voxel[rows]
            grid[voxel] = np.clip(grid[voxel] + np.where(self.hit[rows], l_occ, l_free), *clamp)
            seen[voxel] = True
        return grid, seen

    def read(self, grid: FloatArray, seen: NDArray[np.bool_], xyz: FloatArray) -> FloatArray:
        """Occupancy at world points: the logistic of the voxel's log-odds; 0.5 unseen."""
        key = voxel_keys(np.floor(xyz / self.resolution).astype(np.int64))
        at = np.minimum(np.searchsorted(self.keys, key), self.keys.size - 1)
        known = (self.keys[at] == key) & seen[at]
        return np.where(known, 1.0 / (1.0 + np.exp(-grid[at])), 0.5)


# ----------------------------------------------------------------------------- rows
def _scores(p: FloatArray, n_occupied: int, band: NDArray[np.bool_]) -> dict[str, Any]:
    return {"auc_3d": auc(p[:n_occupied], p[n_occupied:]),
            "auc_band": auc(p[:n_occupied][band[:n_occupied]], p[n_occupied:][band[n_occupied:]]),
            "returns_unknown": float(np.mean(p[:n_occupied] == 0.5)),
            "band_returns_unknown": float(np.mean(p[:n_occupied][band[:n_occupied]] == 0.5))}


def grid_rows(train: list[tuple[FloatArray, FloatArray, NDArray[np.bool_]]], inner_test: NDArray[np.bool_],
              inner_points: tuple[FloatArray, int], xyz: FloatArray, n_occupied: int,
              band: NDArray[np.bool_]) -> list[dict[str, Any]]:
    """(c): per resolution, the setting of best inner AUC, rebuilt on every training frame."""
    rows = []
    inner_xyz, inner_n = inner_points
    for resolution in RESOLUTIONS:
        started = time.process_time()
        updates = Updates.build(train, resolution)
        build_s = time.process_time() - started
        inner_frames = np.flatnonzero(~inner_test)
        best = max(SETTINGS, key=lambda s: auc(*np.split(updates.read(*updates.log_odds(inner_frames, *s), inner_xyz),
                                                         [inner_n])))
        inner = auc(*np.split(updates.read(*updates.log_odds(inner_frames, *best), inner_xyz), [inner_n]))
        tuned_s = time.process_time() - started
        started = time.process_time()
        grid, seen = updates.log_odds(np.arange(len(train)), *best)
        cpu = build_s + time.process_time() - started
        p = updates.read(grid, seen, xyz)
        rows.append({"model": f"3D log-odds grid {resolution:g} m", "resolution": resolution,
                     "l_occ": best[0], "l_free": best[1], "clamp": list(best[2]), "inner_auc": inner,
                     "bytes": int(seen.sum()), "cpu_s": cpu, "tuning_cpu_s": tuned_s, **_scores(p, n_occupied, band)})
    return rows


def octomap_rows(train: list[tuple[FloatArray, FloatArray, NDArray[np.bool_]]], max_range: float,
                 xyz: FloatArray, n_occupied: int, band: NDArray[np.bool_], scratch: Path) -> list[dict[str, Any]]:
    """(d): OctoMap with its default sensor model; free-only rays end past the max range, so
    ``insertPointCloud`` cuts them there without a hit."""
    try:
        import pyoctomap
    except ImportError:
        return [{"model": f"OctoMap {r:g} m", "resolution": r, "note": "n/a: pyoctomap is not installed"}
                for r in RESOLUTIONS]
    rows = []
    for resolution in RESOLUTIONS:
        tree = pyoctomap.OcTree(resolution)
        started = time.process_time()
        for origin, end, hit in train:
            beyond = origin + (end - origin) * np.where(hit, 1.0, 1.01)[:, None]
            tree.insertPointCloud(np.ascontiguousarray(beyond), np.ascontiguousarray(origin), max_range=max_range)
        cpu = time.process_time() - started
        path = scratch / f"octomap-{resolution:g}.bt"
        tree.writeBinary(str(path))
        search = tree.search
        p = np.array([0.5 if node is None else node.getOccupancy() for node in map(search, xyz)])
        rows.append({"model": f"OctoMap {resolution:g} m (pyoctomap)", "resolution": resolution,
                     "bytes": path.stat().st_size, "cpu_s": cpu, **_scores(p, n_occupied, band)})
    return rows


def _time_v(stderr: str) -> dict[str, float]:
    wanted = {"User time (seconds)": "user_s", "System time (seconds)": "system_s",
              "Maximum resident set size (kbytes)": "peak_rss_kb"}
    out = {}
    for line in stderr.splitlines():
        name, _, value = line.strip().rpartition(": ")
        if name in wanted:
            out[wanted[name]] = float(value)
    return out


def run_map(source: Path, out: Path, options: list[str]) -> dict[str, Any]:
    """``python -m occtool -q map SOURCE -o OUT ...`` (one thread a library), timed."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    command = [sys.executable, "-m", "occtool", "-q", "map", str(source), "-o", str(out), *options]
    timer = ["/usr/bin/time", "-v"] if Path("/usr/bin/time").is_file() else []
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run(timer + command, env=env, capture_output=True, text=True, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    figures: dict[str, Any] = {"command": " ".join(["python", "-m", "occtool", "-q", "map", source.name, "-o", "DIR",
                                                    *options]),
                               "exit_status": done.returncode, "wall_s": time.perf_counter() - started,
                               "user_s": after.ru_utime - before.ru_utime, "system_s": after.ru_stime - before.ru_stime}
    figures.update(_time_v(done.stderr) if timer else {})
    figures["cpu_s"] = figures["user_s"] + figures["system_s"]
    if done.returncode:
        lines = [line for line in done.stderr.strip().splitlines() if not line.startswith(("\t", "Command "))]
        figures["error"] = lines[-1] if lines else f"exit status {done.returncode}"
    return figures


def write_depth_input(spec: dict[str, Any], train: NDArray[np.bool_], scratch: Path) -> Path:
    """A copy of the depth folder with the training frames only (occtool refuses a linked
    image that resolves outside the folder)."""
    folder: Path = spec["folder"]
    target = scratch / "train"
    target.mkdir()
    for name in ("groundtruth.txt", "camera-intrinsics.txt"):
        shutil.copyfile(folder / name, target / name)
    lines = [line for line in (folder / "depth.txt").read_text(encoding="utf-8").splitlines()
             if line.strip() and not line.lstrip().startswith("#")]
    kept = set(np.asarray(spec["stamps"])[train])
    lines = [line for line in lines if line.split()[0] in kept]
    for line in lines:
        image = target / line.split()[1]
        image.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(folder / line.split()[1], image)
    (target / "depth.txt").write_text("# timestamp filename\n" + "\n".join(lines) + "\n", encoding="utf-8")
    return target / "depth.txt"


def write_lidar_csv(train: list[tuple[FloatArray, FloatArray, NDArray[np.bool_]]], rotations: list[FloatArray],
                    path: Path) -> Path:
    """The training rays as occtool's CSV: sensor-centred points turned by the scan's yaw,
    the pose the scan's position (its world z) and yaw."""
    blocks = []
    for (origin, end, hit), rotation in zip(train, rotations):
        yaw = math.atan2(rotation[1, 0], rotation[0, 0])
        c, s = math.cos(yaw), math.sin(yaw)
        d = end - origin
        local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
        pose = np.tile([origin[0], origin[1], origin[2], yaw], (len(d), 1))
        blocks.append(np.column_stack([local, np.where(hit, 0.9, 0.0), pose]))
    np.savetxt(path, np.concatenate(blocks), fmt="%.6f", delimiter=",",
               header="x,y,z,m,pose_x,pose_y,pose_z,pose_yaw", comments="")
    return path


def read_pgm(path: Path) -> FloatArray:
    """A PGM image (P5, 8 or 16 bits) as grey levels 0-255, row 0 the top."""
    data = path.read_bytes()
    tokens: list[bytes] = []
    at = 0
    while len(tokens) < 4:
        while at < len(data) and data[at:at + 1].isspace():
            at += 1
        if data[at:at + 1] == b"#":
            at = data.find(b"\n", at) + 1 or len(data)
            continue
        begin = at
        while at < len(data) and not data[at:at + 1].isspace():
            at += 1
        if begin == at:
            raise InputError(f"{path}: truncated PGM header")
        tokens.append(data[begin:at])
    if tokens[0] != b"P5":
        raise InputError(f"{path}: not a binary PGM (P5)")
    width, height, maxval = (int(t) for t in tokens[1:])
    dtype = np.dtype(">u2") if maxval > 255 else np.dtype(np.uint8)
    grey = np.frombuffer(data, dtype=dtype, count=width * height, offset=at + 1).astype(np.float64)
    return (grey * (255.0 / maxval)).reshape(height, width)


def read_nav2(yaml_path: Path) -> tuple[FloatArray, float, tuple[float, float, float]]:
    """A trinary map_server map: values (1 occupied, 0 free, 0.5 unknown; row 0 the bottom),
    resolution and origin."""
    fields = {}
    for line in yaml_path.read_text(encoding="utf-8").splitlines():
        key, _, value = line.split("#", 1)[0].partition(":")
        if value:
            fields[key.strip()] = value.strip().strip("'\"")
    p = (255.0 - read_pgm(yaml_path.parent / fields["image"])) / 255.0
    if int(fields.get("negate", "0")):
        p = 1.0 - p
    cells = np.where(p > float(fields["occupied_thresh"]), 1.0, np.where(p < float(fields["free_thresh"]), 0.0, 0.5))
    ox, oy, yaw = (float(v) for v in fields["origin"].strip("[]").split(","))
    return np.ascontiguousarray(cells[::-1]), float(fields["resolution"]), (ox, oy, yaw)


def nav2_lookup(nav2: tuple[FloatArray, float, tuple[float, float, float]], xy: FloatArray) -> FloatArray:
    """The map's value at world ``(K, 2)`` points; 0.5 off the map."""
    value, resolution, (ox, oy, yaw) = nav2
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = xy[:, 0] - ox, xy[:, 1] - oy
    i = np.floor((c * dx + s * dy) / resolution).astype(np.int64)
    j = np.floor((-s * dx + c * dy) / resolution).astype(np.int64)
    inside = (i >= 0) & (i < value.shape[1]) & (j >= 0) & (j < value.shape[0])
    out = np.full(xy.shape[0], 0.5)
    out[inside] = value[j[inside], i[inside]]
    return out


def occmap_header(path: Path) -> dict[str, Any]:
    """The JSON header of an ``.occmap`` file (8 bytes of magic, a little-endian uint32
    length, the header), read here rather than through occtool."""
    data = path.read_bytes()
    (length,) = np.frombuffer(data[8:12], dtype="<u4")
    header = json.loads(data[12:12 + int(length)].decode("utf-8"))
    return header if isinstance(header, dict) else {}


def map_frame(header: dict[str, Any], xyz: FloatArray) -> FloatArray:
    """World points moved into a 3D map's own frame by the 3x4 ``to_map`` its header stores
    (where occtool levelled the world), for the Nav2 map drawn in that frame."""
    if header.get("to_map") is None:
        return xyz
    m = np.asarray(header["to_map"], dtype=np.float64).reshape(3, 4)
    return xyz @ m[:, :3].T + m[:, 3]


def occtool_rows(out: Path, command: dict[str, Any], xyz: FloatArray, xyz_floor: FloatArray, n_occupied: int,
                 band: NDArray[np.bool_]) -> list[dict[str, Any]]:
    """(a) and (b): ``world.occmap`` and the Nav2 map of ``occtool map``'s run. A 3D map
    (version 5 or 6) is queried at the world x, y, z; a 2D one at x, y and the height above the
    floor (its datum)."""
    names = ("occtool world.occmap (load_map().predict)", "occtool Nav2 map (map.yaml + PGM, trinary)")
    if command["exit_status"]:
        return [{"model": name, "note": f"n/a: occtool map failed: {command.get('error')}"} for name in names]
    rows: list[dict[str, Any]] = []
    path = out / "world.occmap"
    try:
        load_map = importlib.import_module("occtool.fuse").load_map
        started = time.process_time()
        header = occmap_header(path)
        three_d = header.get("version") in (5, 6)
        p = np.asarray(load_map(path).predict(xyz if three_d else xyz_floor), dtype=np.float64)
        rows.append({"model": names[0], "bytes": path.stat().st_size, "cpu_s": command["cpu_s"],
                     "query_cpu_s": time.process_time() - started, "version": header.get("version"),
                     "resolution": header.get("resolution"), **_scores(p, n_occupied, band)})
    except Exception as exc:  # occtool's reader: any failure is reported, not raised
        rows.append({"model": names[0], "note": f"n/a: {type(exc).__name__}: {exc}"})
    if (out / "map.yaml").is_file():
        at = map_frame(occmap_header(path), xyz) if path.is_file() else xyz
        v = nav2_lookup(read_nav2(out / "map.yaml"), at[:, :2])
        image = out / [line.split(":", 1)[1].strip() for line in (out / "map.yaml").read_text().splitlines()
                       if line.startswith("image:")][0]
        rows.append({"model": names[1], "bytes": image.stat().st_size, "cpu_s": command["cpu_s"],
                     **_scores(v, n_occupied, band)})
    else:
        rows.append({"model": names[1], "note": "n/a: occtool map wrote no map.yaml"})
    return rows


# ----------------------------------------------------------------------------- one sequence
def _kept_rays(frames: list[Frame], index: NDArray[np.intp], keep: int, rng: np.random.Generator,
               spec: dict[str, Any]) -> list[tuple[FloatArray, FloatArray, NDArray[np.bool_]]]:
    out = []
    for i in index:
        end, hit = cut_rays(frames[i], keep, rng, spec["min_range"], spec["max_range"])
        out.append((frames[i].origin, end, hit))
    return out


def _points(rays: list[tuple[FloatArray, FloatArray, NDArray[np.bool_]]]) -> tuple[FloatArray, int]:
    parts = [ray_points(o, e, h) for o, e, h in rays]
    occupied = np.concatenate([a for a, _ in parts])
    return np.concatenate([occupied, *[b for _, b in parts]]), len(occupied)


def score_sequence(name: str, seed: int = 0, data_dir: str | os.PathLike[str] = DATA_DIR,
                   keep: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """Every row for one sequence (module docstring)."""
    if name not in SEQUENCES:
        raise InputError(f"unknown sequence {name!r}: one of {', '.join(SEQUENCES)}")
    started_all = time.process_time()
    frames, spec = load_sequence(name, Path(data_dir))
    n = len(frames)
    test = held_out(n, spec["block"], seed)
    rng = np.random.default_rng(seed)
    train_index, test_index = np.flatnonzero(~test), np.flatnonzero(test)
    train = _kept_rays(frames, train_index, spec["train_rays"], rng, spec)
    xyz, n_occupied = _points(_kept_rays(frames, test_index, spec["test_rays"], rng, spec))
    inner_test = held_out(len(train), spec["block"], seed + 1000)
    inner = _points([(o, e, h) for (o, e, h), t in zip(train, inner_test) if t])
    positions = np.array([frames[i].origin for i in train_index])
    if spec["kind"] == "depth":
        sensor_height = float(spec["camera_height"])
        floor = np.full(len(xyz), float(np.median(positions[:, 2])) - sensor_height)
        floor_note = f"flat, {sensor_height:g} m (the stated camera height) below the training cameras' median z"
    else:
        sensor_height = lidar_sensor_height(frames, ~test)
        floor = floor_under(xyz, positions, sensor_height)
        floor_note = ("the nearest training position's z less the sensor height, estimated from the lowest dense "
                      "layer of training returns under each training position")
    body = round(max(sensor_height, 0.3), 2)
    height = xyz[:, 2] - floor
    band = (height >= CLEARANCE) & (height <= body)
    xyz_floor = np.column_stack([xyz[:, :2], height])
    scratch = Path(tempfile.mkdtemp(prefix="heldout3d-", dir=keep))
    try:
        options = ["--sensor-height", f"{sensor_height:.2f}", "--body-height", f"{body:.2f}"]
        if spec["kind"] == "depth":
            source = write_depth_input(spec, ~test, scratch)
            options += ["--depth-features", str(spec["train_rays"]), "--no-return-range", f"{spec['max_range']:g}"]
        else:
            poses = read_kitti_poses(spec["folder"] / "optimized_poses.txt")
            source = write_lidar_csv(train, [poses[i][:3, :3] for i in train_index], scratch / "train.csv")
        command = run_map(source, scratch / "map", options)
        rows = occtool_rows(scratch / "map", command, xyz, xyz_floor, n_occupied, band)
        rows += grid_rows(train, inner_test, inner, xyz, n_occupied, band)
        rows += octomap_rows(train, spec["max_range"], xyz, n_occupied, band, scratch)
    finally:
        if keep is None:
            shutil.rmtree(scratch, ignore_errors=True)
    return {"sequence": name, "seed": seed, "frames": n, "held_out_frames": int(test.sum()), "block": spec["block"],
            "train_rays_per_frame": spec["train_rays"], "test_rays_per_frame": spec["test_rays"],
            "max_range": spec["max_range"], "floor": floor_note, "sensor_height": sensor_height,
            "body_height": body, "occupied_points": n_occupied, "free_points": len(xyz) - n_occupied,
            "band_points": int(band.sum()), "map_command": command, "rows": rows,
            "total_cpu_s": time.process_time() - started_all + command["cpu_s"],
            "kept": str(scratch) if keep is not None else None}


def _f(value: Any, fmt: str) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, fmt)


def markdown(result: dict[str, Any]) -> str:
    """A table of one sequence's rows."""
    command = result["map_command"]
    lines = [f"**{result['sequence']}**, seed {result['seed']}: {result['held_out_frames']} of {result['frames']} "
             f"frames held out in blocks of {result['block']}; {result['train_rays_per_frame']:,} rays kept a training "
             f"frame, {result['test_rays_per_frame']:,} a held-out one (max range {result['max_range']:g} m); "
             f"{result['occupied_points']:,} returns, {result['free_points']:,} free points, {result['band_points']:,} "
             f"in the body band (floor: {result['floor']}; sensor "
             f"{result['sensor_height']:.2f} m, body {result['body_height']:.2f} m). `{command['command']}`: "
             + (f"{command['cpu_s']:.1f} s CPU." if not command["exit_status"] else f"failed ({command.get('error')})."),
             "", "| model | AUC 3D | AUC band | returns on unknown (3D / band) | bytes | CPU s | notes |",
             "|---|---|---|---|---|---|---|"]
    for row in result["rows"]:
        if "auc_3d" not in row:
            lines.append(f"| {row['model']} | - | - | - | - | - | {row.get('note', '')} |")
            continue
        note = row.get("note", "")
        if "l_occ" in row:
            note = (f"l_occ {row['l_occ']:g}, l_free {row['l_free']:g}, clamp [{row['clamp'][0]:g}, "
                    f"{row['clamp'][1]:g}], inner AUC {_f(row['inner_auc'], '.3f')}; bytes: a byte a known voxel")
        elif row["model"].startswith("OctoMap"):
            note = "default sensor model; bytes: its .bt file"
        elif "world.occmap" in row["model"] and row.get("version") in (5, 6):
            note = (f"3D (version {row['version']}, {row['resolution']:g} m cells, chosen by occtool); queried at world x, y, z; "
                    "CPU: the whole `occtool map`")
        elif "world.occmap" in row["model"]:
            note = "queried at height above the floor; 0.5 outside its 2D band; CPU: the whole `occtool map`"
        else:
            note = "looked up at x, y of every point; bytes: the PGM"
        lines.append(f"| {row['model']} | {_f(row['auc_3d'], '.3f')} | {_f(row['auc_band'], '.3f')} | "
                     f"{row['returns_unknown']:.1%} / {row['band_returns_unknown']:.1%} | "
                     f"{row['bytes'] / 1e3:,.1f} KB | {_f(row.get('cpu_s'), '.1f')} | {note} |")
    return "\n".join(lines) + "\n"


def heldout3d_section(data_dir: str | os.PathLike[str] = DATA_DIR, sequences: tuple[str, ...] = tuple(SEQUENCES),
                      seed: int = 0) -> dict[str, Any]:
    """Score every sequence found; ``{"markdown": text, "sequences": [...], "notes": [...]}``."""
    results, notes = [], []
    for name in sequences:
        started = time.perf_counter()
        try:
            result = score_sequence(name, seed, data_dir)
        except (InputError, OSError) as exc:
            notes.append(f"{name}: skipped ({exc})")
            continue
        result["total_s"] = time.perf_counter() - started
        results.append(result)
        print(f"[bench] held-out 3D score {name}: {result['total_s']:.0f} s", flush=True)
    text = ["## Held out in 3D, scored independently (bench/heldout3d.py)", "",
            "Scored by code that shares nothing with occtool's model, fusion, grids or scoring; occtool runs as the "
            "real command on the training frames. Protocol: bench/heldout3d.py's docstring.", ""]
    text += [markdown(result) for result in results]
    text += [f"- {note}" for note in notes]
    return {"markdown": "\n".join(text) + "\n", "sequences": results, "notes": notes}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--sequence", required=True, choices=[*SEQUENCES, "all"], help="The sequence to score.")
    parser.add_argument("--seed", type=int, default=0, help="Seed of the held-out blocks and ray draws.")
    parser.add_argument("--data-dir", default=str(DATA_DIR), help="Folder holding the lidar sequences.")
    parser.add_argument("--json", help="Write the figures here as JSON.")
    parser.add_argument("--keep", help="Keep the training input and occtool's output in a folder made under this one.")
    args = parser.parse_args(argv)
    names = list(SEQUENCES) if args.sequence == "all" else [args.sequence]
    results = []
    try:
        for name in names:
            results.append(score_sequence(name, args.seed, args.data_dir, keep=args.keep))
            print(markdown(results[-1]), flush=True)
    except (InputError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        Path(args.json).write_text(json.dumps(results if len(results) > 1 else results[0], indent=1) + "\n",
                                   encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
