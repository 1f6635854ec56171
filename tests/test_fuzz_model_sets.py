"""Hostile model-set indexes: poses and versions that are no pose or no version are one
line naming the index and the entry, never a traceback, a warning or a pose taken as data."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.modelset import read_model_set

GOOD_POSE = {"x": 1.0, "y": -2.0, "z": 0.0, "yaw": 0.5}


def write_set(folder: Path, pose: object = GOOD_POSE, *, version: object = 1, raw_pose: str | None = None) -> Path:
    """A two-entry index (model files that exist; their content is never reached) whose second pose is ``pose``."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("a.json", "b.json"):
        (folder / name).write_text("{}")
    index = {"format": "occtool-model-set", "format_version": version, "source": "t", "frame": "base_link",
             "poses_frame": "map", "complete": True, "failed": [],
             "models": [{"position": 0, "file": "a.json", "pose": GOOD_POSE},
                        {"position": 1, "file": "b.json", "pose": "@@pose@@"}]}
    text = json.dumps(index).replace('"@@pose@@"', raw_pose if raw_pose is not None else json.dumps(pose))
    (folder / "index.json").write_text(text)
    return folder


def test_a_good_index_is_read(tmp_path):
    folder, entries = read_model_set(write_set(tmp_path / "set"))
    assert folder == tmp_path / "set" and entries[1]["pose"] == GOOD_POSE


@pytest.mark.parametrize("raw, message", [
    ('{"x": NaN, "y": 0, "z": 0, "yaw": 0}', "pose x = nan"),
    ('{"x": 0, "y": Infinity, "z": 0, "yaw": 0}', "pose y = inf"),
    ('{"x": 0, "y": 0, "z": -Infinity, "yaw": 0}', "pose z = -inf"),
    ('{"x": 1e300, "y": 0, "z": 0, "yaw": 0}', "pose x = 1e+300"),
    ('{"x": 0, "y": 0, "z": 0, "yaw": 1e999}', "pose yaw = inf"),
    ('{"x": true, "y": 0, "z": 0, "yaw": 0}', "pose x is bool"),
    ('{"x": "1", "y": 0, "z": 0, "yaw": 0}', "pose x is str"),
    ('{"x": [1], "y": 0, "z": 0, "yaw": 0}', "pose x is list"),
    ("{}", "missing x, y, z, yaw"),
    ('{"x": 0, "y": 0, "yaw": 0}', "missing z"),
    ('{"x": 0, "y": 0, "z": 0, "yaw": 0, "roll": 0}', "unknown roll"),
    ("[0, 0, 0, 0]", "'pose' is not an object"),
    ("5", "'pose' is not an object"),
])
def test_a_bad_pose_is_one_line_naming_the_entry(tmp_path, raw, message):
    write_set(tmp_path / "set", raw_pose=raw)
    with pytest.raises(InputError) as caught:
        read_model_set(tmp_path / "set")
    text = str(caught.value)
    assert message in text and "model entry 2 (position 1)" in text and "index.json" in text
    assert "\n" not in text


@pytest.mark.parametrize("version", [99, 0, True, "1", None, 1.5, [1], 10**18])
def test_an_unknown_format_version_is_refused(tmp_path, version):
    write_set(tmp_path / "set", version=version)
    with pytest.raises(InputError, match="format_version .*this occtool reads 1") as caught:
        read_model_set(tmp_path / "set")
    assert "\n" not in str(caught.value)


def test_an_index_nested_deep_or_with_a_huge_integer_is_one_line(tmp_path):
    for n, raw in enumerate(("[" * 100_000 + "]" * 100_000, "9" * 5000)):
        write_set(tmp_path / f"s{n}", raw_pose=raw)
        with pytest.raises(InputError, match="not valid JSON") as caught:
            read_model_set(tmp_path / f"s{n}")
        assert "\n" not in str(caught.value)


@pytest.mark.parametrize("raw", ['{"x": NaN, "y": 0, "z": 0, "yaw": 0}', '{"x": 1e300, "y": 0, "z": 0, "yaw": 0}',
                                 "{}", '{"x": true, "y": 0, "z": 0, "yaw": 0}'])
def test_occtool_map_of_a_set_with_a_bad_pose_is_exit_1_and_writes_nothing(tmp_path, raw):
    write_set(tmp_path / "set", raw_pose=raw)
    result = CliRunner().invoke(cli, ["-q", "map", str(tmp_path / "set"), "-o", str(tmp_path / "out")])
    assert result.exit_code == 1, result.output
    assert len(result.output.strip().splitlines()) == 1 and "model entry 2" in result.output
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**19, 10**19), st.booleans(),
                    st.none(), st.text(max_size=3), st.lists(st.integers(), max_size=2))


@settings(max_examples=80, deadline=None)
@given(pose=st.dictionaries(st.sampled_from(["x", "y", "z", "yaw", "roll", "X"]), _VALUES, max_size=6))
def test_any_pose_is_read_checked_or_refused_in_one_line(tmp_path_factory, pose):
    folder = write_set(tmp_path_factory.mktemp("set"), raw_pose=json.dumps(pose))
    try:
        _, entries = read_model_set(folder)
    except InputError as exc:
        # An integer literal of over 20 digits is refused by the JSON reader, before any entry.
        assert "\n" not in str(exc) and ("model entry 2" in str(exc) or "too long to be a value" in str(exc))
    else:
        read = entries[1]["pose"]
        assert sorted(read) == ["x", "y", "yaw", "z"]
        assert all(not isinstance(v, bool) and math.isfinite(v) and abs(v) <= 1e8 for v in read.values())


@pytest.mark.parametrize("raw, message", [
    ("NaN", "stamp = nan"), ("1e300", "stamp = 1e+300"), ("-Infinity", "stamp = -inf"),
    ("true", "stamp is bool"), ('"12:00"', "stamp is str"), ("[1]", "stamp is list"),
])
def test_a_stamp_that_is_no_time_is_one_line_naming_the_entry(tmp_path, raw, message):
    folder = write_set(tmp_path / "set")
    index = folder / "index.json"
    index.write_text(index.read_text().replace('"file": "b.json"', f'"file": "b.json", "stamp": {raw}'))
    with pytest.raises(InputError) as caught:
        read_model_set(folder)
    assert message in str(caught.value) and "model entry 2 (position 1)" in str(caught.value)
    result = CliRunner().invoke(cli, ["-q", "map", str(folder), "-o", str(tmp_path / "out")])
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1, result.output
    assert not (tmp_path / "out").exists()


def test_stamps_from_any_origin_are_read(tmp_path):
    folder = write_set(tmp_path / "set")
    index = folder / "index.json"
    index.write_text(index.read_text().replace('"file": "b.json"', '"file": "b.json", "stamp": -12.5'))
    assert read_model_set(folder)[1][1]["stamp"] == -12.5
