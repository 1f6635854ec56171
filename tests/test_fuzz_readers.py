"""Issue 12, classes 1, 3, 7 and 11: corrupt or hostile range logs are one-line errors.

Corrupt data is never read as data (MCAP chunk CRCs, xyz column counts, coordinates
that overflow), non-finite poses are refused naming where they are, malformed PCD and
PLY headers are errors, compressed input is told by its bytes and bounded, a UTF-8
byte-order mark is accepted.
"""

from __future__ import annotations

import bz2
import gzip
import math
import traceback
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import example, given, settings
from hypothesis import strategies as st
from test_io_mcap import header, laserscan, quaternion, transform, write_ros2

from occtool import limits
from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.features import Features
from occtool.io import describe_log, read_log, write_mcap

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures"


def run(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


def assert_one_line_error(result, *fragments: str) -> str:
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError("uncaught exception:\n" + "".join(traceback.format_exception(*result.exc_info)))
    assert result.exit_code != 0, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1, result.output
    assert "Traceback" not in result.output
    for fragment in fragments:
        assert fragment.lower() in " ".join(result.output.split()).lower(), (fragment, result.output)
    return errors[0]


def points_text(n: int = 50, seed: int = 0) -> str:
    xyz = np.random.default_rng(seed).uniform(-2.0, 2.0, (n, 3))
    return "".join(f"{x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in xyz)


# --- class 1: corrupt data ----------------------------------------------------------------


@pytest.fixture(scope="module")
def chunked_mcap(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("mcap")
    path = folder / "features.mcap"
    write_mcap(read_log(FIXTURES / "office" / "features.csv"), path)
    return path


def _chunk_span(path: Path) -> tuple[int, int]:
    """Byte range of the (first) chunk's compressed records in a file occtool wrote."""
    from mcap.reader import make_reader

    with open(path, "rb") as handle:
        index = make_reader(handle).get_summary().chunk_indexes[0]
    start = index.chunk_start_offset + 1 + 8 + 8 + 8 + 8 + 4 + 4 + len(index.compression) + 8
    return start, index.chunk_start_offset + index.chunk_length


@settings(max_examples=20)
@given(fraction=st.floats(0.0, 1.0, exclude_max=True), bit=st.integers(0, 7))
def test_a_flipped_bit_inside_an_mcap_chunk_is_a_one_line_error(tmp_path_factory, chunked_mcap, fraction, bit):
    data = bytearray(chunked_mcap.read_bytes())
    start, stop = _chunk_span(chunked_mcap)
    data[start + int(fraction * (stop - start))] ^= 1 << bit
    path = tmp_path_factory.mktemp("flip") / "flipped.mcap"
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match="corrupt"):
        read_log(path)


def test_info_says_whether_mcap_chunks_carry_checksums(tmp_path, chunked_mcap):
    from mcap.writer import CompressionType, Writer

    assert "CRC32 on all 1 chunk(s)" in " ".join(run("info", chunked_mcap).output.split())
    path = tmp_path / "nocrc.mcap"
    with open(path, "wb") as handle:
        writer = Writer(handle, compression=CompressionType.NONE, enable_crcs=False)
        writer.start()
        schema = writer.register_schema("s", "jsonschema", b"{}")
        channel = writer.register_channel("/x", "json", schema)
        writer.add_message(channel, log_time=0, publish_time=0, data=b"{}")
        writer.finish()
    text = " ".join(run("info", path).output.split())
    assert "carry no CRC32" in text, text


@settings(max_examples=30)
@given(columns=st.integers(1, 40).filter(lambda c: c not in (3, 4)))
def test_xyz_lines_must_hold_three_or_four_numbers(tmp_path_factory, columns):
    path = tmp_path_factory.mktemp("xyz") / "scan.xyz"
    path.write_text("".join(" ".join(["1.5"] * columns) + "\n" for _ in range(5)))
    with pytest.raises(InputError, match="expected x y z"):
        read_log(path)


def test_xyz_with_four_columns_keeps_the_first_three(tmp_path):
    path = tmp_path / "scan.xyz"
    path.write_text("1 2 3 0.5\n-1 0.5 0.2 7\n")
    assert read_log(path).single().features.points.tolist() == [[1, 2, 3], [-1, 0.5, 0.2]]


def test_a_raw_laser_log_of_another_layout_is_refused_as_a_laser_log(tmp_path):
    # BreezySLAM's URG layout (707 values a line) is read as format urg; 300 values is no known layout.
    path = tmp_path / "scan.dat"
    path.write_text("".join(" ".join(["1500"] * 300) + "\n" for _ in range(3)))
    error = assert_one_line_error(run("info", path), "line 1", "300 values", "raw laser log")
    assert "1500 1500" not in error


def test_a_damaged_urg_line_is_one_line_naming_it(shared_data, tmp_path):
    lines = (shared_data / "mines_paristech_urg" / "exp1.dat").read_text().splitlines()[:5]
    lines[3] = lines[3].rsplit(" ", 2)[0]  # two values short
    path = tmp_path / "exp1.dat"
    path.write_text("\n".join(lines) + "\n")
    assert_one_line_error(run("info", path), "line 4", "706 values")


@settings(max_examples=30)
@given(big=st.floats(min_value=limits.MAX_COORDINATE * 1.01, max_value=1e308), axis=st.integers(0, 2),
       sign=st.sampled_from([-1.0, 1.0]))
def test_coordinates_beyond_a_thousand_kilometres_are_refused(big, axis, sign):
    points = np.ones((3, 3))
    points[1, axis] = sign * big
    with pytest.raises(InputError, match="farther than"):
        Features(points, np.full(3, 0.9))


def test_an_xyz_file_with_1e308_is_an_error_not_an_empty_model(tmp_path):
    path = tmp_path / "big.xyz"
    path.write_text("1e308 1e308 1e308\n1 2 0\n1 0 0\n")
    out = tmp_path / "m.json"
    assert_one_line_error(run("fit", path, "-o", out, "--pieces", "8"), "big.xyz", "farther than")
    assert not out.exists()


# --- class 3: non-finite poses ---------------------------------------------------------------


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_a_non_finite_node_pose_is_an_error_naming_the_line(tmp_path, value):
    path = tmp_path / "scan.dat"
    path.write_text(points_text() + f"NODE {value} 0 0 0 0 0\n" + points_text(seed=1))
    with pytest.raises(InputError, match=r"line 51: the scan's pose is not finite"):
        read_log(path)
    log = read_log(path, skip_invalid=True)
    assert len(log.single().features) == 50
    assert any("NODE pose is not finite" in note for note in log.notes)
    assert not any("sensor origin" in note for note in log.notes)


def _odometry(t: float, x: float, orientation: dict | None = None) -> dict:
    return {
        "header": header(t, "odom"), "child_frame_id": "base_link",
        "pose": {"pose": {"position": {"x": x, "y": 1.0, "z": 0.0}, "orientation": orientation or quaternion(0.0)},
                 "covariance": [0.0] * 36},
        "twist": {"twist": {"linear": {"x": 0, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}},
                  "covariance": [0.0] * 36},
    }


@pytest.mark.parametrize("x", [math.nan, math.inf])
def test_a_non_finite_odometry_pose_is_an_error(tmp_path, x):
    messages = [("/odom", "nav_msgs/msg/Odometry", _odometry(1.0, x), 1.0),
                ("/scan", "sensor_msgs/msg/LaserScan", laserscan(1.0, "base_link", [1.0, 2.0]), 1.001)]
    path = write_ros2(tmp_path / "odom.mcap", messages)
    with pytest.raises(InputError, match="odometry pose is not finite"):
        read_log(path)


def test_a_zero_odometry_quaternion_is_an_error(tmp_path):
    zero = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 0.0}
    messages = [("/odom", "nav_msgs/msg/Odometry", _odometry(1.0, 0.0, zero), 1.0),
                ("/scan", "sensor_msgs/msg/LaserScan", laserscan(1.0, "base_link", [1.0, 2.0]), 1.001)]
    with pytest.raises(InputError, match="zero quaternion"):
        read_log(write_ros2(tmp_path / "odom.mcap", messages))


@pytest.mark.parametrize("field", ["angle_min", "angle_increment", "range_min"])
def test_a_laserscan_with_a_nan_angle_is_an_error_not_dropped_beams(tmp_path, field):
    scan = laserscan(1.0, "base_link", [1.0, 2.0, 3.0])
    scan[field] = math.nan
    path = write_ros2(tmp_path / "scan.mcap", [("/scan", "sensor_msgs/msg/LaserScan", scan, 1.0)])
    with pytest.raises(InputError, match=f"{field} is nan, not a finite number"):
        read_log(path)


def _tf_static_scan(tmp_path: Path, rotation: dict, translation=(0.2, 0.0, 0.3)) -> Path:
    static = transform(0.0, "base_link", "laser", translation)
    static["transform"]["rotation"] = rotation
    return write_ros2(tmp_path / "tf.mcap", [
        ("/tf_static", "tf2_msgs/msg/TFMessage", {"transforms": [static]}, 0.0),
        ("/scan", "sensor_msgs/msg/LaserScan", laserscan(1.0, "laser", [1.0, 2.0]), 1.0),
    ])


def test_a_zero_quaternion_in_tf_static_is_an_error_and_extract_world_never_runs(tmp_path):
    path = _tf_static_scan(tmp_path, {"x": 0.0, "y": 0.0, "z": 0.0, "w": 0.0})
    with pytest.raises(InputError, match=r"/tf_static: the transform base_link -> laser has the zero quaternion"):
        read_log(path)
    folder = tmp_path / "models"
    folder.mkdir()
    assert_one_line_error(run("fit", path, "-o", f"{folder}/"), "zero quaternion")
    assert list(folder.iterdir()) == []


@settings(max_examples=25)
@given(values=st.lists(st.sampled_from([0.0, 1.0, math.nan, math.inf, -math.inf]), min_size=7, max_size=7)
       .filter(lambda v: not all(math.isfinite(x) for x in v) or not any(v[3:])))
def test_tf_static_transforms_are_finite_rotations_or_refused(tmp_path_factory, values):
    rotation = dict(zip("xyzw", values[3:]))
    path = _tf_static_scan(tmp_path_factory.mktemp("tf"), rotation, translation=values[:3])
    with pytest.raises(InputError, match="base_link -> laser"):
        read_log(path)


# --- class 7: PCD and PLY headers -------------------------------------------------------------

PCD_HEADER = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT {count}\nWIDTH {width}\nHEIGHT 1\n"
              "POINTS {points}\nDATA {data}\n")


def _pcd(path: Path, data: str, points: int, width: int | None = None, count: str = "1 1 1", body: bytes = b"") -> Path:
    text = PCD_HEADER.format(count=count, width=points if width is None else width, points=points, data=data)
    path.write_bytes(text.encode() + body)
    return path


@pytest.mark.parametrize(("points", "width", "count", "message"), [
    (-5, -5, "1 1 1", "must be >= 0"),
    (10, 10, "0 1 1", "COUNT must be whole numbers >= 1"),
    (10, 7, "1 1 1", "differs from WIDTH x HEIGHT"),
])
def test_pcd_headers_that_cannot_describe_the_data_are_errors(tmp_path, points, width, count, message):
    path = _pcd(tmp_path / "c.pcd", "ascii", points, width, count, points_text(10).encode())
    with pytest.raises(InputError, match=message):
        read_log(path)


@settings(max_examples=30)
@given(declared=st.integers(0, 60), held=st.integers(0, 60))
def test_binary_pcd_must_hold_exactly_points_records(tmp_path_factory, declared, held):
    body = np.random.default_rng(declared).uniform(0.5, 2.0, (held, 3)).astype("<f4").tobytes()
    path = _pcd(tmp_path_factory.mktemp("pcd") / "b.pcd", "binary", declared, body=body)
    if held == declared and held > 0:
        assert len(read_log(path).single().features) == held
    else:
        with pytest.raises(InputError):
            read_log(path)


def test_ascii_pcd_with_fewer_lines_than_points_is_an_error(tmp_path):
    path = _pcd(tmp_path / "a.pcd", "ascii", 20, body=points_text(10).encode())
    with pytest.raises(InputError, match="holds 10 points, the header says POINTS 20"):
        read_log(path)


PLY = "ply\nformat ascii 1.0\nelement vertex {n}\n{properties}end_header\n"


def test_a_ply_with_a_duplicated_property_is_an_error(tmp_path):
    path = tmp_path / "d.ply"
    properties = "property float x\nproperty float y\nproperty float z\nproperty float x\n"
    path.write_text(PLY.format(n=3, properties=properties)
                    + "1 2 3 4\n" * 3)
    with pytest.raises(InputError, match="names a property twice"):
        read_log(path)


@settings(max_examples=20)
@given(count=st.integers(-(10**12), -1))
def test_a_negative_ply_element_count_is_an_error(tmp_path_factory, count):
    path = tmp_path_factory.mktemp("ply") / "n.ply"
    properties = "property float x\nproperty float y\nproperty float z\n"
    path.write_text(PLY.format(n=count, properties=properties) + "1 2 3\n")
    with pytest.raises(InputError, match="does not parse"):
        read_log(path)


def _read_or_input_error(path: Path) -> Features | None:
    """The features read from ``path``, or ``None`` for an InputError that names the file.

    What a fuzzed file may give: one error class, naming the file; or finite features
    with evidence in [0, 1], no more of them than its body has room for (a point takes at
    least five bytes, ``1 2 3``, as text and twelve as binary floats).
    """
    try:
        log = read_log(path)
    except InputError as exc:
        assert path.name in str(exc), str(exc)
        return None
    features = Features(np.concatenate([p.features.points for p in log.positions]),
                        np.concatenate([p.features.evidence for p in log.positions]))
    body = path.read_bytes().split(b"end_header\n" if path.suffix == ".ply" else b"\nDATA", 1)[-1]
    assert 5 * len(features) <= len(body)
    assert np.isfinite(features.points).all()
    assert ((features.evidence >= 0.0) & (features.evidence <= 1.0)).all()
    return features


PLY_POINTS = "1 2 3\n-1 0.5 0.25\n4 -2 1\n"


@settings(max_examples=40)
@given(header_lines=st.lists(st.sampled_from([
    "format ascii 1.0", "format binary_little_endian 1.0", "element vertex 3", "element vertex -1", "element face 2",
    "property float x", "property float y", "property float z", "property double x", "property list uchar int i",
    "property bogus q", "comment hi", "element vertex 99999999999",
]), max_size=10), body=st.binary(max_size=64))
@example(header_lines=["format ascii 1.0", "element vertex 3", "property float x", "property float y",
                       "property float z"], body=PLY_POINTS.encode())
def test_fuzzed_ply_headers_never_raise_anything_but_input_errors(tmp_path_factory, header_lines, body):
    path = tmp_path_factory.mktemp("plyf") / "f.ply"
    path.write_bytes(("ply\n" + "".join(line + "\n" for line in header_lines) + "end_header\n").encode() + body)
    features = _read_or_input_error(path)
    if body == PLY_POINTS.encode() and header_lines[:2] == ["format ascii 1.0", "element vertex 3"]:
        assert features is not None  # the one valid file among them reads as written
        np.testing.assert_array_equal(features.points, [[1, 2, 3], [-1, 0.5, 0.25], [4, -2, 1]])
        np.testing.assert_array_equal(features.evidence, 0.9)  # no evidence property: the constant


@settings(max_examples=40)
@given(lines=st.lists(st.sampled_from([
    "FIELDS x y z", "FIELDS x y z x", "SIZE 4 4 4", "SIZE 4 4", "TYPE F F F", "TYPE F F X", "COUNT 1 1 1",
    "COUNT 0 1 1", "WIDTH 3", "WIDTH -3", "HEIGHT 1", "HEIGHT 0", "POINTS 3", "POINTS -5", "POINTS 99999999999",
    "VIEWPOINT 0 0 0 1 0 0 0", "VIEWPOINT nan 0 0 1 0 0 0",
]), max_size=10), data=st.sampled_from(["DATA ascii", "DATA binary", "DATA binary_compressed", "DATA x"]),
    body=st.binary(max_size=64))
@example(lines=["FIELDS x y z", "SIZE 4 4 4", "TYPE F F F", "COUNT 1 1 1", "WIDTH 3", "HEIGHT 1", "POINTS 3"],
         data="DATA ascii", body=PLY_POINTS.encode())
def test_fuzzed_pcd_headers_never_raise_anything_but_input_errors(tmp_path_factory, lines, data, body):
    path = tmp_path_factory.mktemp("pcdf") / "f.pcd"
    path.write_bytes(("VERSION 0.7\n" + "".join(line + "\n" for line in lines) + data + "\n").encode() + body)
    features = _read_or_input_error(path)
    if lines == ["FIELDS x y z", "SIZE 4 4 4", "TYPE F F F", "COUNT 1 1 1", "WIDTH 3", "HEIGHT 1", "POINTS 3"] \
            and data == "DATA ascii" and body == PLY_POINTS.encode():
        assert features is not None
        np.testing.assert_array_equal(features.points, [[1, 2, 3], [-1, 0.5, 0.25], [4, -2, 1]])


# --- class 11 (and 4): compressed and marked-up text ----------------------------------------------

CSV = "x,y,z,m\n1,0.5,0.2,0.9\n-1,0.5,0.3,0.8\n0.4,-1,0.1,0.7\n"


@pytest.mark.parametrize("compress", [gzip.compress, bz2.compress])
@pytest.mark.parametrize("name", ["plain.csv", "plain.txt", "scan.dat"])
def test_compressed_content_under_a_plain_name_is_decompressed(tmp_path, compress, name):
    text = CSV if name != "scan.dat" else "1 0.5 0.2\n-1 0.5 0.3\n0.4 -1 0.1\n"
    path = tmp_path / name
    path.write_bytes(compress(text.encode()))
    assert len(read_log(path, format=None if name != "plain.txt" else "csv").single().features) == 3


def test_a_csv_with_a_utf8_byte_order_mark_is_read(tmp_path):
    path = tmp_path / "bom.txt"
    path.write_bytes(b"\xef\xbb\xbf" + CSV.encode())
    assert len(read_log(path).single().features) == 3
    assert_text = " ".join(run("info", path).output.split())
    assert "features 3" in assert_text


@pytest.mark.parametrize("suffix", [".csv.gz", ".csv"])
def test_a_decompression_bomb_stops_at_the_limit(tmp_path, monkeypatch, suffix):
    monkeypatch.setattr(limits, "MAX_DECOMPRESSED_BYTES", 100_000)
    path = tmp_path / f"bomb{suffix}"
    path.write_bytes(gzip.compress(CSV.encode() + b"# padding\n" * 50_000))  # 500 KB of text
    with pytest.raises(InputError, match="expands to more than 100,000 bytes"):
        read_log(path)
    assert_one_line_error(run("info", path), "decompress")


def test_a_plain_file_is_not_bounded_by_the_decompression_limit(tmp_path, monkeypatch):
    monkeypatch.setattr(limits, "MAX_DECOMPRESSED_BYTES", 100)
    path = tmp_path / "plain.csv"
    path.write_text(CSV + "# padding\n" * 100)
    assert len(read_log(path).single().features) == 3


def test_describe_log_of_a_gzip_csv_under_a_plain_name(tmp_path):
    from rich.console import Console

    path = tmp_path / "g.txt"  # nothing in the name says CSV or gzip: the bytes do
    path.write_bytes(gzip.compress(CSV.encode()))
    console = Console(width=200, record=True, file=open(tmp_path / "out", "w"))  # noqa: SIM115
    console.print(describe_log(path))
    console.file.close()
    rows = {" ".join(line.split()[:1]): " ".join(line.split()[1:]) for line in console.export_text().splitlines()}
    assert rows["format"] == "csv"
    assert rows["positions"] == "1"
    assert rows["features"] == "3"
    assert rows["size"] == f"{path.stat().st_size:,} bytes"


@pytest.mark.parametrize(("name", "text"), [("far.csv", "x,y,z,m\n1,1,1,0.9\n1e308,0,0,0.9\n"),
                                            ("far.xyz", "1 1 1\n1e308 0 0\n")])
def test_readers_name_the_file_of_a_far_point_and_skip_it_when_asked(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(InputError, match=rf"{name}.*farther than"):
        read_log(path)
    assert len(read_log(path, skip_invalid=True).single().features) == 1
