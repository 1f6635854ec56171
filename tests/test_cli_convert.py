"""`occtool convert` and the shared log options, through the real command line."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.io import read_log


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


def test_csv_to_mcap_and_back(runner, tmp_path):
    source = tmp_path / "in.csv"
    source.write_text("x,y,z,m\n1,2,3,0.5\n-1,0.5,0.25,1\n")
    result = runner.invoke(cli, ["convert", str(source), "-o", str(tmp_path / "log.mcap")])
    assert result.exit_code == 0, result.output
    result = runner.invoke(cli, ["convert", str(tmp_path / "log.mcap"), "-o", str(tmp_path / "back.csv")])
    assert result.exit_code == 0, result.output
    a = read_log(source).single().features
    b = read_log(tmp_path / "back.csv").single().features
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.evidence, b.evidence)


def test_csv_to_standard_output(runner, tmp_path):
    source = tmp_path / "in.csv"
    source.write_text("x,y,z,m\n1,2,3,0.5\n")
    result = runner.invoke(cli, ["convert", str(source), "-o", "-"])
    assert result.exit_code == 0
    assert result.stdout.splitlines()[:2] == ["x,y,z,m", "1.0,2.0,3.0,0.5"]


def test_bad_input_is_one_line_error_and_leaves_no_output(runner, tmp_path):
    source = tmp_path / "in.csv"
    source.write_text("x,y,z,m\n1,2,3,0.5\n1,2,3,7\n")
    out = tmp_path / "out.mcap"
    result = runner.invoke(cli, ["convert", str(source), "-o", str(out)])
    assert result.exit_code == 1
    assert "in.csv, line 3" in result.output and "Traceback" not in result.output
    assert not out.exists()
    result = runner.invoke(cli, ["convert", str(source), "-o", str(out), "--skip-invalid"])
    assert result.exit_code == 0
    assert len(read_log(out).single().features) == 1


def test_log_options_reach_the_reader(runner, fixtures_dir, tmp_path):
    out = tmp_path / "out.csv"
    log_path = str(fixtures_dir / "logs" / "tiny.carmen.log")
    result = runner.invoke(
        cli, ["convert", log_path, "-o", str(out), "--group-by", "message", "--evidence", "0.4"]
    )
    assert result.exit_code == 0, result.output
    back = read_log(out)
    assert len(back.positions) == 3
    assert set(np.concatenate([p.features.evidence for p in back.positions])) == {0.4}
    result = runner.invoke(cli, ["convert", log_path, "-o", str(out), "--position-tolerance", "5,2"])
    assert result.exit_code == 0
    assert len(read_log(out).positions) == 1


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--position-tolerance", "0.2"], "METRES,RADIANS"),
        (["--evidence", "2"], "must lie in [0, 1]"),
        (["--group-by", "scan"], "Invalid value"),
    ],
)
def test_bad_options_are_usage_errors(runner, fixtures_dir, tmp_path, args, message):
    result = runner.invoke(
        cli, ["convert", str(fixtures_dir / "logs" / "tiny.xyz"), "-o", str(tmp_path / "o.csv"), *args]
    )
    assert result.exit_code == 2
    assert message in result.output


def test_unknown_topic_and_output_format_errors(runner, fixtures_dir, tmp_path):
    source = str(fixtures_dir / "logs" / "tiny.xyz")
    result = runner.invoke(cli, ["convert", source, "-o", str(tmp_path / "o.json")])
    assert result.exit_code == 2 and "cannot tell the output format" in result.output
    result = runner.invoke(cli, ["convert", source, "-o", str(tmp_path / "o.csv"), "--topic", "/scan"])
    assert result.exit_code == 1 and "MCAP logs only" in result.output
