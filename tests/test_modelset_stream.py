"""Model sets read their logs streamed: the same models and index as from the log held whole,
and a bad line anywhere leaves no output."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

import occtool.io.csv_stream as csv_module
from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.fit import OccupancyRegressor
from occtool.io import read_log
from occtool.modelset import fit_model_set

ESTIMATOR = OccupancyRegressor(pieces=6, seed=1)


def carmen_log(path: Path, scans: int = 9, bad_line: int | None = None) -> Path:
    """A CARMEN log of a robot driving down a corridor, one FLASER line per 0.4 m."""
    lines = ["PARAM robot_name test nohost 0"]
    for k in range(scans):
        ranges = " ".join(f"{1.0 + 0.01 * ((b * 7 + k) % 13):.3f}" for b in range(60))
        lines.append(f"FLASER 60 {ranges} {0.4 * k:.2f} 0.0 {0.05 * k:.2f} 0 0 0 {k}.5 nohost {k}.5")
        lines.append(f"ODOM {0.4 * k:.2f} 0 0 0 0 0 {k}.6 nohost {k}.6")
    if bad_line is not None:
        lines.insert(bad_line, "FLASER 60 1.0 oops")
    path.write_text("\n".join(lines) + "\n")
    return path


def set_contents(folder: Path) -> dict[str, object]:
    """Every model without its run object (time, host), and the index as written."""
    out: dict[str, object] = {"index.json": (folder / "index.json").read_text()}
    for model in sorted(folder.glob("model_*.json")):
        data = json.loads(model.read_text())
        data.pop("run")
        out[model.name] = data
    return out


@pytest.mark.parametrize("positions", [None, [5, 0, 5]])
def test_a_streamed_log_gives_the_models_and_index_of_the_log_held_whole(tmp_path, positions):
    path = carmen_log(tmp_path / "corridor.log")
    streamed, held = tmp_path / "streamed", tmp_path / "held"
    options = {"no_return_range": 3.0}
    first = fit_model_set(path, streamed, estimator=ESTIMATOR, read_options=options, jobs=1, positions=positions,
                          planar_defaults=True)
    second = fit_model_set(read_log(path, **options), held, estimator=ESTIMATOR, jobs=1, positions=positions,
                           planar_defaults=True)
    assert first.positions == second.positions == (3 if positions else 9) and not first.failures
    assert set_contents(streamed) == set_contents(held)


def test_a_csv_log_streamed_in_small_chunks_gives_the_same_models(tmp_path, monkeypatch):
    path = tmp_path / "scans.csv"
    rows = ["x,y,z,m,pose_x,pose_y,pose_yaw"]
    for k in range(4):
        rows += [f"{1.0 + 0.02 * b},{(b % 5) * 0.2 - 0.4},{(b % 3) * 0.2 - 0.3},0.8,{0.5 * k},0,0" for b in range(40)]
    path.write_text("\n".join(rows) + "\n")
    held = fit_model_set(read_log(path), tmp_path / "held", estimator=ESTIMATOR, jobs=1)
    monkeypatch.setattr(csv_module, "CHUNK_BYTES", 100)
    streamed = fit_model_set(path, tmp_path / "streamed", estimator=ESTIMATOR, jobs=1)
    assert streamed.done == held.done == 4
    assert set_contents(tmp_path / "streamed") == set_contents(tmp_path / "held")


def test_a_bad_line_near_the_end_of_a_log_leaves_no_partial_output(tmp_path):
    path = carmen_log(tmp_path / "late.log", bad_line=17)
    with pytest.raises(InputError, match=r"late.log, line 18: FLASER"):
        fit_model_set(path, tmp_path / "models", estimator=ESTIMATOR, jobs=1)
    assert not (tmp_path / "models").exists()
    result = CliRunner().invoke(cli, ["fit", str(path), "-o", str(tmp_path / "cli") + "/", "-j", "1"])
    assert result.exit_code == 1
    assert len(result.output.strip().splitlines()) == 1 and "line 18" in result.output
    assert not (tmp_path / "cli").exists() or not any((tmp_path / "cli").iterdir())


def test_a_position_out_of_range_is_refused_before_any_model(tmp_path):
    path = carmen_log(tmp_path / "corridor.log")
    with pytest.raises(InputError, match=r"position 9 is out of range \(the log has 9\)"):
        fit_model_set(path, tmp_path / "models", estimator=ESTIMATOR, jobs=1, positions=[0, 9])
    assert not (tmp_path / "models").exists()
