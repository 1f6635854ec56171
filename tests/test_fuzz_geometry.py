"""Issue 12, classes 10 and 11: data that cannot fit the robot's geometry is warned about,
planar laser logs get a planar scanner's defaults, and warnings are one log line.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.cli.main import cli
from occtool.features import Features
from occtool.robot import PLANAR_LASER_BODY_HEIGHT, PLANAR_LASER_SENSOR_HEIGHT, Robot
from occtool.sensor import geometry_findings, is_planar

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures"


def run(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


def ring(z: np.ndarray | float, n: int = 400, radius: float = 2.0, seed: int = 0) -> Features:
    angles = np.random.default_rng(seed).uniform(-np.pi, np.pi, n)
    heights = np.broadcast_to(np.asarray(z, dtype=float), (n,))
    return Features(np.column_stack([radius * np.cos(angles), radius * np.sin(angles), heights]), np.full(n, 0.9))


def test_a_2d_laser_at_the_top_edge_of_the_default_band_is_a_finding():
    findings = geometry_findings(ring(0.0), Robot())
    assert len(findings) == 1 and "one plane at h = 0 m" in findings[0] and "edge" in findings[0]
    assert geometry_findings(ring(0.0), Robot(sensor_height=PLANAR_LASER_SENSOR_HEIGHT,
                                              body_height=PLANAR_LASER_BODY_HEIGHT)) == []


def test_the_office_scene_agrees_with_its_robot():
    from occtool.io import read_log

    features = read_log(FIXTURES / "office" / "features.csv").single().features
    assert geometry_findings(features, Robot()) == []
    assert not is_planar(features)


def test_a_floor_layer_far_above_the_assumed_floor_is_a_finding():
    # A scan taken 7 cm above the floor (OctoMap's scan.dat): half the returns are floor at -0.07 m.
    rng = np.random.default_rng(1)
    floor = ring(-0.07 + rng.normal(0, 0.005, 400), seed=1)
    walls = ring(rng.uniform(-0.05, 2.0, 400), seed=2)
    features = Features.concatenate([floor, walls])
    (finding,) = geometry_findings(features, Robot())
    assert "layer at h = -0.07 m" in finding and "lower than" in finding
    assert geometry_findings(features, Robot(sensor_height=0.07, body_height=0.5, ground_clearance=0.03)) == []


def test_much_data_below_the_floor_is_a_finding():
    # A Velodyne 1.8 m up read with the default 1 m sensor height.
    features = ring(np.random.default_rng(2).uniform(-1.8, 1.0, 400))
    findings = geometry_findings(features, Robot())
    assert any("below the floor" in f and "higher than" in f for f in findings)
    assert not any("below the floor" in f for f in geometry_findings(features, Robot(sensor_height=1.8, body_height=2)))


def test_no_returns_inside_the_body_band_is_a_finding():
    features = ring(np.random.default_rng(3).uniform(1.0, 2.0, 400))
    assert any("none of the 400 returns lies inside" in f for f in geometry_findings(features, Robot()))


def test_free_rays_are_not_returns():
    features = Features(ring(0.0).points, np.zeros(400))
    assert geometry_findings(features, Robot()) == []


@settings(max_examples=60)
@given(z=st.lists(st.floats(-3.0, 3.0), min_size=1, max_size=50),
       sensor=st.floats(0.05, 3.0), body=st.floats(0.1, 3.0))
def test_findings_are_sentences_for_any_data(z, sensor, body):
    robot = Robot(sensor_height=sensor, body_height=body, ground_clearance=0.05)
    findings = geometry_findings(ring(np.array(z * (400 // len(z) + 1))[:400]), robot)
    assert all(isinstance(f, str) and "\n" not in f for f in findings)


@pytest.fixture(scope="module")
def carmen_log(tmp_path_factory) -> Path:
    """A CARMEN log of three scans from one place."""
    path = tmp_path_factory.mktemp("carmen") / "laser.log"
    ranges = " ".join(f"{1.5 + 0.5 * np.sin(k / 20):.3f}" for k in range(180))
    path.write_text("".join(f"FLASER 180 {ranges} 0 0 0 0 0 0 {t} host {t}\n" for t in (1.0, 1.1, 1.2)))
    return path


def test_a_planar_laser_log_gets_planar_scanner_defaults(carmen_log, tmp_path, caplog):
    out = tmp_path / "m.json"
    result = run("fit", carmen_log, "-o", out, "--pieces", "8")
    assert result.exit_code == 0, result.output
    robot = json.loads(out.read_text())["robot"]
    assert (robot["sensor_height"], robot["body_height"]) == (PLANAR_LASER_SENSOR_HEIGHT, PLANAR_LASER_BODY_HEIGHT)
    assert "at the edge" not in result.output
    # A laser's focus range, unless another is given.
    from occtool.fit import PLANAR_FOCUS_RANGE

    assert json.loads(out.read_text())["fit"]["focus_range"] == PLANAR_FOCUS_RANGE
    assert run("fit", carmen_log, "-o", out, "--pieces", "8", "--focus-range", "3").exit_code == 0
    assert json.loads(out.read_text())["fit"]["focus_range"] == 3.0


def test_given_heights_win_and_a_plane_at_the_edge_is_warned(carmen_log, tmp_path):
    out = tmp_path / "m.json"
    result = run("fit", carmen_log, "-o", out, "--pieces", "8", "--sensor-height", "1", "--body-height", "1")
    assert result.exit_code == 0, result.output
    assert json.loads(out.read_text())["robot"]["sensor_height"] == 1.0
    assert "at the edge of the body band" in " ".join(result.output.split())


def test_a_config_file_counts_as_given(carmen_log, tmp_path):
    config = tmp_path / "fit.toml"
    config.write_text("[sensor]\nsensor-height = 0.2\n")
    out = tmp_path / "m.json"
    assert run("fit", carmen_log, "-o", out, "--pieces", "8", "--config", config).exit_code == 0
    robot = json.loads(out.read_text())["robot"]
    assert (robot["sensor_height"], robot["body_height"]) == (0.2, 1.0)


# --- class 11: warnings are log lines ---------------------------------------------------------------


def test_a_runtime_warning_is_one_log_line_without_source(monkeypatch, tmp_path):
    import occtool.io as io_module

    real = io_module.iter_positions  # what `info` reads a log through

    def noisy(*args, **kwargs):
        with np.errstate(divide="warn"):
            np.float64(1.0) / np.zeros(1)
        warnings.warn("a second warning", UserWarning, stacklevel=1)
        return real(*args, **kwargs)

    monkeypatch.setattr(io_module, "iter_positions", noisy)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        result = run("info", FIXTURES / "office" / "features.csv")
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "WARNING RuntimeWarning: divide by zero encountered in divide" in text
    assert "WARNING UserWarning: a second warning" in text
    assert "np.float64(1.0)" not in result.output and "noisy" not in result.output
