"""Issue 37, item 3: ``--config`` keys are spelled as the options and checked as click checks them.

Every option of every command may be set by its flag without the dashes (``topic``,
``intensities``, ``angles``, ``slices``, ``path``), dashes and underscores alike, or by
its parameter's name; each value goes through the option's own click type and callback,
with what TOML adds refused: a boolean for anything but a switch (``sensor_height =
true``), a number for a switch (``register = 1``), a list for an option given once, dates,
tables nested in tables, arrays nested deep. Every refusal is one line naming the file and
the key, never a traceback.
"""

from __future__ import annotations

import datetime
import math
import traceback
from pathlib import Path

import click
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from occtool.cli._config import MAX_CONFIG_BYTES, _config_names, load_config
from occtool.cli.main import cli

FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def commands() -> list[tuple[str, click.Command]]:
    ctx = click.Context(cli)
    found = []
    for name in cli.list_commands(ctx):
        command = cli.get_command(ctx, name)
        assert command is not None
        if isinstance(command, click.Group):
            found += [(f"{name} {sub}", command.get_command(ctx, sub)) for sub in command.list_commands(ctx)]
        else:
            found.append((name, command))
    return found


def defaults_from(command: click.Command, name: str, text: str, tmp_path: Path) -> dict:
    """The defaults a config file gives ``command`` (what click then reads as the options' defaults)."""
    config = tmp_path / "settings.toml"
    config.write_text(text, encoding="utf-8")
    ctx = click.Context(command, info_name=name)
    load_config(ctx, command.params[0], str(config))
    return dict(ctx.default_map or {})


def toml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value == math.inf else "-inf" if value == -math.inf
                                                else repr(value))
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    return str(value)  # int, date, time


def run(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


def config_error(result, config: Path) -> str | None:
    """The one error line, if it is the config file's; ``None`` when the file was taken."""
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError("uncaught exception:\n" + "".join(traceback.format_exception(*result.exc_info)))
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1, result.output
    return errors[0] if "--config" in errors[0] else None


# --- names ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "command"), commands(), ids=[name for name, _ in commands()])
def test_every_flag_is_a_key(name, command):
    names = _config_names(command)
    for param in command.params:
        if not param.expose_value:
            continue
        flags = [f for f in getattr(param, "opts", []) if f.startswith("--")]
        for flag in flags:
            for key in (flag[2:], flag[2:].replace("-", "_")):
                assert names[key.replace("-", "_")] == (param, False), (name, key)
        for flag in getattr(param, "secondary_opts", []):
            assert names[flag[2:].replace("-", "_")] == (param, True), (name, flag)
        if not any(names.get(f[2:].replace("-", "_"), (None,))[0] is not param for f in flags):
            assert names[str(param.name)][0] is param  # the parameter's own name, unless a flag took it


@pytest.mark.parametrize(("name", "text", "expected"), [
    ("map", 'topic = "/scan"\n', {"topics": ["/scan"]}),
    ("map", '[log]\ntopic = ["/scan", "/points"]\n', {"topics": ["/scan", "/points"]}),
    ("map", "intensities = true\n", {"use_intensities": True}),
    ("map", "use-intensities = false\n", {"use_intensities": False}),
    ("extract", "angles = 72\n", {"n_angles": 72}),
    ("extract", "slices = true\n", {"include_slices": True}),
    ("plot map", "path = false\n", {"draw_path": False}),
    ("plot map", "no-path = true\n", {"draw_path": False}),
    ("fit", "[sensor]\nnear-positions = [0.7, 0.85]\n", {"near_positions": "0.7,0.85"}),
    ("fit", "[sensor]\nsensor-height = 0.2\n[fit]\npieces = 6\n", {"sensor_height": 0.2, "pieces": 6}),
    ("map", "position-tolerance = [0.3, 0.1]\n", {"position_tolerance": "0.3,0.1"}),
])
def test_keys_spelled_as_the_flags_set_the_options(tmp_path, name, text, expected):
    command = dict(commands())[name]
    assert defaults_from(command, name, text, tmp_path) == expected


def test_a_key_of_the_flag_reaches_the_command(tmp_path):
    config = tmp_path / "map.toml"
    config.write_text('topic = "/points"\nintensities = true\n')
    log = tmp_path / "run.csv"
    log.write_text("x,y,z\n1,0,0\n")
    command = dict(commands())["map"]
    with command.make_context("map", ["--config", str(config), str(log), "-o", str(tmp_path / "out")]) as ctx:
        assert ctx.params["topics"] == ("/points",) and ctx.params["use_intensities"] is True


# --- refusals ------------------------------------------------------------------------------


@pytest.mark.parametrize(("command", "text", "fragments"), [
    ("fit", "[sensor]\ndepth-error = [1.0, 2.0]\n", ["depth-error", "not a list"]),
    ("fit", "[sensor]\ndepth-error = 1979-05-27\n", ["depth-error", "date"]),
    ("fit", "[sensor]\ndepth-error = 07:32:00\n", ["depth-error", "date or time"]),
    ("fit", '[sensor]\ndepth-error = "much"\n', ["depth-error", "much"]),
    ("fit", "[sensor]\ndepth-error = {a = 1}\n", ["depth-error", "table"]),
    ("map", "register = 1\n", ["register", "true or false"]),
    ("map", 'register = "yes"\n', ["register", "true or false"]),
    ("map", "intensities = 0\n", ["intensities", "true or false"]),
    ("fit", "[sensor]\nsensor_height = true\n", ["sensor_height", "not true"]),
    ("fit", "pieces = 8.7\n", ["pieces", "whole number"]),
    ("fit", "seed = true\n", ["seed", "whole number"]),
    ("fit", "pieces = 99999999999999999999\n", ["pieces", "range"]),
    ("fit", "[sensor]\nnear-positions = [[0.7], [0.85]]\n", ["near-positions", "nested"]),
    ("fit", "[sensor]\ndepth-error = " + "[" * 5000 + "]" * 5000 + "\n", ["nested too deeply"]),
    ("fit", "[sensor.deeper]\ndepth-error = 0.1\n", ["[sensor] deeper", "table inside"]),
    ("fit", "pieces = 6\n[fit]\npieces = 7\n", ["pieces", "set twice"]),
    ("map", '[log]\nformat = "nonsense"\n', ["format", "nonsense"]),
    ("map", "topic = [1, true]\n", ["topic", "plain values"]),
    ("fit", "angles = 72\n", ["unknown settings", "angles"]),
])
def test_a_bad_setting_is_one_line_naming_the_file_and_key(tmp_path, command, text, fragments):
    config = tmp_path / "settings.toml"
    config.write_text(text, encoding="utf-8")
    args = [*command.split(), "--config", config, tmp_path / "missing.log"]
    error = config_error(run(*args), config)
    assert error is not None and str(config) in error, error
    for fragment in fragments:
        assert fragment in error, (fragment, error)


def test_a_settings_file_too_large_is_refused_unread(tmp_path):
    config = tmp_path / "big.toml"
    config.write_text("# padding\n" * (MAX_CONFIG_BYTES // 10 + 10))
    error = config_error(run("fit", "--config", config, tmp_path / "missing.log"), config)
    assert error is not None and "larger than" in error


# --- fuzzed values -------------------------------------------------------------------------

SCALARS = (st.booleans() | st.integers(min_value=-(2**70), max_value=2**70) | st.floats()
           | st.text(alphabet=st.characters(codec="utf-8", exclude_categories=["Cs", "Cc"]), max_size=12)
           | st.dates() | st.times())
VALUES = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=4), max_leaves=8)
FIT_KEYS = ["pieces", "seed", "depth-error", "sensor_height", "near-positions", "focus-range", "basis",
            "topic", "intensities", "position-tolerance", "no-return-range", "skip-invalid", "format",
            "depth-features", "evidence"]


@FUZZ
@given(key=st.sampled_from(FIT_KEYS), value=VALUES, table=st.sampled_from(["", "[sensor]\n", "[log]\n"]))
@example(key="depth-error", value=[1.0, 2.0], table="[sensor]\n")
@example(key="sensor_height", value=True, table="")
@example(key="position-tolerance", value=[[0.1]], table="")
@example(key="pieces", value=datetime.date(1979, 5, 27), table="")
def test_any_value_is_taken_or_refused_in_one_line(tmp_path_factory, key, value, table):
    config = tmp_path_factory.mktemp("config") / "fit.toml"
    config.write_text(f"{table}{key} = {toml_value(value)}\n", encoding="utf-8")
    error = config_error(run("fit", "--config", config, config.parent / "missing.log"), config)
    if error is not None:
        assert str(config) in error and key in error, error
    else:
        # Taken: a switch only from true or false, never from a number or text.
        command = dict(commands())["fit"]
        target, _ = _config_names(command)[key.replace("-", "_")]
        if isinstance(target, click.Option) and target.is_flag:
            assert isinstance(value, bool)
        else:
            assert not isinstance(value, bool)
