"""The pieces of bench/heldout3d.py, the independent 3D held-out scorer, on known answers."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def h3():
    spec = importlib.util.spec_from_file_location("heldout3d", ROOT / "bench" / "heldout3d.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["heldout3d"] = module
    spec.loader.exec_module(module)
    return module


def test_auc_on_known_ranks(h3):
    assert h3.auc(np.array([3.0, 4.0]), np.array([1.0, 2.0])) == 1.0
    assert h3.auc(np.array([1.0]), np.array([2.0])) == 0.0
    # One tie of four pairs counts half: (1 + 1 + 0.5 + 1) / 4.
    assert h3.auc(np.array([2.0, 3.0]), np.array([1.0, 2.0])) == pytest.approx(0.875)
    # A method that knows nothing (0.5 everywhere) scores 0.5.
    assert h3.auc(np.full(5, 0.5), np.full(7, 0.5)) == 0.5


def test_ray_points_every_step_to_the_margin(h3):
    origin = np.zeros(3)
    end = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.15], [0.0, 2.0, 0.0]])
    hit = np.array([True, True, False])
    occupied, free = h3.ray_points(origin, end, hit)
    np.testing.assert_allclose(occupied, end[:2])
    # 1 m ray: 0.1 ... 0.9; 0.15 m ray: none; a 2 m free-only ray: 0.1 ... 1.9, no return.
    assert len(free) == 9 + 0 + 19
    np.testing.assert_allclose(free[:9, 0], np.arange(1, 10) * 0.1)
    np.testing.assert_allclose(free[9:, 1], np.arange(1, 20) * 0.1)


def test_cut_rays_at_max_range_and_budget(h3):
    frame = h3.Frame(np.array([1.0, 1.0, 1.0]), np.array([[2.0, 1.0, 1.0], [1.0, 41.0, 1.0], [1.05, 1.0, 1.0]]))
    end, hit = h3.cut_rays(frame, 10, np.random.default_rng(0), 0.1, 30.0)
    np.testing.assert_allclose(end, [[2.0, 1.0, 1.0], [1.0, 31.0, 1.0]])  # the 5 cm ray dropped
    assert hit.tolist() == [True, False]
    many = h3.Frame(np.zeros(3), np.random.default_rng(1).normal(size=(100, 3)) + 5.0)
    assert h3.cut_rays(many, 7, np.random.default_rng(0), 0.1, 30.0)[0].shape == (7, 3)


def test_held_out_blocks(h3):
    out = h3.held_out(58, 5, 0)
    assert out.sum() == 10  # round(0.15 * 58 / 5) = 2 blocks of 5
    starts = np.flatnonzero(np.diff(np.concatenate([[0], out.astype(int)])) == 1)
    assert all(s % 5 == 0 for s in starts)
    assert not np.array_equal(out, h3.held_out(58, 5, 1))
    with pytest.raises(h3.InputError):
        h3.held_out(3, 5, 0)


def test_voxel_traversal_hand_made(h3):
    # From the middle of voxel (0, 0, 0) to the middle of (2, 1, 0) at 1 m: x crosses at 1
    # and 2, y at 1 (t = 0.5 of the way, between the x crossings at t 0.25 and 0.75).
    ray, voxel = h3.crossed_voxels(np.array([[0.5, 0.5, 0.5]]), np.array([[2.5, 1.5, 0.5]]), 1.0)
    assert ray.tolist() == [0, 0, 0, 0]
    assert voxel.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [2, 1, 0]]
    # A diagonal ray in negative directions at 0.5 m.
    _, voxel = h3.crossed_voxels(np.array([[0.1, 0.1, 0.1]]), np.array([[-0.9, 0.1, -0.4]]), 0.5)
    assert voxel[0].tolist() == [0, 0, 0] and voxel[-1].tolist() == [-2, 0, -1]
    steps = np.abs(np.diff(voxel, axis=0)).sum(axis=1)
    assert (steps == 1).all()  # face neighbours, one plane at a time


def test_frame_updates_hit_wins_once_a_frame(h3):
    origin = np.array([0.05, 0.05, 0.05])
    end = np.array([[0.55, 0.05, 0.05], [0.25, 0.05, 0.05]])  # the second ray crosses the first's...
    keys, hit = h3.frame_updates(origin, end, np.array([True, True]), 0.1)
    assert keys.size == np.unique(keys).size == 6  # voxels 0..5 along x, once each
    by_x = {int((k >> (2 * h3._BITS)) - h3._OFFSET): bool(v) for k, v in zip(keys, hit)}
    assert by_x == {0: False, 1: False, 2: True, 3: False, 4: False, 5: True}


def test_log_odds_grid_replay_and_read(h3):
    origin = np.array([0.05, 0.05, 0.05])
    rays = [(origin, np.array([[0.35, 0.05, 0.05]]), np.array([True]))] * 2
    updates = h3.Updates.build(rays, 0.1)
    grid, seen = updates.log_odds(np.arange(2), 1.0, -0.5, (-0.8, 1.5))
    p = updates.read(grid, seen, np.array([[0.35, 0.05, 0.05], [0.15, 0.05, 0.05], [5.0, 5.0, 5.0]]))
    np.testing.assert_allclose(p, [1 / (1 + np.exp(-1.5)), 1 / (1 + np.exp(0.8)), 0.5])  # clamped; unseen 0.5
    grid, seen = updates.log_odds(np.arange(0), 1.0, -0.5, (-0.8, 1.5))
    assert (updates.read(grid, seen, np.zeros((1, 3))) == 0.5).all()


def test_read_pcd_binary_with_padding_and_ascii(h3, tmp_path):
    points = np.array([[1.0, 2.0, 3.0, 7.0], [4.0, 5.0, 6.0, 8.0]], dtype=np.float32)
    header = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
              "WIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\n")
    (tmp_path / "b.pcd").write_bytes((header + "DATA binary\n").encode() + points.tobytes() + bytes(100))
    np.testing.assert_allclose(h3.read_pcd(tmp_path / "b.pcd"), points[:, :3])
    (tmp_path / "a.pcd").write_text(header + "DATA ascii\n1 2 3 7\n4 5 6 8\n")
    np.testing.assert_allclose(h3.read_pcd(tmp_path / "a.pcd"), points[:, :3])
    (tmp_path / "c.pcd").write_bytes((header + "DATA binary_compressed\n").encode() + bytes(40))
    with pytest.raises(h3.InputError):
        h3.read_pcd(tmp_path / "c.pcd")


def test_read_kitti_poses(h3, tmp_path):
    (tmp_path / "poses.txt").write_text("1 0 0 1 0 1 0 2 0 0 1 3\n0 -1 0 0 1 0 0 0 0 0 1 0\n")
    poses = h3.read_kitti_poses(tmp_path / "poses.txt")
    assert poses.shape == (2, 4, 4)
    np.testing.assert_allclose(poses[0][:3, 3], [1, 2, 3])
    np.testing.assert_allclose(poses[1][:3, :3] @ [1, 0, 0], [0, 1, 0])
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    with pytest.raises(h3.InputError):
        h3.read_kitti_poses(tmp_path / "bad.txt")


def test_read_tum_and_depth_rays(h3, tmp_path):
    Image = pytest.importorskip("PIL.Image")
    (tmp_path / "depth").mkdir()
    z = np.zeros((3, 4), dtype=np.uint16)
    z[1, 2] = 10000  # 2 m at pixel (u 2, v 1)
    Image.fromarray(z).save(tmp_path / "depth" / "1.0.png")
    (tmp_path / "depth.txt").write_text("# timestamp filename\n1.0 depth/1.0.png\n5.0 depth/5.0.png\n")
    # Identity orientation (optical z forward = world z), camera at (1, 2, 3).
    (tmp_path / "groundtruth.txt").write_text("# t tx ty tz qx qy qz qw\n1.01 1 2 3 0 0 0 1\n")
    (tmp_path / "camera-intrinsics.txt").write_text("2 0 2\n0 2 1\n0 0 1\n")
    frames, K = h3.read_tum(tmp_path)
    assert len(frames) == 1 and frames[0][0] == "1.0"  # 5.0 has no pose within 0.02 s
    origin, end = h3.depth_rays(frames[0][1], K, frames[0][2])
    np.testing.assert_allclose(origin, [1, 2, 3])
    np.testing.assert_allclose(end, [[1.0, 2.0, 5.0]])


def test_nav2_lookup_and_pgm(h3, tmp_path):
    pixels = np.array([[0, 254], [205, 254]], dtype=np.uint8)  # top row first: occupied, free / unknown, free
    (tmp_path / "map.pgm").write_bytes(b"P5\n# c\n2 2\n255\n" + pixels.tobytes())
    (tmp_path / "map.yaml").write_text("image: map.pgm\nmode: trinary\nresolution: 1.0\norigin: [0.0, 0.0, 0.0]\n"
                                       "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    nav2 = h3.read_nav2(tmp_path / "map.yaml")
    v = h3.nav2_lookup(nav2, np.array([[0.5, 1.5], [1.5, 1.5], [0.5, 0.5], [9.0, 9.0]]))
    assert v.tolist() == [1.0, 0.0, 0.5, 0.5]
