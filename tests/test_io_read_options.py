"""The readers' options are declared once (ReadOptions) and the formats registered once."""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path

import pytest

from occtool.errors import InputError
from occtool.io import FORMATS, ReadOptions, iter_positions, read_log
from occtool.io.read_options import OPTION_NAMES

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures"


def _keywords(function) -> dict[str, object]:
    return {name: p.default for name, p in inspect.signature(function).parameters.items()
            if p.kind is inspect.Parameter.KEYWORD_ONLY}


def test_every_reader_keyword_that_is_an_option_has_the_options_default() -> None:
    from occtool.io.carmen import CarmenScans, read_carmen
    from occtool.io.csv import read_csv
    from occtool.io.csv_stream import iter_csv
    from occtool.io.depth_folders import DepthFolderScans, read_depth_folder
    from occtool.io.mcap import read_mcap
    from occtool.io.mcap._reader import McapScans
    from occtool.io.pointcloud import read_pointcloud
    from occtool.io.urg import read_urg

    defaults = {f.name: f.default for f in dataclasses.fields(ReadOptions)}
    assert tuple(defaults) == OPTION_NAMES
    for reader in (read_csv, iter_csv, read_mcap, McapScans, read_carmen, CarmenScans, read_pointcloud, read_urg,
                   read_depth_folder, DepthFolderScans):
        shared = {k: v for k, v in _keywords(reader).items()
                  if k in defaults}
        assert shared == defaults, reader.__name__  # every option, by name, with the field's default


def test_one_registry_reads_and_streams_every_format() -> None:
    from occtool.io._formats import READERS, STREAMS

    assert set(READERS) == set(FORMATS)
    assert set(STREAMS) == {"csv", "carmen", "mcap", "rosbag", "tum", "3dmatch", "scans"}


def test_read_options_check_every_field_with_the_readers_messages() -> None:
    cases = {
        "group_by": ("scan", "group-by must be one of position, message, got 'scan'"),
        "evidence": (1.5, "constant evidence must lie in [0, 1], got 1.5"),
        "format": ("laz", "unknown format 'laz': expected one of csv, mcap"),
        "no_return_range": (0, "no-return range must be a finite number of metres > 0, got 0"),
        "position_tolerance": ((1.0,), "position tolerance must be two numbers >= 0"),
        "depth_features": (0, "depth features must be a whole number in [1, "),
        "depth_noise": (2.0, "depth noise must be a number in [0, 1]"),
        "depth_max_range": (0.05, "depth max range must lie in (0.1, "),
    }
    for name, (value, message) in cases.items():
        with pytest.raises(InputError) as caught:
            ReadOptions(**{name: value})
        assert str(caught.value).startswith(message), (name, str(caught.value))


def test_read_options_hold_the_checked_values() -> None:
    options = ReadOptions(format="DAT", no_return_range=5, position_tolerance=[1, 2], depth_max_range=3)
    assert options.format == "xyz"
    assert options.no_return_range == 5.0 and isinstance(options.no_return_range, float)
    assert options.position_tolerance == (1.0, 2.0)
    assert options.depth_max_range == 3.0
    assert options.constant_evidence == 0.9 and ReadOptions(evidence=0.4).constant_evidence == 0.4
    assert options.replace(group_by="message").group_by == "message"
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.group_by = "message"  # type: ignore[misc]


def test_read_log_takes_options_keywords_or_both(tmp_path: Path) -> None:
    path = FIXTURES / "office" / "features.csv"
    by_keywords = read_log(path, group_by="message")
    by_options = read_log(path, ReadOptions(group_by="message"))
    both = read_log(path, ReadOptions(group_by="position"), group_by="message")
    assert len(by_keywords.positions) == len(by_options.positions) == len(both.positions)
    streamed = list(iter_positions(path, ReadOptions(group_by="message")))
    assert len(streamed) == len(by_options.positions)
    with pytest.raises(TypeError, match="unexpected keyword argument 'topic'"):
        read_log(path, topic=["/scan"])
    with pytest.raises(InputError, match="topics= applies to MCAP logs only"):
        read_log(path, ReadOptions(topics=["/scan"]))
    with pytest.raises(FileNotFoundError):
        read_log(tmp_path / "absent.csv", ReadOptions(group_by="message"))


def test_a_new_option_reaches_a_reader_through_the_options_alone(monkeypatch) -> None:
    # Every format's reader is handed the ReadOptions whole: a field its reader reads needs
    # no line in the registry, read_log or the stream.
    import occtool.io.csv as csv_module

    seen = []
    original = csv_module.read_csv

    def spy(path, options=None, **keywords):
        seen.append(options)
        return original(path, options, **keywords)

    monkeypatch.setattr(csv_module, "read_csv", spy)
    options = ReadOptions(skip_invalid=True, group_by="message")
    read_log(FIXTURES / "office" / "features.csv", options)
    assert seen == [options]


def test_the_constant_evidence_has_one_home() -> None:
    import occtool.io
    import occtool.io.mcap
    from occtool.io import read_options

    assert occtool.io.DEFAULT_CONSTANT_EVIDENCE is read_options.DEFAULT_CONSTANT_EVIDENCE
    assert occtool.io.mcap.DEFAULT_CONSTANT_EVIDENCE is read_options.DEFAULT_CONSTANT_EVIDENCE
    for module in ("occtool/io/pointcloud.py", "occtool/io/mcap/_decode.py", "occtool/io/__init__.py"):
        text = (Path(__file__).resolve().parent.parent / module).read_text()
        assert "DEFAULT_CONSTANT_EVIDENCE = " not in text, module


def test_depth_imports_nothing_from_depth_folders() -> None:
    text = (Path(__file__).resolve().parent.parent / "occtool/io/depth.py").read_text()
    assert "depth_folders import" not in text
    from occtool.io.depth import estimate_floor
    from occtool.io.depth_folders import estimate_floor as re_exported

    assert estimate_floor is re_exported
