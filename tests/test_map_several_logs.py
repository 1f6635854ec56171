"""Several logs, one map (issue 36): `occtool map A.log B.log` maps the logs' positions one
after the other, their poses in one frame, as the one log they make together."""

from __future__ import annotations

import gzip
import hashlib
from pathlib import Path

import pytest
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.io import iter_positions, read_log

ROOT = Path(__file__).resolve().parents[1]
INTEL = ROOT.parent / "shared" / "data" / "intel_lab" / "intel-corrected.log.gz"
ARGS = ["--sensor-height", "0.3", "--body-height", "0.5", "--no-return-range", "5", "--no-mcap"]


@pytest.fixture(scope="module")
def halves(tmp_path_factory) -> tuple[Path, Path, Path]:
    if not INTEL.is_file():
        pytest.skip(f"{INTEL} is not here (../shared beside the checkout)")
    with gzip.open(INTEL, "rt") as stream:
        lines = [next(stream) for _ in range(1600)]
    folder = tmp_path_factory.mktemp("logs")
    (folder / "a.log").write_text("".join(lines[:800]))
    (folder / "b.log").write_text("".join(lines[800:]))
    (folder / "ab.log").write_text("".join(lines))
    return folder / "a.log", folder / "b.log", folder / "ab.log"


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.slow
def test_two_logs_map_as_the_one_log_they_make(halves, tmp_path: Path) -> None:
    a, b, ab = halves
    both = read_log([a, b], no_return_range=5)
    assert len(both.positions) == len(read_log(a).positions) + len(read_log(b).positions)
    assert [p.index for p in both.positions] == list(range(len(both.positions)))
    assert all(note.startswith(("a.log: ", "b.log: ")) for note in both.notes)
    for sources, out in (([a, b], tmp_path / "two"), ([ab], tmp_path / "one")):
        result = CliRunner().invoke(cli, ["-q", "map", *map(str, sources), "-o", str(out), *ARGS])
        assert result.exit_code == 0, result.output
    for name in ("world.occmap", "map.pgm", "navigation.geojson"):
        assert _digest(tmp_path / "two" / name) == _digest(tmp_path / "one" / name), name


def test_a_log_and_a_point_cloud_together_are_refused(halves, tmp_path: Path) -> None:
    cloud = tmp_path / "scan.xyz"
    cloud.write_text("1 0 0\n0 1 0\n")
    with pytest.raises(InputError, match="point cloud .* range log"):
        read_log([halves[0], cloud])
    with pytest.raises(InputError, match="read whole"):
        iter_positions([halves[0], halves[1]])
