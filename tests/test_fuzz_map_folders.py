"""Issue 37: a damaged map folder given to `plot map` is one line naming the file, never a picture.

The campaign's map folders (map.yaml, map.pgm or map.png, summary.json, frontiers.geojson):
valid-looking YAML with values out of map_server's ranges (resolution NaN, -1 or 0,
``free_thresh: nan``, a Latin-1 byte), PGM headers that lie about the file's length, PNG
headers that claim huge images, and JSON nested deep or holding huge integers. Each is
refused by the library with an InputError whose one line starts with the damaged file's
path, and by `occtool plot map` with that line, exit 1 and no file in the output folder.
"""

from __future__ import annotations

import json
import re
import struct
import traceback
import zlib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import example, given
from hypothesis import strategies as st

from occtool._json import MAX_JSON_DEPTH
from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.formats.nav2 import PNG_DECODE_BYTES, read_nav2, write_nav2
from occtool.limits import DEFAULT_MEMORY_LIMIT, memory_bytes
from occtool.plot import read_map_folder

pytest.importorskip("matplotlib")

GOOD_YAML = {"image": "map.pgm", "mode": "trinary", "resolution": "0.05", "origin": "[-1.0, 2.0, 0.0]",
             "negate": "0", "occupied_thresh": "0.65", "free_thresh": "0.196"}
RANGE = r"must be a number in \[{low}, {high}\] \({unit}\), got '.*'"
RESOLUTION = RANGE.format(low="1e-06", high="10000", unit="metres per cell")
THRESHOLD = RANGE.format(low="0", high="1", unit="occupancy probability")


def make_folder(folder: Path) -> Path:
    """A small map folder as `occtool map` writes it: a wall one cell thick, a path, frontiers."""
    folder.mkdir(exist_ok=True)
    pixels = np.full((12, 20), 254, dtype=np.uint8)
    pixels[:, 9] = 0
    pixels[:2] = 205
    write_nav2(pixels, 0.05, (-1.0, 2.0), folder / "map.yaml")
    (folder / "summary.json").write_text(json.dumps({"positions": 2, "path": [[-0.5, 2.1], [-0.2, 2.4]]}))
    (folder / "frontiers.geojson").write_text(json.dumps({
        "type": "FeatureCollection", "properties": {"frame": "map", "kind": "frontier"},
        "features": [{"type": "Feature", "properties": {"kind": "frontier"},
                      "geometry": {"type": "Point", "coordinates": [-0.4, 2.5]}}]}))
    return folder


def write_yaml(folder: Path, settings: dict[str, str]) -> None:
    (folder / "map.yaml").write_text("".join(f"{key}: {value}\n" for key, value in settings.items()))


def assert_refused(folder: Path, damaged: str, pattern: str) -> None:
    """The library and the command both refuse ``folder`` in one line naming ``damaged``, and
    the command writes nothing."""
    expected = re.escape(str(folder / damaged)) + ": " + pattern
    with pytest.raises(InputError) as caught:
        read_map_folder(folder)
    message = str(caught.value)
    assert "\n" not in message and re.fullmatch(expected, message), message
    out = folder.parent / (folder.name + "-out")
    out.mkdir()
    result = CliRunner().invoke(cli, ["plot", "map", str(folder), "-o", str(out / "map.png"), "--size", "200,200px"])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError("uncaught exception:\n" + "".join(traceback.format_exception(*result.exc_info)))
    assert result.exit_code == 1, result.output
    assert result.output.splitlines() == [f"Error: {message}"], result.output
    assert list(out.iterdir()) == []  # no picture, no temporary file


def test_the_undamaged_folder_is_drawn(tmp_path):
    folder = make_folder(tmp_path / "map")
    nav2, path, frontiers = read_map_folder(folder)
    assert nav2.cells.shape == (12, 20) and path == [[-0.5, 2.1], [-0.2, 2.4]] and frontiers.shape == (1, 2)
    result = CliRunner().invoke(cli, ["plot", "map", str(folder), "-o", str(tmp_path / "map.png"),
                                      "--size", "200,200px"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --- map.yaml: valid-looking, values out of range -------------------------------------------

NOT_POSITIVE = st.one_of(st.floats(max_value=0.0, allow_nan=False).map(repr), st.sampled_from(["0", "-1", "-0.0"]))
NOT_FINITE = st.sampled_from(["nan", "NaN", "inf", "-inf", "1e400", ".nan", "~", "", "0.05m", "0x10", "[0.05]"])
OUT_OF_UNIT = st.one_of(st.floats(min_value=1.0, exclude_min=True, allow_infinity=False).map(repr),
                        st.floats(max_value=0.0, exclude_max=True, allow_infinity=False).map(repr))
BAD_ORIGINS = st.one_of(
    st.sampled_from(["[nan, 0, 0]", "[0, inf, 0]", "[0, 0, nan]", "[0, 0]", "[0, 0, 0, 0]", "0, 0, 0", "[]",
                     "[a, b, c]", "[1e400, 0, 0]"]),
    st.floats(min_value=1e8, exclude_min=True, allow_infinity=False).map(lambda x: f"[{x!r}, 0.0, 0.0]"),
)


BAD_SETTINGS = st.one_of(
    st.tuples(st.just("resolution"), st.one_of(NOT_POSITIVE, NOT_FINITE, st.just("1e5"))),
    st.tuples(st.sampled_from(["free_thresh", "occupied_thresh"]), st.one_of(NOT_FINITE, OUT_OF_UNIT)),
    st.tuples(st.just("origin"), BAD_ORIGINS),
    st.tuples(st.just("negate"), st.sampled_from(["2", "-1", "true", "0.5", "", "yes"])),
    st.tuples(st.just("mode"), st.sampled_from(["raw", "Trinary", "", "scale trinary"])),
)
SETTING_ERRORS = {
    "resolution": "resolution " + RESOLUTION,
    "free_thresh": "free_thresh " + THRESHOLD,
    "occupied_thresh": "occupied_thresh " + THRESHOLD,
    "origin": r"origin must be \[x, y, yaw\], finite, x and y within 1e\+08 m, got '.*'",
    "negate": "negate must be 0 or 1, got '.*'",
    "mode": r"mode '.*' is not read \(trinary or scale\)",
}


@given(BAD_SETTINGS)
@example(("resolution", "nan"))  # the campaign's: a traceback
@example(("resolution", "-1"))  # drawn
@example(("resolution", "0"))  # drawn
@example(("free_thresh", "nan"))  # drawn
def test_a_setting_out_of_range_is_refused(tmp_path_factory, setting):
    key, value = setting
    folder = make_folder(tmp_path_factory.mktemp("yaml"))
    write_yaml(folder, {**GOOD_YAML, key: value})
    assert_refused(folder, "map.yaml", SETTING_ERRORS[key])


@given(st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_thresholds_in_the_wrong_order_are_refused(tmp_path_factory, free, occupied):
    folder = make_folder(tmp_path_factory.mktemp("thresh"))
    free, occupied = max(free, occupied), min(free, occupied)  # free >= occupied
    write_yaml(folder, {**GOOD_YAML, "free_thresh": repr(free), "occupied_thresh": repr(occupied)})
    assert_refused(folder, "map.yaml", r"free_thresh \S+ must be below occupied_thresh \S+")


@given(st.sampled_from(sorted(set(GOOD_YAML) - {"mode", "negate"})))
def test_a_missing_setting_is_refused(tmp_path_factory, key):
    folder = make_folder(tmp_path_factory.mktemp("missing"))
    write_yaml(folder, {k: v for k, v in GOOD_YAML.items() if k != key})
    assert_refused(folder, "map.yaml", rf"no {key} \(map_server needs .*\)")


@given(st.binary(min_size=1, max_size=8).filter(lambda b: not _is_utf8(b)), st.integers(0, 200))
@example(b"\xe9", 20)  # a Latin-1 e-acute
def test_a_yaml_that_is_not_utf8_is_refused(tmp_path_factory, junk, at):
    folder = make_folder(tmp_path_factory.mktemp("latin1"))
    text = (folder / "map.yaml").read_bytes()
    at = min(at, len(text))
    (folder / "map.yaml").write_bytes(text[:at] + junk + text[at:])
    assert_refused(folder, "map.yaml", r"not UTF-8 text \(byte \d+\), not a Nav2 map.yaml")


def _is_utf8(data: bytes) -> bool:
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def test_an_endless_yaml_is_refused_unread(tmp_path):
    folder = make_folder(tmp_path / "map")
    with open(folder / "map.yaml", "a") as handle:
        handle.write("# padding\n" * 10_000)
    assert_refused(folder, "map.yaml", r"longer than 65,536 bytes, not a Nav2 map.yaml")


@given(st.sampled_from(["missing.pgm", "../map", ".", "sub/none.pgm"]))
def test_an_image_that_is_not_a_file_is_refused(tmp_path_factory, image):
    folder = make_folder(tmp_path_factory.mktemp("image"))
    write_yaml(folder, {**GOOD_YAML, "image": image})
    assert_refused(folder, "map.yaml", r"image '.*' is not a file \(.*\)")


@given(st.floats(min_value=1.0, max_value=1e4), st.floats(min_value=-1e8, max_value=1e8))
def test_a_map_reaching_past_the_coordinate_range_is_refused(tmp_path_factory, resolution, x):
    folder = make_folder(tmp_path_factory.mktemp("far"))
    # 20 columns of `resolution` metres from x: refused exactly when the far corner is beyond 1e8 m.
    write_yaml(folder, {**GOOD_YAML, "resolution": repr(resolution), "origin": f"[{x!r}, 0.0, 0.0]"})
    if abs(x + 20 * resolution) <= 1e8:
        assert read_nav2(folder / "map.yaml").cells.shape == (12, 20)
    else:
        assert_refused(folder, "map.yaml", r"the map's far corner \(.*\) lies beyond 1e\+08 m "
                                           r"\(check resolution and origin\)")


# --- map.pgm: headers that lie about the file ----------------------------------------------


@given(st.integers(1, 40), st.integers(1, 40), st.sampled_from([1, 15, 255, 256, 65535]), st.integers(-50, 50))
@example(3, 4, 255, -1)  # one byte short
@example(3, 4, 255, 1)  # one byte too long
@example(3, 4, 65535, -1)  # half a 16-bit sample short
def test_a_pgm_whose_header_lies_about_its_length_is_refused(tmp_path_factory, width, height, maxval, error):
    folder = make_folder(tmp_path_factory.mktemp("pgm"))
    sample = 1 if maxval < 256 else 2
    length = max(0, width * height * sample + error)
    (folder / "map.pgm").write_bytes(f"P5\n{width} {height}\n{maxval}\n".encode() + bytes(length))
    if length == width * height * sample:
        assert read_nav2(folder / "map.yaml").cells.shape == (height, width)
        return
    assert_refused(folder, "map.pgm", rf"the PGM header says {width}x{height} pixels \([\d,]+ bytes\) but "
                                      rf"[\d,]+ bytes follow it \(a short or padded file\)")


@given(st.integers(1, 2**31), st.integers(1, 2**31))
@example(100_000, 100_000)
def test_a_pgm_claiming_a_huge_image_is_refused_before_reading(tmp_path_factory, width, height):
    # A PGM holds every pixel it claims: a header its length does not bear out is refused
    # from the two, before any pixel is read, however large it claims to be.
    folder = make_folder(tmp_path_factory.mktemp("pgm"))
    (folder / "map.pgm").write_bytes(f"P5 {width} {height} 255\n".encode() + bytes(16))
    if width * height == 16:
        return
    assert_refused(folder, "map.pgm", r"the PGM header says .* \(a short or padded file\)")


@given(st.sampled_from([
    (b"P5\n2 2\n0\n" + bytes(4), r"PGM maxval 0 is not in \[1, 65535\]"),
    (b"P5\n2 2\n65536\n" + bytes(8), r"PGM maxval 65536 is not in \[1, 65535\]"),
    (b"P5\n2 2\n15\n" + bytes([0, 16, 0, 0]), r"a pixel value 16 is above the PGM maxval 15"),
    (b"P5\n-2 2\n255\n" + bytes(4), r"malformed PGM header \(.*\)"),
    (b"P5\n2 2.0\n255\n" + bytes(4), r"malformed PGM header \(.*\)"),
    (b"P5\n0 2\n255\n", r"a 0x2 PGM image has no pixels"),
    (b"P2\n2 2\n255\n0 0 0 0\n", r"not a binary PGM \(P5\) image"),
    (b"P5\n2 2\n# no end of comment", r"truncated PGM header"),
    (b"P5\n2 2\n255", r"truncated PGM header"),
    (b"", r"truncated PGM header"),
]))
def test_a_malformed_pgm_header_is_refused(tmp_path_factory, case):
    data, pattern = case
    folder = make_folder(tmp_path_factory.mktemp("pgm"))
    (folder / "map.pgm").write_bytes(data)
    assert_refused(folder, "map.pgm", pattern)


# --- map.png: headers that claim huge images, truncated files ------------------------------


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


@given(st.integers(1, 2**31 - 1), st.integers(1, 2**31 - 1), st.sampled_from([0, 2, 4, 6]))
@example(8_000, 8_000, 6)
@example(2**31 - 1, 2**31 - 1, 6)
def test_a_png_claiming_a_huge_image_is_refused_from_its_header(tmp_path_factory, width, height, colour):
    # Decoded whole, a PNG of more than this many pixels needs more than the default memory limit.
    most = memory_bytes(DEFAULT_MEMORY_LIMIT) // PNG_DECODE_BYTES
    if width * height <= most:
        width = most // height + 1
    folder = make_folder(tmp_path_factory.mktemp("png"))
    header = struct.pack(">IIBBBBB", width, height, 8, colour, 0, 0, 0)
    (folder / "map.png").write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header)
                                     + _chunk(b"IDAT", zlib.compress(b"\0" * 64)))
    write_yaml(folder, {**GOOD_YAML, "image": "map.png", "mode": "scale", "free_thresh": "0.25"})
    expected = (re.escape(str(folder / "map.png")) + rf": a {width}x{height} map image needs about [0-9.]+ [GT]B of "
                r"memory to read, over the limit of 4.0 GB: raise it with {}[0-9]+G'?")
    with pytest.raises(InputError, match=expected.format("memory_limit='")):
        read_map_folder(folder)
    out = folder.parent / (folder.name + "-out")
    out.mkdir()
    result = CliRunner().invoke(cli, ["plot", "map", str(folder), "-o", str(out / "map.png"), "--size", "200,200px"])
    assert result.exit_code == 1 and re.fullmatch("Error: " + expected.format("--memory-limit "),
                                                  result.output.strip()), result.output
    assert list(out.iterdir()) == []


@given(st.data())
def test_a_truncated_png_is_refused(tmp_path_factory, data):
    from PIL import Image

    folder = make_folder(tmp_path_factory.mktemp("png"))
    rgba = np.random.default_rng(0).integers(0, 256, (30, 40, 4), dtype=np.uint8)
    Image.fromarray(rgba, mode="RGBA").save(folder / "map.png")
    whole = (folder / "map.png").read_bytes()
    cut = data.draw(st.integers(0, len(whole) - 1), label="cut")
    (folder / "map.png").write_bytes(whole[:cut])
    write_yaml(folder, {**GOOD_YAML, "image": "map.png", "mode": "scale", "free_thresh": "0.25"})
    assert_refused(folder, "map.png", r"not a PNG image \(no PNG signature and IHDR header\)" if cut < 24
                   else r"truncated PNG image \(it does not end with an IEND chunk\)")


# --- summary.json and frontiers.geojson: deep nesting, huge integers, non-numbers -----------


@given(st.integers(3, 200_000))
@example(100_000)
@example(MAX_JSON_DEPTH - 1)
@example(MAX_JSON_DEPTH)
@example(950)
def test_a_deeply_nested_summary_is_refused(tmp_path_factory, depth):
    folder = make_folder(tmp_path_factory.mktemp("json"))
    (folder / "summary.json").write_text('{"path": ' + "[" * depth + "]" * depth + "}")
    # Past MAX_JSON_DEPTH (the object and its arrays) a JSON error, whatever the stack;
    # short of it, a path that is no list of pairs.
    assert_refused(folder, "summary.json", r"not valid JSON \(line 1: nested too deeply\)" if depth + 1 > MAX_JSON_DEPTH
                   else r"path must be \[x, y\] pairs .*")


@given(st.integers(21, 5000), st.sampled_from(["summary.json", "frontiers.geojson"]))
@example(400, "summary.json")
def test_a_huge_integer_is_refused(tmp_path_factory, digits, name):
    folder = make_folder(tmp_path_factory.mktemp("json"))
    number = "9" * digits
    if name == "summary.json":
        text = '{"path": [[' + number + ", 0]]}"
    else:
        text = ('{"type": "FeatureCollection", "properties": {"frame": "map"}, "features": [{"type": "Feature",'
                ' "geometry": {"type": "Point", "coordinates": [0, ' + number + "]}}]}")
    (folder / name).write_text(text)
    assert_refused(folder, name, rf"not valid JSON \(line 1: an integer of {digits} digits \(9+\.\.\.\) is too long "
                                 r"to be a value\)")


NOT_A_POINT = st.one_of(
    st.sampled_from(["NaN", "Infinity", "-Infinity", "1e400", '"1"', "true", "null", "[1]", "{}"]),
    st.integers(10**8 + 1, 10**19).map(str),
    st.floats(min_value=1e8, exclude_min=True, allow_infinity=False).map(repr),
)


@given(NOT_A_POINT, st.sampled_from(["summary.json", "frontiers.geojson"]))
def test_a_coordinate_that_is_not_a_finite_number_in_range_is_refused(tmp_path_factory, value, name):
    folder = make_folder(tmp_path_factory.mktemp("json"))
    if name == "summary.json":
        (folder / name).write_text('{"path": [[0.5, 2.5], [' + value + ", 2.0]]}")
        what = "path"
    else:
        (folder / name).write_text('{"type": "FeatureCollection", "properties": {"frame": "map"}, "features": ['
                                   '{"type": "Feature", "geometry": {"type": "Point", "coordinates": [0, '
                                   + value + "]}}]}")
        what = "each frontier's coordinates"
    assert_refused(folder, name, rf"{what} must be \[x, y\] pairs of finite numbers within 1e\+08 m "
                                 r"\(as `occtool map` writes it\)")


@given(st.sampled_from(["[]", '"path"', "1", "null"]))
def test_a_summary_that_is_not_an_object_is_refused(tmp_path_factory, text):
    folder = make_folder(tmp_path_factory.mktemp("json"))
    (folder / "summary.json").write_text(text)
    assert_refused(folder, "summary.json", r"not a JSON object \(as `occtool map` writes it\)")


@given(st.sampled_from(['{"features": [{"geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 1]]}}],'
                        ' "properties": {"frame": "map"}}',
                        '{"features": [1], "properties": {"frame": "map"}}',
                        '{"features": {}, "properties": {"frame": "map"}}', "[]"]))
def test_frontiers_that_are_not_points_are_refused(tmp_path_factory, text):
    folder = make_folder(tmp_path_factory.mktemp("json"))
    (folder / "frontiers.geojson").write_text(text)
    assert_refused(folder, "frontiers.geojson", r"(every frontier must be a GeoJSON Point feature|"
                                                r"not a GeoJSON FeatureCollection \(as `occtool map` writes it\))")


def test_a_huge_summary_is_refused_unread(tmp_path):
    folder = make_folder(tmp_path / "map")
    with open(folder / "summary.json", "r+b") as handle:
        handle.truncate(128 * 1024 * 1024 + 1)  # sparse: nothing is written to disk
    assert_refused(folder, "summary.json", r"134,217,729 bytes, over the 134,217,728 read from a map folder's JSON")
