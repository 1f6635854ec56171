"""``occtool compare-grid`` end to end on small logs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from occtool.cli.main import cli


@pytest.fixture(scope="module")
def small_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The office fixture cut to its first 2000 features (the test stays fast)."""
    source = Path(__file__).resolve().parent.parent / "fixtures" / "office" / "features.csv"
    lines = source.read_text(encoding="utf-8").splitlines()
    header = [i for i, line in enumerate(lines) if not line.startswith("#")][0]
    path = tmp_path_factory.mktemp("log") / "features.csv"
    path.write_text("\n".join(lines[: header + 1 + 2000]) + "\n", encoding="utf-8")
    return path


def _run(*args: str) -> object:
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


def test_table_and_json_report(small_log: Path, fixtures_dir: Path, tmp_path: Path) -> None:
    pytest.importorskip("pyoctomap")
    report_path = tmp_path / "report.json"
    result = _run(
        "compare-grid", str(small_log), "--resolution", "0.1", "--pieces", "8", "--octomap",
        "--truth", str(fixtures_dir / "office" / "truth.json"), "--json", str(report_path),
    )
    assert result.exit_code == 0, result.output
    for label in ("samples", "memory ratio", "IoU with truth", "violation", "ROC AUC", "octomap"):
        assert label in result.output
    report = json.loads(report_path.read_text())
    assert report["features"] == 2000
    assert set(report["models"]) == {"parametric", "grid", "octomap"}
    assert set(report["truth"]) == {"parametric", "grid", "octomap"}
    assert set(report["ratios"]) == {"grid", "octomap"}
    assert report["settings"]["pieces"] == 8
    assert report["settings"]["resolution"] == 0.1
    assert report["models"]["parametric"]["memory_bytes"] < report["models"]["grid"]["memory_bytes"]


def test_json_to_stdout_and_shared_options(small_log: Path) -> None:
    result = _run(
        "compare-grid", str(small_log), "--resolution", "0.2", "-L", "6", "--threshold", "0.55",
        "--max-range", "1.0", "--robot-radius", "0.2", "--angles", "90", "--holdout", "0.2", "--json", "-",
    )
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["features_held_out"] == 400
    assert report["settings"]["threshold"] == 0.55
    assert report["settings"]["max_range"] == 1.0
    assert report["settings"]["robot_radius"] == 0.2
    assert report["settings"]["n_angles"] == 90
    assert "truth" not in report


def test_plot_is_written(small_log: Path, tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    image = tmp_path / "compare.png"
    result = _run("compare-grid", str(small_log), "--resolution", "0.2", "-L", "6", "--plot", str(image))
    assert result.exit_code == 0, result.output
    assert image.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_missing_octomap_extra_is_a_one_line_error(small_log: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import occtool.grid

    monkeypatch.setattr(occtool.grid, "octomap_available", lambda: False)
    result = CliRunner().invoke(cli, ["compare-grid", str(small_log), "--octomap"])
    assert result.exit_code == 1
    assert "pip install 'occtool[octomap]'" in result.output
    assert "Traceback" not in result.output


def test_bad_input_is_a_clear_error(tmp_path: Path, small_log: Path) -> None:
    broken = tmp_path / "broken.csv"
    broken.write_text("x,y,z,m\n1,2,3,0.5\n1,2,oops,0.5\n", encoding="utf-8")
    result = CliRunner().invoke(cli, ["compare-grid", str(broken)])
    assert result.exit_code == 1
    assert result.output.startswith("Error:") and "broken.csv" in result.output
    result = CliRunner().invoke(cli, ["compare-grid", str(small_log), "--holdout", "0.9"])
    assert result.exit_code == 2 and "holdout" in result.output
    result = CliRunner().invoke(cli, ["compare-grid", str(small_log), "--resolution", "0"])
    assert result.exit_code == 2
    # A failed run leaves no partial report behind.
    target = tmp_path / "report.json"
    result = CliRunner().invoke(cli, ["compare-grid", str(broken), "--json", str(target)])
    assert result.exit_code == 1 and not target.exists()


def test_config_file_sets_defaults_and_the_command_line_wins(small_log: Path, tmp_path: Path) -> None:
    config = tmp_path / "compare.toml"
    config.write_text("resolution = 0.2\n[fit]\npieces = 6\n[extract]\nthreshold = 0.65\n", encoding="utf-8")
    result = _run("compare-grid", str(small_log), "--config", str(config), "--threshold", "0.7", "--json", "-")
    assert result.exit_code == 0, result.output
    settings = json.loads(result.stdout)["settings"]
    assert settings["resolution"] == 0.2
    assert settings["pieces"] == 6
    assert settings["threshold"] == 0.7


@pytest.mark.slow
def test_the_octomap_scan(shared_data: Path, tmp_path: Path) -> None:
    pytest.importorskip("pyoctomap")
    scan = shared_data / "octomap_scan" / "scan.dat.bz2"
    if not scan.exists():
        pytest.skip("the OctoMap scan is not in ../shared/data")
    report_path = tmp_path / "scan.json"
    result = _run(
        "compare-grid", str(scan), "--resolution", "0.2", "-L", "8", "--octomap", "--octomap-scans", "1",
        "--json", str(report_path),
    )
    assert result.exit_code == 0, result.output
    report = json.loads(report_path.read_text())
    assert report["features"] == 88206
    # A scan over tens of metres: the grids take megabytes, the model a few hundred bytes.
    assert report["models"]["grid"]["memory_bytes"] > 1e6
    assert report["models"]["parametric"]["memory_bytes"] < 2e3
    assert report["ratios"]["octomap"]["memory"] > 100


def test_no_overwrite_refuses_an_existing_report(tmp_path, fixtures_dir):
    from click.testing import CliRunner

    from occtool.cli.main import cli

    report = tmp_path / "report.json"
    report.write_text("{}")
    result = CliRunner().invoke(cli, ["compare-grid", str(fixtures_dir / "office" / "features.csv"),
                                      "--resolution", "0.2", "--json", str(report), "--no-overwrite"])
    assert result.exit_code == 1 and "exists already" in result.output
    assert report.read_text() == "{}"


def test_unknown_option_round_trips_in_the_json(small_log: Path, tmp_path: Path) -> None:
    pytest.importorskip("pyoctomap")
    common = ("compare-grid", str(small_log), "--resolution", "0.2", "-L", "6", "--angles", "90", "--octomap")
    default = json.loads(_run(*common, "--json", "-").stdout)
    assert default["settings"]["unknown"] == "free"
    result = _run(*common, "--unknown", "occupied", "--json", "-")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["settings"]["unknown"] == "occupied"
    # The body band (robot defaults: 0.05 to 1 m above the floor, sensor at 1 m).
    assert report["settings"]["observed_band"] == pytest.approx([-0.95, 0.0])
    assert "occupied" in report["unknown_space"]
    # Only the grids' reading changes.
    assert report["polygons"]["parametric"] == default["polygons"]["parametric"]
    # The table says how unseen space was read; a config file sets it too.
    config = tmp_path / "compare.toml"
    config.write_text('unknown = "occupied"\n', encoding="utf-8")
    table = _run(*common, "--config", str(config))
    assert table.exit_code == 0, table.output
    assert "unobserved space as occupied" in " ".join(table.output.split())


def test_bad_unknown_value_is_a_clear_error(small_log: Path, tmp_path: Path) -> None:
    target = tmp_path / "report.json"
    result = CliRunner().invoke(cli, ["compare-grid", str(small_log), "--unknown", "maybe", "--json", str(target)])
    assert result.exit_code == 2
    output = " ".join(result.output.split())
    assert "Error: Invalid value for '--unknown'" in output and "'free', 'occupied'" in output
    assert "Traceback" not in output and not target.exists()
