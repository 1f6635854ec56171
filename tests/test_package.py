"""The package's front door: a light start-up, a lazy facade, one version."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import occtool

HEAVY = ("numpy", "scipy", "shapely", "matplotlib", "mcap", "rich")


def _modules_after(code: str) -> set[str]:
    """Top-level packages imported by ``code`` in a fresh interpreter."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}})))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return set(json.loads(done.stdout.strip().splitlines()[-1]))


def test_the_command_group_imports_no_numerical_library() -> None:
    loaded = _modules_after("import occtool.cli.main")
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))


@pytest.mark.parametrize("command", [[], ["fit"], ["extract"], ["info"], ["plot"], ["compare-grid"]])
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
