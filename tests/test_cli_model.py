"""`occtool fit`, `invert` and `info` end to end."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.features import Features
from occtool.formats.model import load_inverse, load_model


@pytest.fixture(scope="module")
def log_csv(tmp_path_factory) -> str:
    rng = np.random.default_rng(0)
    n = 1500
    a = rng.uniform(-np.pi, np.pi, n)
    z = rng.uniform(-0.9, 0.5, n)
    f = Features.from_xyz(1.6 * np.cos(a), 1.6 * np.sin(a), z, 0.9)
    path = tmp_path_factory.mktemp("log") / "features.csv"
    rows = "\n".join(
        f"{float(x)!r},{float(y)!r},{float(zz)!r},{float(m)!r}" for (x, y, zz), m in zip(f.points, f.evidence)
    )
    path.write_text("x,y,z,m\n" + rows + "\n")
    return str(path)


def run(*args: str):
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


def test_fit_invert_info(log_csv, tmp_path):
    model_path = tmp_path / "model.json"
    result = run("fit", log_csv, "-o", str(model_path), "--pieces", "8", "--seed", "2")
    assert result.exit_code == 0, result.output
    model = load_model(model_path)
    assert model.tree_.n_pieces == 8 and model.seed == 2 and model.n_features_ == 1500
    data = json.loads(model_path.read_text())
    assert {"seconds", "date", "occtool_version", "host"} <= set(data["run"])

    inverse_path = tmp_path / "inverse.json"
    result = run("invert", str(model_path), "-o", str(inverse_path))
    assert result.exit_code == 0, result.output
    assert load_inverse(inverse_path) == model.invert()

    result = run("info", str(model_path))
    assert result.exit_code == 0 and "pieces" in result.output and "RMSE" in result.output
    result = run("info", str(inverse_path))
    assert result.exit_code == 0 and "F^-1" in result.output


def test_sensor_and_fit_options(log_csv, tmp_path):
    config = tmp_path / "fit.toml"
    config.write_text('[sensor]\ndepth-error = 0.05\nnear-positions = "0.7,0.85"\n[fit]\npieces = 4\n')
    model_path = tmp_path / "model.json"
    result = run("fit", log_csv, "-o", str(model_path), "--config", str(config), "--basis", "linear",
                 "--a-max", "5", "--sensor-height", "1.2")
    assert result.exit_code == 0, result.output
    model = load_model(model_path)
    assert model.sensor_.depth_error == 0.05 and model.sensor_.near_positions == (0.7, 0.85)
    assert model.tree_.n_pieces == 4 and model.basis == "linear" and model.a_max == 5.0
    assert model.robot_.sensor_height == 1.2


def test_bad_input_is_one_line_error(tmp_path, log_csv):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "occtool-model", "format_version": 99}')
    result = CliRunner().invoke(cli, ["invert", str(bad), "-o", str(tmp_path / "x.json")])
    assert result.exit_code == 1 and "newer" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "x.json").exists()
    result = CliRunner().invoke(cli, ["fit", log_csv, "-o", str(tmp_path / "m.json"), "--near-values", "0.5"])
    assert result.exit_code == 2
    result = CliRunner().invoke(cli, ["fit", log_csv, "-o", str(tmp_path / "m.json"), "--depth-error", "0.9"])
    assert result.exit_code == 1 and "depth error" in result.output
    assert not (tmp_path / "m.json").exists()


def test_fit_writes_model_set_for_positions(tmp_path):
    rng = np.random.default_rng(1)
    lines = ["x,y,z,m,position,pose_x,pose_y,pose_yaw"]
    for position in range(2):
        for _ in range(600):
            a = rng.uniform(-np.pi, np.pi)
            lines.append(f"{float(1.5 * np.cos(a))!r},{float(1.5 * np.sin(a))!r},{float(rng.uniform(-0.9, 0.3))!r},0.9,"
                         f"{position},{position * 2.0},0.0,0.0")
    log = tmp_path / "two.csv"
    log.write_text("\n".join(lines) + "\n")
    out = tmp_path / "models"
    out.mkdir()
    result = run("fit", str(log), "-o", str(out) + "/", "--pieces", "4")
    assert result.exit_code == 0, result.output
    index = json.loads((out / "index.json").read_text())
    assert [m["position"] for m in index["models"]] == [0, 1]
    assert index["models"][1]["pose"]["x"] == 2.0
    for entry in index["models"]:
        assert load_model(out / entry["file"]).n_features_ == 600
    result = CliRunner().invoke(cli, ["fit", str(log), "-o", str(tmp_path / "one.json")])
    assert result.exit_code == 1 and "--position" in result.output
