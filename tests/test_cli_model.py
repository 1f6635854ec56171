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


# --- the command line's options map onto the library's keywords ---------------------------


def _commands():
    """Every command and subcommand: (name, click command)."""
    import importlib

    import click

    from occtool.cli.main import COMMANDS

    found = []
    for name, (module, attribute, _) in COMMANDS.items():
        command = getattr(importlib.import_module(module), attribute)
        found.append((name, command))
        if isinstance(command, click.Group):
            found += [(f"{name} {sub}", c) for sub, c in command.commands.items()]
    return found


def _library_defaults() -> dict[str, dict[str, object]]:
    """The library keywords the options map onto, by owner: name -> default."""
    import dataclasses
    import inspect

    from occtool.fit import OccupancyRegressor
    from occtool.io import ReadOptions
    from occtool.navigation import navigation_map
    from occtool.robot import Robot
    from occtool.sensor import SensorModel

    def keywords(function) -> dict[str, object]:
        return {n: p.default for n, p in inspect.signature(function).parameters.items()
                if p.default is not inspect.Parameter.empty}

    return {
        "read": {f.name: f.default for f in dataclasses.fields(ReadOptions)},
        "sensor": {f.name: f.default for f in dataclasses.fields(SensorModel)},
        "fit": keywords(OccupancyRegressor.__init__),
        "robot": {f.name: f.default for f in dataclasses.fields(Robot)},
        "navigation": keywords(navigation_map),
    }


def test_every_shared_option_is_named_and_defaulted_as_its_library_keyword() -> None:
    from occtool.cli import options

    library = _library_defaults()
    # Which library object each shared option group maps onto; the robot's options are
    # renamed (--robot-radius sets Robot.radius), the rest keep the keyword's name
    # (--topic is topics=, --intensities use_intensities=, --angles n_angles=: click's
    # parameter names are the keywords).
    owners = {
        **{name: ("read", name) for name in options.LOG_OPTION_NAMES},
        **{name: ("sensor", name) for name in options.SENSOR_OPTION_NAMES},
        **{name: ("fit", name) for name in options.FIT_OPTION_NAMES},
        **{name: ("robot", field) for name, field in options.ROBOT_FIELDS.items()},
        **{name: ("navigation", name) for name in options.EXTRACT_OPTION_NAMES},
    }
    assert tuple(options.LOG_FLAGS) == options.LOG_OPTION_NAMES == tuple(library["read"])
    # The defaults the help texts state for options left to the library (default None) are the library's.
    for name, stated in options.LIBRARY_DEFAULTS.items():
        owner, keyword = owners[name]
        assert library[owner][keyword] == stated, name
    own_meaning = {("plot model", "pieces")}  # --pieces/--no-pieces: draw the pieces, not how many
    checked = set()
    for command_name, command in _commands():
        for param in command.params:
            if param.name not in owners or (command_name, param.name) in own_meaning:
                continue
            owner, keyword = owners[param.name]
            assert keyword in library[owner], (command_name, param.name)
            expected = library[owner][keyword]
            default = param.default
            if param.name == "position_tolerance":
                default = options.float_list(None, None, default)
            if getattr(param, "multiple", False) and default in ((), None):
                default = None
            if default is None and param.name in options.LIBRARY_DEFAULTS:
                continue  # the library decides; its default is named in the help, checked above
            assert default == expected, (command_name, param.name, default, expected)
            checked.add(param.name)
    assert set(options.LOG_OPTION_NAMES) <= checked
    assert set(options.ROBOT_FIELDS) <= checked


def test_each_commands_own_options_default_as_the_library_function_it_calls() -> None:
    import dataclasses
    import inspect

    from occtool.compare import compare_grid
    from occtool.robot import Robot
    from occtool.scoring import evaluate_log
    from occtool.simulate import simulate_scene

    def keywords(function) -> dict[str, object]:
        return {n: p.default for n, p in inspect.signature(function).parameters.items()
                if p.default is not inspect.Parameter.empty}

    robot = {f.name: f.default for f in dataclasses.fields(Robot)}
    # command -> (library keywords, option name -> keyword where they differ)
    calls = {
        "compare-grid": (keywords(compare_grid), {"use_octomap": "octomap"}),
        "evaluate-log": (keywords(evaluate_log), {}),
        "simulate": ({**keywords(simulate_scene), **robot}, {"features": "n_features", "noise": "range_noise"}),
    }
    commands = dict(_commands())
    for name, (library, renamed) in calls.items():
        matched = 0
        for param in commands[name].params:
            keyword = renamed.get(param.name, param.name)
            if keyword in library and param.default is not None:
                assert param.default == library[keyword], (name, param.name, param.default, library[keyword])
                matched += 1
        assert matched >= 3, name
