"""Help texts say what an option changes, from the code's own values, and `--json [FILE]`
works alike in every command that reports figures."""

from __future__ import annotations

import json
import re

import pytest
from click.testing import CliRunner

from occtool.cli.main import cli


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def help_of(*command: str) -> str:
    """A command's --help, its lines joined (click wraps them at any width)."""
    result = run(*command, "--help")
    assert result.exit_code == 0, result.output
    return " ".join(result.output.split())


def test_simulate_lists_every_scene_of_the_catalogue():
    from occtool.simulate import SCENES

    text = help_of("simulate")
    for name, description in SCENES.items():
        assert re.search(rf"\b{name}\b", text), name
        assert " ".join(description.split()[:4]) in text, name


def test_jobs_says_what_runs_in_parallel_for_each_command():
    fit, extract = help_of("fit"), help_of("extract")
    assert "positions whose models are fitted at once" in fit
    assert "navigation maps are extracted at once" in extract
    assert "positions fitted" not in extract


def test_map_threshold_states_the_nav2_maps_own_thresholds():
    from occtool.formats.nav2 import FREE_THRESH, OCCUPIED_THRESH, SCALE_FREE_THRESH
    from occtool.raster import RASTER_FREE, RASTER_OCCUPIED

    text = help_of("map")
    threshold = text[text.index("--threshold"):text.index("--keyframe-share")]
    assert "[default: 0.6]" in threshold and "navigation polygon" in threshold
    for value in (RASTER_OCCUPIED, RASTER_FREE, OCCUPIED_THRESH, FREE_THRESH, SCALE_FREE_THRESH):
        assert f"{value:g}" in threshold, value


def test_keyframe_share_and_c_max_quote_the_codes_values():
    from occtool.cli.options import LIBRARY_DEFAULTS
    from occtool.fuse._keyframes import KEYFRAME_CELL, KEYFRAME_NEW_SHARE

    for command in ("map", "evaluate-log"):
        text = help_of(command)
        assert f"{KEYFRAME_CELL:g} m world cells" in text and "Raised: fewer positions fitted" in text
    assert f"{KEYFRAME_NEW_SHARE:g} fits 420 of 819" in help_of("map")
    c_max = LIBRARY_DEFAULTS["c_max"]
    text = help_of("fit")
    assert f"({c_max:g}: {100 / c_max:g} cm)" in text and f"[default: {c_max:g}]" in text
    assert "Raised:" in help_of("extract")  # --return-snap


@pytest.mark.parametrize("command", ["map", "fit", "extract", "evaluate", "evaluate-log", "compare-grid",
                                     "simulate", "convert", "plot", "query"])
def test_help_speaks_to_the_user_not_of_the_projects_issues(command):
    assert not re.search(r"\bissues?\b", help_of(command), re.IGNORECASE)


@pytest.fixture
def scored(tmp_path, fixtures_dir):
    """A navigation map (the office's reachable region, less a bite) and the office's truth."""
    import shapely

    from occtool.scoring import reachable_region
    from occtool.simulate import load_truth

    truth = fixtures_dir / "office" / "truth.json"
    region = reachable_region(load_truth(truth), robot_radius=0.3, max_range=1.2).difference(
        shapely.box(1.0, -0.2, 1.3, 0.2))
    nav = tmp_path / "nav.geojson"
    nav.write_text(json.dumps({
        "type": "FeatureCollection",
        "properties": {"frame_id": "base_link", "units": "m", "robot_radius": 0.3, "max_range": 1.2},
        "features": [{"type": "Feature", "properties": {"kind": "navigation"},
                      "geometry": json.loads(shapely.to_geojson(region))}],
    }))
    return nav, truth


def test_evaluate_json_file_holds_what_standard_output_gave(scored, tmp_path):
    nav, truth = scored
    printed = run("evaluate", nav, truth, "--json")  # the old flag, still standard output
    assert printed.exit_code == 0, printed.output
    assert json.loads(run("evaluate", nav, truth, "--json", "-").output) == json.loads(printed.output)
    target = tmp_path / "scores.json"
    result = run("evaluate", nav, truth, "--json", target)
    assert result.exit_code == 0, result.output
    assert json.loads(target.read_text()) == json.loads(printed.output)
    assert "IoU" in result.output and not result.output.lstrip().startswith("{")  # the table, as without --json
