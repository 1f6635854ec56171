"""The ``scans`` format: folders of PCD / PLY / KITTI .bin scans with a KITTI-style poses file,
and several point-cloud files mapped in one call (occtool.io.scans)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.io import detect_format, iter_positions, read_log
from occtool.io.scans import read_poses
from occtool.limits import MAX_WORLD_COORDINATE


def rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw),
                              math.sin(yaw))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def transform(roll: float, pitch: float, yaw: float, t: tuple[float, float, float]) -> np.ndarray:
    return np.column_stack([rotation(roll, pitch, yaw), np.asarray(t, dtype=float)])


def pose_line(matrix: np.ndarray) -> str:
    return " ".join(f"{v:.9g}" for v in matrix.reshape(-1))


def write_pcd(path: Path, points: np.ndarray, padding: int = 0) -> Path:
    n = len(points)
    header = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\n"
              f"TYPE F F F F\nCOUNT 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
              "DATA binary\n")
    records = np.column_stack([points, np.full(n, 7.0)]).astype("<f4")
    path.write_bytes(header.encode() + records.tobytes() + b"\0" * padding)
    return path


def write_ply(path: Path, points: np.ndarray) -> Path:
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(points)}\nproperty float x\n"
              "property float y\nproperty float z\nend_header\n")
    path.write_bytes(header.encode() + points.astype("<f4").tobytes())
    return path


def write_bin(path: Path, points: np.ndarray) -> Path:
    path.write_bytes(np.column_stack([points, np.zeros(len(points))]).astype("<f4").tobytes())
    return path


def wall(n: int = 400, seed: int = 0) -> np.ndarray:
    """World points of a wall: the plane x = 6, y in [-3, 3], z in [0, 2.5]."""
    rng = np.random.default_rng(seed)
    return np.column_stack([np.full(n, 6.0), rng.uniform(-3, 3, n), rng.uniform(0, 2.5, n)])


#: Three sensor poses (scan to world) with roll, pitch and yaw, and the writer of each scan.
POSES = [transform(0.05, -0.1, 0.3, (0.0, 0.0, 1.2)), transform(-0.08, 0.12, -0.4, (1.5, 0.7, 1.0)),
         transform(0.0, 0.2, 0.1, (3.0, -0.5, 1.5))]
WRITERS = [(write_pcd, "000000.pcd"), (write_ply, "000001.ply"), (write_bin, "000002.bin")]


def scan_folder(tmp_path: Path, extra_lines: int = 2) -> tuple[Path, Path, np.ndarray]:
    """A folder of three scans of one wall (PCD, PLY, .bin), each in its sensor's frame, and the poses."""
    folder = tmp_path / "Scans"
    folder.mkdir()
    world = wall()
    for matrix, (writer, name) in zip(POSES, WRITERS):
        local = (world - matrix[:, 3]) @ matrix[:, :3]  # R^T (p - t)
        writer(folder / name, local)
    lines = [pose_line(m) for m in POSES] + [pose_line(POSES[0])] * extra_lines  # lines beyond the scans
    poses = tmp_path / "poses.txt"
    poses.write_text("\n".join(lines) + "\n")
    return folder, poses, world


def in_world(position) -> np.ndarray:
    pose = position.pose
    return position.features.points @ pose.rotation.T + pose.translation


def test_a_wall_seen_from_three_poses_lands_where_the_poses_say(tmp_path):
    folder, poses, world = scan_folder(tmp_path)
    assert detect_format(folder) == "scans"
    log = read_log(folder, poses=poses, group_by="message")
    assert len(log.positions) == 3
    for position, matrix in zip(log.positions, POSES):
        assert np.allclose(in_world(position), world, atol=1e-4)  # float32 files
        assert np.allclose(position.pose.translation, matrix[:, 3])
        forward = matrix[:, 0]
        assert math.isclose(position.pose.yaw, math.atan2(forward[1], forward[0]), abs_tol=1e-9)
        # The sensor-centred robot frame: the sensor at the origin, z up (the wall stands upright).
        heights = position.features.points[:, 2] + position.pose.z
        assert np.allclose(np.sort(heights), np.sort(world[:, 2]), atol=1e-4)
    assert any("lines beyond the 3 scans unused" in note for note in log.notes)


def test_streamed_positions_are_the_read_ones(tmp_path):
    folder, poses, _ = scan_folder(tmp_path)
    whole = read_log(folder, poses=poses)
    stream = iter_positions(folder, poses=poses)
    streamed = list(stream)
    assert len(streamed) == len(whole.positions)
    for a, b in zip(streamed, whole.positions):
        assert a.pose == b.pose and np.array_equal(a.features.points, b.features.points)
    assert stream.notes == whole.notes


def test_a_point_cloud_file_keeps_its_own_viewpoint_under_the_poses_file(tmp_path):
    # A file's VIEWPOINT (its own pose) is composed with the poses file's.
    world = wall()
    scan_to_world = POSES[1]
    file_points = world @ scan_to_world[:, :3] - scan_to_world[:, 3] @ scan_to_world[:, :3]
    path = write_pcd(tmp_path / "v.pcd", file_points)
    half = math.sin(0.25), math.cos(0.25)  # the sensor in the file's frame: (0.2, -0.1, 0), yaw 0.5
    path.write_bytes(path.read_bytes().replace(b"VIEWPOINT 0 0 0 1 0 0 0",
                                               f"VIEWPOINT 0.2 -0.1 0 {half[1]!r} 0 0 {half[0]!r}".encode()))
    poses = tmp_path / "p.txt"
    poses.write_text(pose_line(scan_to_world) + "\n")
    log = read_log(path, poses=poses)
    assert np.allclose(in_world(log.single()), world, atol=1e-4)


def test_zero_padded_binary_pcd_reads_and_other_trailing_bytes_do_not(tmp_path):
    points = wall(50)
    padded = write_pcd(tmp_path / "padded.pcd", points, padding=3908)
    assert np.allclose(read_log(padded).single().features.points, points.astype("<f4"), atol=0)
    junk = tmp_path / "junk.pcd"
    junk.write_bytes(padded.read_bytes()[:-3908] + b"\1" * 64)
    with pytest.raises(InputError, match="holds 54 points, the header says POINTS 50"):
        read_log(junk)


@pytest.mark.parametrize(("line", "message"), [
    ("1 0 0 0 0 1 0 0 0 0 1 nan", "NaN or infinity"),
    ("1 0 0 0 0 1 0 0 0 0 1", "expected 12 numbers"),
    ("1 0 0 0 0 1 0 0 0 0 1 0 5", "expected 12 numbers"),
    ("2 0 0 0 0 1 0 0 0 0 1 0", "not a rotation"),
    ("1 0 0 0 0 1 0 0 0 0 -1 0", "not a rotation"),  # a reflection
    ("1 0 0 0 0 1 0 0 0 0 1 x1", "'x1' is not a number"),
    (f"1 0 0 {2 * MAX_WORLD_COORDINATE} 0 1 0 0 0 0 1 0", "reaches past"),
    ("# a comment", "a comment among the poses"),
])
def test_a_bad_poses_line_is_a_one_line_error_naming_the_file_and_line(tmp_path, line, message):
    folder, _, _ = scan_folder(tmp_path)
    poses = tmp_path / "bad.txt"
    poses.write_text("\n".join([pose_line(POSES[0]), line, pose_line(POSES[2])]) + "\n")
    with pytest.raises(InputError, match=message) as caught:
        read_log(folder, poses=poses)
    text = str(caught.value)
    assert "\n" not in text and text.startswith(f"{poses}, line 2:")


def test_fewer_poses_than_scans_is_an_error_naming_both_counts(tmp_path):
    folder, _, _ = scan_folder(tmp_path)
    poses = tmp_path / "two.txt"
    poses.write_text("\n".join(pose_line(m) for m in POSES[:2]) + "\n")
    with pytest.raises(InputError, match="holds 2 poses for 3 scans"):
        read_log(folder, poses=poses)


def test_the_poses_option_is_checked(tmp_path):
    folder, _, _ = scan_folder(tmp_path)
    with pytest.raises(InputError, match="does not exist"):
        read_log(folder, poses=tmp_path / "missing.txt")
    csv = tmp_path / "f.csv"
    csv.write_text("x,y,z,m\n1,2,3,0.9\n")
    with pytest.raises(InputError, match="poses= applies to scans"):
        read_log(csv, poses=tmp_path / "Scans" / "000000.pcd")


def test_several_files_are_one_sequence_each_file_a_scan(tmp_path):
    folder, poses, world = scan_folder(tmp_path)
    files = sorted(folder.iterdir())
    log = read_log(files, poses=poses, group_by="message")
    assert len(log.positions) == 3
    assert np.allclose(in_world(log.positions[2]), world, atol=1e-4)
    unposed = read_log(files, group_by="message")  # no poses: each file a position without a pose
    assert len(unposed.positions) == 3 and not unposed.has_poses
    single = read_log([files[0]])  # a list of one file is that file
    assert single.source == str(files[0])


def test_a_folder_without_scans_is_not_a_log(tmp_path):
    (tmp_path / "notes.txt").write_text("nothing\n")
    with pytest.raises(InputError, match="is a folder, not a range log"):
        read_log(tmp_path)


def test_a_kitti_bin_of_a_partial_record_is_an_error(tmp_path):
    path = tmp_path / "000000.bin"
    path.write_bytes(b"\0" * 20)
    with pytest.raises(InputError, match="not a whole number of them"):
        read_log(path)


# --- the poses parser, fuzzed ----------------------------------------------------------------

angles = st.floats(-math.pi, math.pi, allow_nan=False)
offsets = st.floats(-1e3, 1e3, allow_nan=False)
MUTATIONS = ("none", "nan", "inf", "drop", "extra", "word", "scale", "reflect", "far", "blank")


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(roll=angles, pitch=angles, yaw=angles, x=offsets, y=offsets, z=offsets,
       mutation=st.sampled_from(MUTATIONS), position=st.integers(0, 11), lines=st.integers(1, 4))
def test_the_poses_parser_reads_rotations_and_refuses_everything_else_in_one_line(
        tmp_path, roll, pitch, yaw, x, y, z, mutation, position, lines):
    good = transform(roll, pitch, yaw, (x, y, z))
    tokens = [f"{v:.17g}" for v in good.reshape(-1)]
    if mutation == "nan":
        tokens[position] = "nan"
    elif mutation == "inf":
        tokens[position] = "-inf"
    elif mutation == "drop":
        del tokens[position]
    elif mutation == "extra":
        tokens.insert(position, "0")
    elif mutation == "word":
        tokens[position] = "pose"
    elif mutation == "scale":  # the rotation's first column stretched by 1 %
        for k in (0, 4, 8):
            tokens[k] = f"{float(tokens[k]) * 1.01:.17g}"
    elif mutation == "reflect":
        tokens[2], tokens[6], tokens[10] = (f"{-float(tokens[k]):.17g}" for k in (2, 6, 10))
    elif mutation == "far":
        tokens[3] = f"{2 * MAX_WORLD_COORDINATE:.17g}"
    line = " ".join(tokens)
    text = [pose_line(good)] * (lines - 1) + ([""] if mutation == "blank" else []) + [line, pose_line(good)]
    path = tmp_path / "poses.txt"
    path.write_text("\n".join(text) + "\n")
    if mutation == "none":
        poses = read_poses(path)
        assert poses.shape == (lines + 1, 3, 4)
        assert np.allclose(poses[-2], good, atol=1e-12)
        return
    with pytest.raises(InputError) as caught:
        read_poses(path)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{path}, line {lines}:")


# --- occtool map ------------------------------------------------------------------------------


def room(n: int = 6000, seed: int = 0) -> np.ndarray:
    """World points of a 9 m x 6 m room with a floor, four walls and a box (the box breaks the symmetry)."""
    rng = np.random.default_rng(seed)
    k = n // 7
    u = rng.uniform
    return np.concatenate([
        np.column_stack([u(-4, 5, k), u(-3, 3, k), np.zeros(k)]),
        np.column_stack([np.full(k, 5.0), u(-3, 3, k), u(0, 2.5, k)]),
        np.column_stack([np.full(k, -4.0), u(-3, 3, k), u(0, 2.5, k)]),
        np.column_stack([u(-4, 5, k), np.full(k, 3.0), u(0, 2.5, k)]),
        np.column_stack([u(-4, 5, k), np.full(k, -3.0), u(0, 2.5, k)]),
        np.column_stack([np.full(k, 2.0), u(0.5, 1.5, k), u(0, 1.0, k)]),
        np.column_stack([u(2.0, 3.0, k), np.full(k, 0.5), u(0, 1.0, k)]),
    ])


def map_cli(*args):
    from click.testing import CliRunner

    from occtool.cli.main import cli

    return CliRunner().invoke(cli, ["-q", "map", *(str(a) for a in args)], catch_exceptions=False)


def test_two_pcds_without_poses_are_registered_and_mapped(tmp_path):
    pytest.importorskip("small_gicp")
    world = room()
    files = []
    for k, matrix in enumerate([transform(0, 0, 0, (0, 0, 1.0)), transform(0, 0, 0.1, (0.3, 0.1, 1.0))]):
        files.append(write_pcd(tmp_path / f"{k}.pcd", (world - matrix[:, 3]) @ matrix[:, :3]))
    result = map_cli(*files, "-o", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "out" / "world.occmap").is_file()
    rows = (tmp_path / "out" / "poses.csv").read_text().splitlines()
    x, y, _, yaw = (float(v) for v in rows[2].split(",")[2:])
    assert abs(x - 0.3) < 0.02 and abs(y - 0.1) < 0.02 and abs(yaw - 0.1) < 0.01


def test_a_folder_of_scans_with_poses_maps_without_registering(tmp_path):
    folder, poses, _ = scan_folder(tmp_path)
    result = map_cli(folder, "--poses", poses, "-o", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "out" / "world.occmap").is_file()
    assert not (tmp_path / "out" / "poses.csv").exists()  # the poses file's poses were kept


@pytest.mark.slow
def test_map_of_the_first_three_seosan_scans(tmp_path, shared_data):
    import json
    import shutil

    source = shared_data / "lidar_seosan01"
    scans = tmp_path / "Scans"
    scans.mkdir()
    for k in range(3):
        shutil.copy(source / "Scans" / f"{k:06d}.pcd", scans)
    result = map_cli(scans, "--poses", source / "optimized_poses.txt", "-o", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "out" / "world.occmap").stat().st_size > 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["positions"] == 3
    # A 3D lidar: a 3D map; three positions are too few to hold some out: the coarsest cell.
    assert summary["world_map"]["kind"] == "3d" and summary["world_map"]["resolution"] == 0.4


def test_info_describes_a_folder_of_scans(tmp_path):
    from rich.console import Console

    from occtool.io import describe_log

    folder, _, _ = scan_folder(tmp_path)
    console = Console(width=200, record=True)
    console.print(describe_log(folder))
    text = console.export_text()
    assert "scans" in text and "1,200" in text  # three scans of 400 points
    size = sum(p.stat().st_size for p in folder.iterdir())
    assert f"{size:,} bytes" in text
