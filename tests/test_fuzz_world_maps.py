"""Crafted ``world.occmap`` damage under a valid checksum: every header field and array of a
real map changed one at a time (offsets, counts, shapes, dtypes, the grid, huge integers,
deep JSON) is a one-line :class:`InputError` or a map that answers, never another
exception, a warning or a crash -- in :func:`load_map` and in ``occtool query``."""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import tracemalloc
import warnings
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.formats.occmap import MAGIC
from occtool.fuse import WorldMap, decode_map, load_map

ROOT = Path(__file__).resolve().parents[1]
INTEL = ROOT / "fixtures" / "maps" / "intel.occmap"
POINTS = np.array([[0.0, 0.0, 0.0], [1.0, -2.0, 0.0], [5.0, 5.0, 0.1], [-3.0, 2.0, 0.0]])


def split(data: bytes) -> tuple[dict[str, Any], list[list[Any]]]:
    """A map file's header and its ``[name, array]`` pairs (copies, free to change)."""
    (length,) = struct.unpack("<I", data[8:12])
    header = json.loads(data[12:12 + length])
    offset, arrays = 12 + length, []
    for name, dtype, shape in header["arrays"]:
        count = int(np.prod(shape))
        arrays.append([name, np.frombuffer(data, dtype, count, offset).reshape(shape).copy()])
        offset += count * np.dtype(dtype).itemsize
    return header, arrays


def join(header: dict[str, Any] | str, arrays: list[list[Any]], *, layout: bool = True) -> bytes:
    """The file of ``header`` (or its raw text) and ``arrays``, the checksum valid;
    ``layout``: the header's array list redone from the arrays."""
    if isinstance(header, dict):
        if layout:
            header = {**header, "arrays": [[n, a.dtype.name, list(a.shape)] for n, a in arrays]}
        header = _dumps(header)
    text = header.encode()
    body = MAGIC + struct.pack("<I", len(text)) + text + b"".join(np.ascontiguousarray(a).tobytes()
                                                                  for _, a in arrays)
    return body + struct.pack("<I", zlib.crc32(body))


def _dumps(header: dict[str, Any]) -> str:
    return json.dumps(header, sort_keys=True, separators=(",", ":"))  # as occtool writes it


def array(arrays: list[list[Any]], name: str) -> np.ndarray:
    return next(a for n, a in arrays if n == name)


def check(data: bytes, tmp_path: Path | None = None) -> str | None:
    """Decode ``data``: the one-line message of its InputError, or ``None`` if it is a map
    that answers (without a warning)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            world = decode_map(data, "crafted.occmap")
            assert isinstance(world, WorldMap)
            occupancy = world.predict(POINTS)
            assert np.isfinite(occupancy).all() and ((occupancy >= 0) & (occupancy <= 1)).all()
    except InputError as exc:
        message = str(exc)
        assert "\n" not in message and message.startswith("crafted.occmap: not a readable occtool map")
        return message
    return None


@pytest.fixture(scope="module")
def intel() -> bytes:
    return INTEL.read_bytes()


def _edit(name: str, change):
    def craft(header, arrays):
        change(array(arrays, name))
        return join(header, arrays)
    return craft


def _header(**fields):
    def craft(header, arrays):
        return join({**header, **fields}, arrays)
    return craft


def _setting(key, value):
    def craft(header, arrays):
        return join({**header, "settings": {**header["settings"], key: value}}, arrays)
    return craft


def _raw(old: str, new: str):
    """Replace text in the header as written (NaN, huge integers, deep JSON that json.dumps won't make)."""
    def craft(header, arrays):
        text = _dumps({**header, "arrays": [[n, a.dtype.name, list(a.shape)] for n, a in arrays]})
        assert old in text
        return join(text.replace(old, new, 1), arrays)
    return craft


def _shape(name: str, shape):
    def craft(header, arrays):
        text = _dumps({**header, "arrays": [[n, a.dtype.name, list(a.shape) if n != name else shape]
                                                for n, a in arrays]})
        return join(text, arrays)
    return craft


def _replace(name: str, value):
    def craft(header, arrays):
        return join(header, [[n, value if n == name else a] for n, a in arrays])
    return craft


def _drop(name: str):
    def craft(header, arrays):
        return join(header, [[n, a] for n, a in arrays if n != name])
    return craft


def _bump(a, at, by):
    a[at] = int(a[at]) + by


CRAFTED = {
    # The region's ragged offsets: shapely indexes with them unchecked (exit 139 before).
    "ring offset past the vertices": (_edit("region_offsets_0", lambda a: a.__setitem__(5, 60000)), "region_offsets_0"),
    "ring offset backwards": (_edit("region_offsets_0", lambda a: a.__setitem__(5, 1)), "region_offsets_0"),
    "last ring offset short": (_edit("region_offsets_0", lambda a: _bump(a, -1, -1)), "region_offsets_0"),
    "first ring offset not 0": (_edit("region_offsets_0", lambda a: a.__setitem__(0, 3)), "region_offsets_0"),
    "ring of three vertices": (_edit("region_offsets_0", lambda a: a.__setitem__(1, 3)), "region_offsets_0"),
    "polygon offset past the rings": (_edit("region_offsets_1", lambda a: a.__setitem__(-1, 5000)),
                                      "region_offsets_1"),
    "geometry offset past the polygons": (_edit("region_offsets_2", lambda a: a.__setitem__(-1, 40)),
                                          "region_offsets_2"),
    "two geometries": (_replace("region_offsets_2", np.array([0, 1, 1], dtype="<u2")), "region_offsets_2"),
    "offsets missing": (_drop("region_offsets_1"), "region_offsets_1"),
    "ring that does not close": (_replace("region_steps", None), "close"),
    "anchor count off": (_edit("region_steps", lambda a: a.__setitem__(2, [-128, -128])), "anchor"),
    # Segment arrays disagreeing.
    "a tile counting more": (_edit("tile_counts", lambda a: _bump(a, (3, 3), 7)), "tile counts"),
    "one middle fewer": (_replace("middles", None), "middles"),
    "trust longer": (_replace("trust", None), "trust"),
    "facing short": (_replace("facing", None), "facing"),
    "thickness missing": (_drop("thickness"), "thickness"),
    # Shapes and dtypes.
    "tile shape whose product overflows": (_shape("tile_counts", [2**40, 2**40]), "tile_counts"),
    "tile shape past 256": (_shape("tile_counts", [300, 3]), "tile_counts"),
    "negative size": (_shape("positions", [-1, 2]), "negative size"),
    "shape of a string": (_shape("positions", ["435", 2]), "positions"),
    "shape of booleans": (_shape("facing", [True]), "facing"),
    "three columns": (_shape("positions", [290, 3]), "positions"),
    "shape 5000 digits": (_raw('[435,2]', "[" + "4" * 5000 + ",2]"), "too long"),
    "float64 positions": (_replace("positions", None), "dtype"),
    "unknown array": (_replace("positions", None), "unknown"),
    "array listed twice": (_replace("positions", None), "twice"),
    # The header's grid and settings.
    "version true": (_header(version=True), "format version True"),
    "version string": (_header(version="4"), "format version '4'"),
    "version 5000 digits": (_raw('"version":4', '"version":' + "4" * 5000), "too long"),
    "unit 0": (_header(unit=0), "unit"),
    "unit negative": (_header(unit=-0.005), "unit"),
    "unit 1e308": (_header(unit=1e308), "grid"),
    "unit NaN": (_raw('"unit":0.005', '"unit":NaN'), "NaN"),
    "unit a string": (_header(unit="0.005"), "not a finite number"),
    "unit true": (_header(unit=True), "not a finite number"),
    "origin 1e308": (_header(origin=[1e308, 0.0]), "grid"),
    "origin one number": (_header(origin=[0.0]), "origin"),
    "origin 1e400": (_raw('"origin":[', '"origin":[1e400,'), "origin"),
    "origin long literal": (_raw('"origin":[', '"origin":[1' + "0" * 300 + ".0,"), "too long"),
    "half unit 1e300": (_header(half_unit=1e300), "half_unit"),
    "half unit missing": (lambda h, a: join({k: v for k, v in h.items() if k != "half_unit"}, a), "half_unit"),
    "band upside down": (_setting("band", [0.2, -0.25]), "band"),
    "band 1e300": (_setting("band", [-0.25, 1e300]), "band"),
    "band one number": (_setting("band", [0.2]), "band"),
    "width 1e300": (_setting("width", 1e300), "width"),
    "width negative": (_setting("width", -1.0), "width"),
    "width true": (_setting("width", True), "not a finite number"),
    "free level 2": (_setting("free_level", 2.0), "free_level"),
    "unknown setting": (_setting("depth", 1.0), "unknown setting 'depth'"),
    "settings a list": (_header(settings=[1, 2]), "settings"),
    "settings deep": (_raw('"settings":{', '"settings":{"x":' + "[" * 100_000 + "]" * 100_000 + ","),
                      "deep, more than 8"),
    "header a list": (lambda h, a: join("[1, 2]", a), "occmap format"),
    "arrays not a list": (lambda h, a: join({**h, "arrays": {"a": 1}}, a, layout=False), "arrays"),
}


def _prepare(name: str, header: dict[str, Any], arrays: list[list[Any]]) -> None:
    """The cases above that change arrays rather than fields."""
    if name == "one middle fewer":
        arrays[[n for n, _ in arrays].index("middles")][1] = array(arrays, "middles")[:-1]
    elif name == "trust longer":
        arrays[[n for n, _ in arrays].index("trust")][1] = np.append(array(arrays, "trust"), np.uint8(3))
    elif name == "facing short":
        arrays[[n for n, _ in arrays].index("facing")][1] = array(arrays, "facing")[:-1]
    elif name == "ring that does not close":
        # Move a ring's last vertex (a step, not an anchor) off its first.
        steps, ends = array(arrays, "region_steps"), array(arrays, "region_offsets_0")[1:].astype(int) - 1
        last = next(e for e in ends if steps[e, 0] != -128 and abs(int(steps[e, 0])) < 120)
        steps[last, 0] += 3
        arrays[[n for n, _ in arrays].index("region_steps")][1] = steps
    elif name == "float64 positions":
        arrays[[n for n, _ in arrays].index("positions")][1] = array(arrays, "positions").astype(np.float64)
    elif name == "unknown array":
        arrays.append(["colours", np.zeros(3, dtype=np.uint8)])
    elif name == "array listed twice":
        arrays.append(["positions", array(arrays, "positions")])


@pytest.mark.parametrize("case", sorted(CRAFTED))
def test_a_crafted_file_is_one_line_naming_what_is_wrong(intel, case):
    craft, expected = CRAFTED[case]
    header, arrays = split(intel)
    _prepare(case, header, arrays)
    if case in ("one middle fewer", "trust longer", "facing short", "float64 positions", "unknown array",
                "array listed twice", "ring that does not close"):
        craft = _identity
    message = check(craft(header, arrays))
    assert message is not None and expected in message, message


def _identity(header, arrays):
    return join(header, arrays)


def test_the_untouched_map_and_its_re_encoding_load(intel):
    header, arrays = split(intel)
    assert join(header, arrays) == intel and check(intel) is None


@pytest.mark.parametrize("case", ["ring offset past the vertices", "tile shape whose product overflows",
                                  "settings deep", "origin 1e308", "version 5000 digits"])
def test_occtool_query_of_a_crafted_map_is_exit_1_one_line_and_no_output(intel, tmp_path, case):
    craft, expected = CRAFTED[case]
    header, arrays = split(intel)
    (tmp_path / "m.occmap").write_bytes(craft(header, arrays))
    (tmp_path / "p.csv").write_text("x,y,z\n0,0,0\n")
    result = CliRunner().invoke(cli, ["-q", "query", str(tmp_path / "m.occmap"), str(tmp_path / "p.csv"), "-o",
                                      str(tmp_path / "out.csv")])
    assert result.exit_code == 1 and expected in result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "out.csv").exists()
    with pytest.raises(InputError, match="m.occmap: not a readable occtool map"):
        load_map(tmp_path / "m.occmap")


def test_a_region_offset_out_of_range_exits_1_not_139(intel, tmp_path):
    """The file that crashed the interpreter (a segfault in shapely's ragged-array code)."""
    header, arrays = split(intel)
    (tmp_path / "m.occmap").write_bytes(CRAFTED["ring offset past the vertices"][0](header, arrays))
    (tmp_path / "p.csv").write_text("x,y,z\n0,0,0\n")
    done = subprocess.run([sys.executable, "-m", "occtool", "query", str(tmp_path / "m.occmap"),
                           str(tmp_path / "p.csv"), "-o", str(tmp_path / "out.csv")], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert done.returncode == 1, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "region_offsets_0" in done.stderr
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.slow
def test_files_that_are_no_regular_file_or_too_large_are_refused_before_reading(tmp_path, monkeypatch):
    (tmp_path / "zero.occmap").symlink_to("/dev/zero")
    os.mkfifo(tmp_path / "fifo.occmap")
    for name in ("zero.occmap", "fifo.occmap"):
        with pytest.raises(InputError, match="not a regular file"):
            load_map(tmp_path / name)
    big = tmp_path / "big.occmap"
    with open(big, "wb") as handle:  # 1.5 GB, sparse: refused from its size, nothing read
        handle.write(MAGIC)
        handle.truncate(1_500_000_000)
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match="1500000000 bytes, more than the 32 MB"):
            load_map(big)
        assert tracemalloc.get_traced_memory()[1] < 10_000_000
    finally:
        tracemalloc.stop()
    import occtool.limits

    # Under the cap, a foreign file is refused from its first 12 bytes.
    monkeypatch.setattr(occtool.limits, "MAX_MAP_BYTES", 2_000_000_000)
    tracemalloc.start()
    try:
        with open(big, "r+b") as handle:
            handle.write(b"PK\x03\x04")
        with pytest.raises(InputError, match="no occmap signature"):
            load_map(big)
    finally:
        tracemalloc.stop()
    with open(big, "r+b") as handle:  # the signature, a header said to be longer than MAX_HEADER
        handle.write(MAGIC + struct.pack("<I", 2**31))
    with pytest.raises(InputError, match="header length out of range"):
        load_map(big)


def test_a_map_message_names_no_command_line_option(intel, tmp_path):
    (tmp_path / "m.occmap").write_bytes(intel[:-1])
    with pytest.raises(InputError) as caught:
        load_map(tmp_path / "m.occmap")
    assert "--" not in str(caught.value)


_NAMES = ["tile_counts", "middles", "directions", "half_lengths", "thickness", "trust", "facing", "positions",
          "region_steps", "region_anchors", "region_offsets_0", "region_offsets_1", "region_offsets_2"]
_JSON = st.recursive(st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.floats() | st.text(max_size=4),
                     lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner,
                                                                                  max_size=3), max_leaves=8)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_one_crafted_change_is_an_error_or_a_map(intel, data):
    """One element of one array set to any value of its dtype, or one header field (or one
    setting, or one array's shape) replaced by any JSON value: the checksum redone."""
    header, arrays = split(intel)
    kind = data.draw(st.sampled_from(["element", "field", "setting", "shape"]))
    if kind == "element":
        name = data.draw(st.sampled_from(_NAMES))
        target = array(arrays, name).reshape(-1)
        info = np.iinfo(target.dtype)
        at = data.draw(st.integers(0, target.size - 1))
        target[at] = data.draw(st.integers(int(info.min), int(info.max)) | st.sampled_from(
            [int(target[max(at - 1, 0)]), int(target[min(at + 1, target.size - 1)]), 0, int(info.max)]))
        crafted = join(header, arrays)
    elif kind == "field":
        field = data.draw(st.sampled_from(["version", "unit", "half_unit", "origin", "settings", "format"]))
        crafted = join({**header, field: data.draw(_JSON)}, arrays)
    elif kind == "setting":
        key = data.draw(st.sampled_from(sorted(header["settings"]) + ["other"]))
        crafted = join({**header, "settings": {**header["settings"], key: data.draw(_JSON)}}, arrays)
    else:
        position = data.draw(st.integers(0, len(arrays) - 1))
        listed = [[n, a.dtype.name, list(a.shape)] for n, a in arrays]
        listed[position][2] = data.draw(st.lists(st.integers(-2, 2**64) | st.sampled_from([0, 1, 2, 435, 5202]),
                                                 max_size=3))
        crafted = join({**header, "arrays": listed}, arrays, layout=False)
    check(crafted)
