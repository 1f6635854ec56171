"""The package's front door: a light start-up, a lazy facade, one version."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import occtool
from occtool.cli.main import COMMANDS

HEAVY = ("numpy", "scipy", "shapely", "matplotlib", "mcap", "rich")


def _modules_after(code: str) -> set[str]:
    """Top-level packages imported by ``code`` in a fresh interpreter."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}})))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return set(json.loads(done.stdout.strip().splitlines()[-1]))


def test_the_command_group_imports_no_numerical_library() -> None:
    loaded = _modules_after("import occtool.cli.main")
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))


@pytest.mark.parametrize("command", [[], *([name] for name in COMMANDS), ["plot", "nav"]])
def test_help_imports_no_numerical_library(command: list[str]) -> None:
    code = (
        "from occtool.cli.main import cli\n"
        f"try:\n    cli.main(args={command + ['--help']!r}, prog_name='occtool')\n"
        "except SystemExit as exit:\n    assert exit.code == 0, exit.code\n"
    )
    loaded = _modules_after(code)
    assert not loaded & {"numpy", "scipy", "shapely", "matplotlib"}


def test_the_facade_is_lazy_and_complete() -> None:
    assert "numpy" not in _modules_after("import occtool")
    from occtool import OccupancyRegressor, load_model, navigation_map, read_log, save_model
    from occtool.fit import OccupancyRegressor as defined

    assert OccupancyRegressor is defined
    assert all(callable(f) for f in (navigation_map, read_log, load_model, save_model))
    assert set(occtool.__all__) == {"__version__", *occtool._LAZY}
    assert set(occtool.__all__) <= set(dir(occtool))
    with pytest.raises(AttributeError, match="no attribute 'nonsense'"):
        occtool.nonsense  # noqa: B018


def test_version_has_one_source(tmp_path) -> None:
    from click.testing import CliRunner

    from occtool.cli.main import cli

    result = CliRunner().invoke(cli, ["--version"])
    assert result.exit_code == 0
    assert result.output.strip() == f"occtool, version {occtool.__version__}"


# --- one home per concept ---------------------------------------------------------------


def _keywords(function) -> dict[str, object]:
    import inspect

    return {name: p.default for name, p in inspect.signature(function).parameters.items()
            if p.kind is inspect.Parameter.KEYWORD_ONLY}


def test_the_reader_keywords_are_named_and_defaulted_once() -> None:
    from typing import get_type_hints

    from occtool.io import read_log
    from occtool.io.carmen import read_carmen
    from occtool.io.csv import read_csv
    from occtool.io.mcap import read_mcap
    from occtool.io.pointcloud import read_pointcloud
    from occtool.io.read_options import ReadOptions

    shared = _keywords(read_log)
    assert set(shared) == set(get_type_hints(ReadOptions))
    # CARMEN's constant evidence is resolved by read_log (0.9 when None).
    # read_mcap's opener lets the ROS bag reader reuse its decoding (not a reader option).
    own = {read_carmen: {"evidence"}, read_mcap: {"opener"}}
    for reader in (read_csv, read_mcap, read_carmen, read_pointcloud):
        keywords = {k: v for k, v in _keywords(reader).items() if k not in own.get(reader, set())}
        assert keywords.items() <= shared.items(), reader.__name__


def test_one_angle_wrap_and_one_polar_conversion() -> None:
    import numpy as np

    from occtool.features import Features, polar, wrap_angle

    rng = np.random.default_rng(0)
    alpha = rng.uniform(-20.0, 20.0, 1000)
    wrapped = wrap_angle(alpha)
    assert np.all((wrapped >= -np.pi) & (wrapped < np.pi))
    np.testing.assert_allclose(np.cos(wrapped), np.cos(alpha), atol=1e-12)
    np.testing.assert_allclose(np.sin(wrapped), np.sin(alpha), atol=1e-12)
    features = Features(rng.uniform(-3.0, 3.0, (50, 3)), rng.uniform(0.0, 1.0, 50))
    for mine, theirs in zip(features.polar(), (features.alpha, features.height, features.range)):
        assert np.array_equal(mine, theirs)
    alpha, h, r = polar(features.points)
    np.testing.assert_allclose(r * np.cos(alpha) * np.sqrt(1 - (h / r) ** 2), features.points[:, 0], atol=1e-12)
