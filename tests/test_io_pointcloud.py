"""Point-cloud files: plain x y z (OctoMap), PCD (ascii, binary) and PLY."""

from __future__ import annotations

import bz2

import numpy as np
import pytest

from occtool.errors import InputError
from occtool.features import Pose
from occtool.io import detect_format, read_log


def test_plain_xyz_scan(fixtures_dir, tmp_path):
    path = fixtures_dir / "logs" / "tiny.xyz"
    assert detect_format(path) == "xyz"
    features = read_log(path).single().features
    np.testing.assert_array_equal(features.points, [[1, 0, 0], [0, 2, -0.5], [-1.5, 0, 0.25]])
    np.testing.assert_array_equal(features.evidence, 0.9)
    packed = tmp_path / "scan.dat.bz2"
    packed.write_bytes(bz2.compress(path.read_bytes()))
    np.testing.assert_array_equal(read_log(packed, evidence=0.5).single().features.evidence, 0.5)


def test_octomap_node_lines_are_positions_with_poses(fixtures_dir):
    log = read_log(fixtures_dir / "logs" / "nodes.dat")
    assert [p.pose for p in log.positions] == [Pose(0, 0, 0, 0), Pose(5, 0, 0, np.pi / 2)]
    np.testing.assert_array_equal(log.positions[0].features.points, [[1, 0, 0], [0, 1, 0]])
    np.testing.assert_array_equal(log.positions[1].features.points, [[2, 0, 0]])


def test_bad_xyz_line_is_named(tmp_path):
    path = tmp_path / "bad.xyz"
    path.write_text("1 2 3\n4 five 6\n7 8 9\n")
    with pytest.raises(InputError, match="bad.xyz, line 2"):
        read_log(path)
    log = read_log(path, skip_invalid=True)
    assert len(log.single().features) == 2


def test_ascii_pcd_with_evidence_drops_no_return_points(fixtures_dir):
    log = read_log(fixtures_dir / "logs" / "tiny_ascii.pcd")
    features = log.single().features
    np.testing.assert_array_equal(features.points, [[1, 0, 0], [0, 2, -1]])
    np.testing.assert_array_equal(features.evidence, [0.5, 0.25])
    assert any("NaN" in n for n in log.notes) and any("origin" in n for n in log.notes)


def binary_pcd(points: np.ndarray, viewpoint: str = "0 0 0 1 0 0 0", extra: bytes = b"") -> bytes:
    header = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
        f"WIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT {viewpoint}\nPOINTS {len(points)}\nDATA binary\n"
    )
    body = np.column_stack([points, np.arange(len(points))]).astype("<f4").tobytes()
    return header.encode() + body + extra


def test_binary_pcd_and_viewpoint(tmp_path):
    points = np.array([[1.0, 0.0, 0.0], [2.0, 3.0, -1.0]])
    path = tmp_path / "cloud.pcd"
    path.write_bytes(binary_pcd(points))
    assert detect_format(path) == "pcd"
    np.testing.assert_array_equal(read_log(path).single().features.points, points)
    # A viewpoint at (1, 0, 0) facing +y: points re-centred there and turned into its heading.
    c = np.cos(np.pi / 4)
    path.write_bytes(binary_pcd(points, f"1 0 0 {c} 0 0 {c}"))
    position = read_log(path).single()
    assert (position.pose.x, position.pose.yaw) == pytest.approx((1.0, np.pi / 2))
    # (1,0,0) is the origin: dropped
    np.testing.assert_allclose(position.features.points, [[3.0, -1.0, -1.0]], atol=1e-6)
    truncated = tmp_path / "short.pcd"
    truncated.write_bytes(binary_pcd(points)[:-5])
    with pytest.raises(InputError, match="truncated"):
        read_log(truncated)


def test_ply_ascii_and_binary(fixtures_dir, tmp_path):
    features = read_log(fixtures_dir / "logs" / "tiny_ascii.ply").single().features
    np.testing.assert_array_equal(features.points, np.eye(3))
    np.testing.assert_allclose(features.evidence, [0.5, 0.6, 0.7], rtol=1e-6)
    points = np.array([[1.5, -2.0, 0.25], [0.0, 0.0, 4.0]])
    header = (b"ply\nformat binary_big_endian 1.0\nelement vertex 2\n"
              b"property double x\nproperty double y\nproperty double z\nend_header\n")
    path = tmp_path / "cloud.ply"
    path.write_bytes(header + points.astype(">f8").tobytes())
    assert detect_format(path) == "ply"
    np.testing.assert_array_equal(read_log(path).single().features.points, points)


def test_real_octomap_scan_and_velodyne_pcd(shared_data):
    scan = read_log(shared_data / "octomap_scan" / "scan.dat.bz2").single().features
    assert len(scan) == 88206
    assert 0.46 < scan.range.min() and scan.range.max() < 29.1
    cloud_log = read_log(shared_data / "fast_gicp_velodyne_pair" / "251370668.pcd")
    cloud = cloud_log.single().features
    # 69,088 points, less those at (0, 0, 0) that mean no return.
    dropped = int(next(n for n in cloud_log.notes if "origin" in n).split()[1])
    assert len(cloud) + dropped == 69088
    assert cloud.range.max() < 77.7
