"""The CSV reader and writer, and read_log's format choice for CSV."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.features import Features, Pose, Position, RangeLog
from occtool.io import detect_format, read_log, write_csv


def write(tmp_path: Path, text: str, name: str = "f.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_reads_points_and_evidence_ignoring_comments_blank_lines_and_extra_columns(tmp_path):
    path = write(
        tmp_path,
        "# recorded by hand\nlabel,x,y,z,m\nwall,1,0,0,0.5\n\n# a comment line\nchair,0,2,-0.5,0.75 # trailing\n",
    )
    log = read_log(path)
    assert len(log.positions) == 1
    features = log.single().features
    np.testing.assert_array_equal(features.points, [[1, 0, 0], [0, 2, -0.5]])
    np.testing.assert_array_equal(features.evidence, [0.5, 0.75])
    assert log.single().pose is None
    assert log.notes == []


def test_evidence_column_alias_and_named_field(tmp_path):
    path = write(tmp_path, "x,y,z,evidence,quality\n1,1,1,0.25,0.5\n")
    assert read_log(path).single().features.evidence.tolist() == [0.25]
    assert read_log(path, evidence_field="quality").single().features.evidence.tolist() == [0.5]


def test_constant_evidence_when_the_column_is_absent(tmp_path):
    path = write(tmp_path, "x,y,z\n1,1,1\n2,2,2\n")
    with pytest.raises(InputError, match="no evidence column"):
        read_log(path)
    assert read_log(path, evidence=0.6).single().features.evidence.tolist() == [0.6, 0.6]


@pytest.mark.parametrize(
    ("row", "message"),
    [
        ("1,abc,0,0.5", "column 'y' is not a number"),
        ("1,0,nan,0.5", "NaN or infinite"),
        ("1,0,inf,0.5", "NaN or infinite"),
        ("1,0,0,1.5", "outside \\[0, 1\\]"),
        ("1,0,0,-0.1", "outside \\[0, 1\\]"),
        ("0,0,0,0.5", "sensor origin"),
        ("1,0", "has 2 columns"),
    ],
)
def test_a_bad_row_is_an_error_naming_its_line(tmp_path, row, message):
    path = write(tmp_path, f"# header follows\nx,y,z,m\n1,1,1,0.5\n\n{row}\n2,2,2,0.5\n")
    with pytest.raises(InputError, match=f"f.csv, line 5: .*{message}"):
        read_log(path)


def test_the_earliest_bad_line_is_named_whatever_its_kind(tmp_path):
    path = write(tmp_path, "x,y,z,m\n0,0,0,0.5\n1,x,1,0.5\n")
    with pytest.raises(InputError, match="line 2: .*origin"):
        read_log(path)


def test_skip_invalid_drops_and_counts_bad_rows(tmp_path):
    path = write(tmp_path, "x,y,z,m\n1,1,1,0.5\n0,0,0,0.5\n1,x,1,0.5\n1,1,nan,0.5\n1,1,1,2\n3,3,3,1\n")
    log = read_log(path, skip_invalid=True)
    np.testing.assert_array_equal(log.single().features.points, [[1, 1, 1], [3, 3, 3]])
    assert any("skipped 4 invalid row(s)" in note for note in log.notes)


@pytest.mark.parametrize("text", ["", "# only a comment\n\n"])
def test_an_empty_file_is_an_error(tmp_path, text):
    with pytest.raises(InputError):
        read_log(write(tmp_path, text), format="csv")


def test_a_header_without_rows_is_an_error(tmp_path):
    with pytest.raises(InputError, match="no data rows"):
        read_log(write(tmp_path, "x,y,z,m\n"))


def test_missing_coordinate_columns_are_named(tmp_path):
    with pytest.raises(InputError, match="missing z"):
        read_log(write(tmp_path, "x,y,m\n1,2,0.5\n"), format="csv")


def test_position_column_groups_rows_in_order_of_appearance(tmp_path):
    path = write(tmp_path, "x,y,z,m,position\n1,0,0,0.1,7\n2,0,0,0.2,3\n3,0,0,0.3,7\n")
    log = read_log(path)
    assert [len(p.features) for p in log.positions] == [2, 1]
    assert log.positions[0].features.evidence.tolist() == [0.1, 0.3]
    assert [p.index for p in log.positions] == [0, 1]


def test_pose_columns_group_by_tolerance_and_move_points_into_the_reference_frame(tmp_path):
    # Scan A at the origin facing +x; scan B 0.1 m ahead, turned by 90 degrees: within
    # the default tolerance in distance, but not in angle, unless the angle tolerance is wide.
    text = (
        "x,y,z,m,pose_x,pose_y,pose_yaw\n"
        "1,0,0,0.5,0,0,0\n"
        "1,0,0,0.5,0.1,0,1.5707963267948966\n"
        "2,0,0,0.5,5,0,0\n"
    )
    path = write(tmp_path, text)
    log = read_log(path)
    assert len(log.positions) == 3
    wide = read_log(path, position_tolerance=(0.25, 2.0))
    assert len(wide.positions) == 2
    first = wide.positions[0]
    assert first.pose == Pose(0.0, 0.0, 0.0, 0.0)
    # B's point, 1 m ahead of a robot at (0.1, 0) facing +y, lies at (0.1, 1) in A's frame.
    np.testing.assert_allclose(first.features.points, [[1, 0, 0], [0.1, 1, 0]], atol=1e-12)
    assert wide.positions[1].pose == Pose(5.0, 0.0, 0.0, 0.0)
    assert len(read_log(path, group_by="message", position_tolerance=(0.25, 2.0)).positions) == 3


def test_compressed_csv_is_read(tmp_path):
    path = tmp_path / "f.csv.gz"
    with gzip.open(path, "wt") as handle:
        handle.write("x,y,z,m\n1,2,3,0.5\n")
    assert detect_format(path) == "csv"
    assert read_log(path).single().features.points.tolist() == [[1, 2, 3]]


@pytest.mark.slow
def test_large_file_reads_vectorised(tmp_path):
    rng = np.random.default_rng(0)
    points = rng.uniform(0.5, 5.0, size=(200_000, 3))
    evidence = rng.uniform(0, 1, size=200_000)
    path = tmp_path / "big.csv"
    write_csv(Features(points, evidence), path)
    features = read_log(path).single().features
    np.testing.assert_array_equal(features.points, points)
    np.testing.assert_array_equal(features.evidence, evidence)


finite = st.floats(min_value=-50, max_value=50, allow_nan=False, allow_subnormal=False)


@given(
    points=st.lists(
        st.tuples(finite, finite, finite).filter(lambda p: any(v != 0 for v in p)), min_size=1, max_size=30
    ),
    evidence=st.floats(min_value=0, max_value=1),
)
def test_write_then_read_round_trips_exactly(tmp_path_factory, points, evidence):
    path = tmp_path_factory.mktemp("rt") / "f.csv"
    features = Features.from_xyz(*np.array(points).T, evidence)
    write_csv(features, path)
    back = read_log(path).single().features
    np.testing.assert_array_equal(back.points, features.points)
    np.testing.assert_array_equal(back.evidence, features.evidence)


def test_a_log_with_positions_and_poses_round_trips(tmp_path):
    log = RangeLog(
        positions=[
            Position(0, Features.from_xyz([1, 2], [0, 1], [0, -1], [0.2, 0.4]), Pose(0.0, 0.0, 0.0, 0.0)),
            Position(1, Features.from_xyz([3], [3], [3], 1.0), Pose(10.0, -2.0, 0.5, 1.0)),
        ]
    )
    path = tmp_path / "log.csv"
    write_csv(log, path)
    back = read_log(path)
    assert [p.pose for p in back.positions] == [p.pose for p in log.positions]
    for mine, theirs in zip(log.positions, back.positions):
        np.testing.assert_array_equal(mine.features.points, theirs.features.points)
        np.testing.assert_array_equal(mine.features.evidence, theirs.features.evidence)


pose_values = st.tuples(
    st.floats(-20, 20), st.floats(-20, 20), st.floats(-1, 1), st.floats(-np.pi, np.pi)
)


@given(poses=st.lists(pose_values, min_size=1, max_size=5), seed=st.integers(0, 1000))
def test_points_keep_their_world_position_when_moved_into_the_position_frame(tmp_path_factory, poses, seed):
    # Whatever the poses, grouping everything into one position must not move any point in
    # the world: reference.to_world(p') == own_pose.to_world(p), heights shifted by pose z.
    rng = np.random.default_rng(seed)
    rows, world = [], []
    for x, y, z, yaw in poses:
        pts = rng.uniform(0.5, 5.0, size=(3, 3))
        own = Pose(x, y, z, yaw)
        world.append(np.column_stack([own.to_world(pts[:, :2]), pts[:, 2] + z]))
        rows += [f"{p[0]!r},{p[1]!r},{p[2]!r},0.5,{x!r},{y!r},{z!r},{yaw!r}" for p in pts.tolist()]
    path = tmp_path_factory.mktemp("poses") / "f.csv"
    path.write_text("x,y,z,m,pose_x,pose_y,pose_z,pose_yaw\n" + "\n".join(rows) + "\n")
    log = read_log(path, position_tolerance=(1e3, 4.0))
    assert len(log.positions) == 1
    position = log.single()
    back = np.column_stack([position.pose.to_world(position.features.points[:, :2]),
                            position.features.points[:, 2] + position.pose.z])
    np.testing.assert_allclose(back, np.vstack(world), atol=1e-9)


def test_a_truncated_compressed_file_is_a_clear_error(tmp_path):
    path = tmp_path / "f.csv.gz"
    with gzip.open(path, "wt") as handle:
        handle.write("x,y,z,m\n" + "1,2,3,0.5\n" * 5000)
    path.write_bytes(path.read_bytes()[:-40])
    with pytest.raises(InputError, match="truncated or corrupt|cannot be read"):
        read_log(path)
