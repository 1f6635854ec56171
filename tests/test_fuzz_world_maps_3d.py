"""Damage to a 3D ``world.occmap`` (version 6): flipped and cut bytes, and header fields and
array bytes changed under a valid checksum, are a one-line :class:`InputError` or a map that
answers in [0, 1], never another exception -- in :func:`load_map` and in ``occtool query``."""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.formats.occmap import MAGIC
from occtool.fuse import build_world_map_3d, load_map

QUERY = np.array([[0.5, 0.5, 0.5], [2.0, 1.0, 0.2], [9.0, 9.0, 9.0]])


def _room() -> bytes:
    """A small 3D map: a floor and two walls seen from one sensor."""
    rng = np.random.default_rng(1)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    origin = np.array([1.0, 1.0, 1.0])
    with np.errstate(divide="ignore"):
        t = np.min(np.where(np.column_stack([-origin[2] / d[:, 2], (3.0 - origin[0]) / d[:, 0],
                                             (3.0 - origin[1]) / d[:, 1]]) > 0,
                            np.column_stack([-origin[2] / d[:, 2], (3.0 - origin[0]) / d[:, 0],
                                             (3.0 - origin[1]) / d[:, 1]]), np.inf), axis=1)
    hit = t < 5.0
    ends = origin + np.where(hit, t, 5.0)[:, None] * d
    world = build_world_map_3d(origin, ends, hit, resolution=0.25)
    world.to_map = np.eye(4)
    return world.to_bytes()


DATA = _room()
(_LENGTH,) = struct.unpack("<I", DATA[8:12])
HEADER = json.loads(DATA[12:12 + _LENGTH])
RAW = zlib.decompress(DATA[12 + _LENGTH:-4])


def _file(header: dict[str, Any], raw: bytes) -> bytes:
    packed = zlib.compress(raw)
    text = json.dumps({**header, "packed": len(packed)} if "packed" in header else header).encode()
    body = MAGIC + struct.pack("<I", len(text)) + text + packed
    return body + struct.pack("<I", zlib.crc32(body))


def _answers_or_one_line(path: Path) -> None:
    try:
        world = load_map(path)
    except InputError as exc:
        assert "\n" not in str(exc) and str(path) in str(exc)
        return
    with np.errstate(over="raise", invalid="raise"):  # a map that loads answers without overflow
        p = world.predict(QUERY)
    assert p.shape == (3,) and np.all((p >= 0.0) & (p <= 1.0))


def test_the_intact_file_loads(tmp_path: Path) -> None:
    (tmp_path / "m.occmap").write_bytes(DATA)
    assert load_map(tmp_path / "m.occmap").patch_count > 0


@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(at=st.integers(0, len(DATA) - 1), value=st.integers(0, 255), cut=st.booleans())
def test_flipped_or_cut_bytes_are_one_line(tmp_path: Path, at: int, value: int, cut: bool) -> None:
    data = DATA[:at] if cut else DATA[:at] + bytes([value]) + DATA[at + 1:]
    if data == DATA:
        return
    (tmp_path / "m.occmap").write_bytes(data)
    with pytest.raises(InputError) as caught:
        load_map(tmp_path / "m.occmap")
    assert "\n" not in str(caught.value)


VALUES = st.one_of(st.none(), st.booleans(), st.integers(-2**40, 2**40), st.floats(allow_nan=True),
                   st.text(max_size=5), st.lists(st.integers(-5, 5), max_size=13))


@settings(max_examples=150, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(sorted(HEADER)), value=VALUES)
@example(key="resolution", value=4.740375954054589e+153)  # finite, but its queries' reach overflowed
@example(key="edge_falloff", value=5e-324)  # positive, but the ridges' slopes overflowed
def test_header_fields_changed_under_a_valid_checksum(tmp_path: Path, key: str, value: Any) -> None:
    (tmp_path / "m.occmap").write_bytes(_file({**HEADER, key: value}, RAW))
    _answers_or_one_line(tmp_path / "m.occmap")


@settings(max_examples=100, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(changes=st.lists(st.tuples(st.integers(0, len(RAW) - 1), st.integers(0, 255)), min_size=1, max_size=8),
       extra=st.integers(-3, 3))
def test_array_bytes_changed_under_a_valid_checksum(tmp_path: Path, changes: list[tuple[int, int]],
                                                    extra: int) -> None:
    raw = bytearray(RAW)
    for at, value in changes:
        raw[at] = value
    raw = raw[:len(raw) + extra] if extra < 0 else raw + bytes(extra)
    (tmp_path / "m.occmap").write_bytes(_file(HEADER, bytes(raw)))
    _answers_or_one_line(tmp_path / "m.occmap")


def test_the_command_line_reports_a_damaged_3d_map_in_one_line(tmp_path: Path) -> None:
    (tmp_path / "m.occmap").write_bytes(DATA[:-9])
    (tmp_path / "p.csv").write_text("x,y,z\n0,0,0\n")
    for args in (["query", str(tmp_path / "m.occmap"), str(tmp_path / "p.csv"), "-o", str(tmp_path / "o.csv")],
                 ["info", str(tmp_path / "m.occmap")]):
        result = CliRunner().invoke(cli, ["-q", *args])
        assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1, result.output
        assert "m.occmap" in result.output
    assert not (tmp_path / "o.csv").exists()
