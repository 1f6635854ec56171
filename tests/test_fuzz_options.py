"""Issue 12, classes 4 and 8: every size and length option is bounded up front.

A size too large for the machine (`--angles 10000000`, `--features 1000000000`, ...) or
an absurd length (`--robot-radius 1e308`) is refused before any work, naming the flag on
the command line and the keyword in the library; the bounds live in occtool.limits.
"""

from __future__ import annotations

import traceback
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool import limits
from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.robot import Robot

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures"
TRUTH = FIXTURES / "office" / "truth.json"


def run(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


def assert_refused(result, flag: str) -> None:
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError("uncaught exception:\n" + "".join(traceback.format_exception(*result.exc_info)))
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    error = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(error) == 1 and flag in error[0], result.output


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("inputs")
    lines = (FIXTURES / "office" / "features.csv").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("x,"))
    csv = folder / "features.csv"
    csv.write_text("\n".join(lines[start: start + 301]) + "\n")
    model = folder / "model.json"
    assert run("fit", csv, "-o", model, "--pieces", "8").exit_code == 0
    nav = folder / "nav.geojson"
    assert run("extract", model, "-o", nav, "--angles", "72").exit_code == 0
    return {"csv": csv, "model": model, "nav": nav}


# The examples of the issue, and every other size or length option of every command.
SIZE_CASES = [
    ("extract", "--angles", limits.MAX_ANGLES),
    ("simulate", "--features", limits.MAX_FEATURES),
    ("fit", "--pieces", limits.MAX_PIECES),
    ("fit", "--footprint-samples", limits.MAX_BODY_SAMPLES),
    ("fit", "--background-samples", limits.MAX_BODY_SAMPLES),
    ("fit", "--max-sweeps", limits.MAX_SWEEPS),
    ("evaluate", "--rays", limits.MAX_RAYS),
    ("compare-grid", "--repeat", limits.MAX_REPEATS),
    ("compare-grid", "--octomap-scans", limits.MAX_REPEATS),
]
LENGTH_CASES = [
    ("fit", "--robot-radius", limits.MAX_ROBOT_SIZE),
    ("fit", "--sensor-height", limits.MAX_ROBOT_SIZE),
    ("fit", "--body-height", limits.MAX_ROBOT_SIZE),
    ("fit", "--ground-clearance", limits.MAX_ROBOT_SIZE),
    ("fit", "--focus-range", limits.MAX_DISTANCE),
    ("fit", "--background-range", limits.MAX_DISTANCE),
    ("fit", "--c-min", limits.MAX_WEIGHT),
    ("fit", "--a-max", limits.MAX_WEIGHT),
    ("fit", "--b-max", limits.MAX_WEIGHT),
    ("fit", "--c-max", limits.MAX_WEIGHT),
    ("fit", "--huber-delta", limits.MAX_WEIGHT),
    ("extract", "--robot-radius", limits.MAX_ROBOT_SIZE),
    ("extract", "--max-range", limits.MAX_DISTANCE),
    ("evaluate", "--robot-radius", limits.MAX_ROBOT_SIZE),
    ("evaluate", "--max-range", limits.MAX_DISTANCE),
    ("plot", "--robot-radius", limits.MAX_ROBOT_SIZE),
]


def _command(inputs: dict[str, Path], command: str, out: Path) -> list[object]:
    return {
        "extract": ["extract", inputs["model"], "-o", out / "nav.geojson"],
        "simulate": ["simulate", "office", "-o", out],
        "fit": ["fit", inputs["csv"], "-o", out / "m.json"],
        "evaluate": ["evaluate", inputs["nav"], TRUTH],
        "compare-grid": ["compare-grid", inputs["csv"], "--json", out / "r.json"],
        "plot": ["plot", "nav", inputs["nav"], "-o", out / "p.png"],
    }[command]


@pytest.mark.parametrize(("command", "flag", "bound"), SIZE_CASES)
def test_sizes_beyond_the_bound_are_refused_naming_the_flag(inputs, tmp_path, command, flag, bound):
    for value in (bound + 1, 10**9, 10**30):
        assert_refused(run(*_command(inputs, command, tmp_path), flag, value), flag)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("command", "flag", "bound"), LENGTH_CASES)
def test_absurd_lengths_are_refused_naming_the_flag(inputs, tmp_path, command, flag, bound):
    if command == "plot":
        pytest.importorskip("matplotlib")
    for value in (bound * 1.5, 1e308, "inf"):
        assert_refused(run(*_command(inputs, command, tmp_path), flag, value), flag)
    assert list(tmp_path.iterdir()) == []


def test_the_issue_examples_are_refused_within_seconds(inputs, tmp_path):
    assert_refused(run("extract", inputs["model"], "-o", tmp_path / "n.geojson", "--angles", 10_000_000), "--angles")
    assert_refused(run("simulate", "office", "-o", tmp_path, "--features", 1_000_000_000), "--features")
    assert_refused(run("fit", inputs["csv"], "--pieces", 1_000_000), "--pieces")
    assert_refused(run("fit", inputs["csv"], "--footprint-samples", "1e9"), "--footprint-samples")
    assert_refused(run("evaluate", inputs["nav"], TRUTH, "--rays", 100_000_000), "--rays")
    assert_refused(run("fit", inputs["csv"], "--robot-radius", "1e308"), "--robot-radius")


# --- the library names its keywords -------------------------------------------------------------


@settings(max_examples=25)
@given(value=st.integers(limits.MAX_ANGLES + 1, 10**15))
def test_navigation_map_refuses_too_many_angles_by_keyword(value):
    from occtool.navigation import navigation_map

    with pytest.raises(InputError, match="n_angles must be at most"):
        navigation_map(lambda a, h, level: a * 0 + 1.0, robot=Robot(), n_angles=value)


@settings(max_examples=10)
@given(value=st.integers(limits.MAX_PIECES + 1, 10**12))
def test_the_regressor_refuses_too_many_pieces_by_keyword(value):
    from occtool.features import Features
    from occtool.fit import OccupancyRegressor

    with pytest.raises(InputError, match="pieces must be at most"):
        OccupancyRegressor(pieces=value).fit(Features([[1.0, 0.0, 0.0]], [0.9]))


@pytest.mark.parametrize("name", ["footprint_samples", "background_samples"])
def test_the_sensor_model_refuses_too_many_samples_by_keyword(name):
    from occtool.sensor import SensorModel

    with pytest.raises(InputError, match=f"{name} must be at most"):
        SensorModel(**{name: limits.MAX_BODY_SAMPLES + 1})


def test_simulate_and_evaluate_refuse_by_keyword():
    from occtool.scoring import reachable_region
    from occtool.simulate import load_truth, simulate_scene

    with pytest.raises(InputError, match="n_features must be at most"):
        simulate_scene("office", n_features=limits.MAX_FEATURES + 1)
    with pytest.raises(InputError, match="n_rays must be at most"):
        reachable_region(load_truth(TRUTH), robot_radius=0.25, max_range=1.5, n_rays=limits.MAX_RAYS + 1)


@settings(max_examples=40)
@given(name=st.sampled_from(["radius", "sensor_height", "body_height", "ground_clearance"]),
       value=st.floats(min_value=limits.MAX_ROBOT_SIZE, max_value=1e308, exclude_min=True))
def test_the_robot_refuses_lengths_beyond_its_range(name, value):
    with pytest.raises(InputError, match=rf"robot {name} must lie in \[0, 100\]"):
        Robot(**{name: value})


@pytest.mark.parametrize(("flag", "value"), [("--sensor-range", "1e308"), ("--noise", "1e308"), ("--radius", "1e308"),
                                             ("--sensor-height", "1e308"), ("--body-height", "1e308")])
def test_simulate_refuses_absurd_geometry(tmp_path, flag, value):
    assert_refused(run("simulate", "office", "-o", tmp_path / "s", "--features", 100, flag, value), flag)
    assert not (tmp_path / "s").exists()


def test_library_distances_are_bounded_by_keyword():
    from occtool.io import check_no_return_range
    from occtool.navigation import navigation_map
    from occtool.simulate import simulate_scene

    with pytest.raises(InputError, match="sensor_range must be at most"):
        simulate_scene("office", n_features=10, sensor_range=1e308)
    with pytest.raises(InputError, match="range_noise must be at most"):
        simulate_scene("office", n_features=10, range_noise=1e308)
    with pytest.raises(InputError, match="no-return range must be at most"):
        check_no_return_range(1e308)
    with pytest.raises(InputError, match="max_range must be at most"):
        navigation_map(lambda a, h, level: a * 0 + 1.0, robot=Robot(), max_range=1e308)
    with pytest.raises(InputError, match="more than 10,000"):
        navigation_map(lambda a, h, level: a * 0 + 1.0, robot=Robot(), heights=-0.5 + 1e-5 * np.arange(10_001))
