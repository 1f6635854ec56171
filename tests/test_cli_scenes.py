"""``occtool simulate`` and ``occtool evaluate`` from the command line."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.io import read_log
from occtool.scoring import reachable_region
from occtool.simulate import load_truth, simulate_scene


def run(*args: str):
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


def read_csv_rows(path) -> np.ndarray:
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    assert lines[0] == "x,y,z,m"
    return np.loadtxt(lines[1:], delimiter=",", ndmin=2)


def test_simulate_writes_features_and_truth(tmp_path) -> None:
    out = tmp_path / "office"
    result = run("simulate", "office", "-o", str(out), "--features", "1500", "--seed", "4", "--yaw", "0.5")
    assert result.exit_code == 0, result.output
    lines = (out / "features.csv").read_text().splitlines()
    comments = [line for line in lines if line.startswith("#")]
    assert lines[: len(comments)] == comments and lines[len(comments)] == "x,y,z,m"
    assert any("office" in c and "seed 4" in c and "1500 features" in c for c in comments)
    assert any("base_link" in c for c in comments)
    # The readers' CSV reader takes the file as it is.
    log = read_log(out / "features.csv")
    features, scene = simulate_scene("office", n_features=1500, seed=4, yaw=0.5)
    np.testing.assert_allclose(log.single().features.points, features.points, atol=6e-5)
    np.testing.assert_allclose(log.single().features.evidence, features.evidence, atol=6e-4)
    assert load_truth(out / "truth.json") == scene


def test_simulate_robot_options_reach_the_truth(tmp_path) -> None:
    result = run("simulate", "corridor", "-o", str(tmp_path), "--features", "300", "--sensor-height", "1.3",
                 "--body-height", "1.4", "--radius", "0.3", "--noise", "0", "--outlier-rate", "0")
    assert result.exit_code == 0, result.output
    robot = load_truth(tmp_path / "truth.json").robot
    assert (robot.sensor_height, robot.body_height, robot.radius) == (1.3, 1.4, 0.3)
    assert read_csv_rows(tmp_path / "features.csv")[:, 2].min() == pytest.approx(-1.3, abs=1e-4)


def test_unknown_scene_is_a_usage_error_listing_the_scenes(tmp_path) -> None:
    result = run("simulate", "garage", "-o", str(tmp_path))
    assert result.exit_code == 2
    assert "office" in result.output and "corridor" in result.output
    assert not list(tmp_path.iterdir())


def test_simulate_replaces_outputs_unless_told_not_to(tmp_path) -> None:
    assert run("simulate", "open", "-o", str(tmp_path), "--features", "100").exit_code == 0
    before = (tmp_path / "features.csv").read_text()
    result = run("simulate", "open", "-o", str(tmp_path), "--features", "100", "--seed", "1", "--no-overwrite")
    assert result.exit_code == 1 and "exists already" in result.output and "--overwrite" in result.output
    assert (tmp_path / "features.csv").read_text() == before
    assert run("simulate", "open", "-o", str(tmp_path), "--features", "100", "--seed", "1").exit_code == 0
    assert (tmp_path / "features.csv").read_text() != before


@pytest.mark.parametrize("name", ["office", "corridor"])
def test_fixtures_are_what_the_documented_command_makes(fixtures_dir, name: str) -> None:
    features, scene = simulate_scene(name, n_features=10000, seed=0)
    rows = read_csv_rows(fixtures_dir / name / "features.csv")
    np.testing.assert_allclose(rows[:, :3], features.points, atol=2e-4)
    assert load_truth(fixtures_dir / name / "truth.json") == scene
    assert (fixtures_dir / name / "features.csv").stat().st_size < 400_000


def write_navigation(path, geometry, **properties) -> None:
    collection = {
        "type": "FeatureCollection",
        "properties": {"frame_id": "base_link", "units": "m", **properties},
        "features": [
            {
                "type": "Feature",
                "properties": {"kind": "navigation"},
                "geometry": json.loads(shapely.to_geojson(geometry)),
            },
            {
                "type": "Feature",
                "properties": {"kind": "exploration"},
                "geometry": {"type": "Point", "coordinates": [1, 0]},
            },
        ],
    }
    path.write_text(json.dumps(collection))


def test_evaluate_reads_radius_and_range_from_the_geojson(tmp_path, fixtures_dir) -> None:
    truth = fixtures_dir / "office" / "truth.json"
    region = reachable_region(load_truth(truth), robot_radius=0.3, max_range=1.2)
    nav = tmp_path / "nav.geojson"
    write_navigation(nav, region, robot_radius=0.3, max_range=1.2)
    result = run("evaluate", str(nav), str(truth), "--json")
    assert result.exit_code == 0, result.output
    scores = json.loads(result.output)
    assert scores["iou"] == pytest.approx(1.0, abs=1e-9) and scores["violation"] == 0.0
    assert scores["robot_radius"] == 0.3 and scores["max_range"] == 1.2
    # Options override the file: a larger disk makes the same polygon a partial answer.
    wider = json.loads(run("evaluate", str(nav), str(truth), "--json", "--max-range", "2.0").output)
    assert wider["max_range"] == 2.0 and wider["iou"] < 0.9 and wider["coverage"] < 0.9


def test_evaluate_prints_a_table(tmp_path, fixtures_dir) -> None:
    nav = tmp_path / "nav.geojson"
    write_navigation(nav, shapely.Point(0, 0).buffer(1.5), robot_radius=0.25, max_range=1.5)
    result = run("evaluate", str(nav), str(fixtures_dir / "office" / "truth.json"))
    assert result.exit_code == 0, result.output
    for word in ("IoU", "violation", "truth area"):
        assert word in result.output
    assert "0.0000" not in result.output.split("violation")[1].splitlines()[0]  # the disk hits the table


def test_evaluate_without_max_range_asks_for_it(tmp_path, fixtures_dir) -> None:
    nav = tmp_path / "nav.geojson"
    write_navigation(nav, shapely.Point(0, 0).buffer(1.0))
    result = run("evaluate", str(nav), str(fixtures_dir / "office" / "truth.json"))
    assert result.exit_code == 1 and "--max-range" in result.output


@pytest.mark.parametrize(
    "content",
    ["not json at all", json.dumps({"type": "FeatureCollection", "features": []}),
     json.dumps({"type": "FeatureCollection", "properties": {"max_range": "far"}, "features": [
         {"type": "Feature", "properties": {"kind": "navigation"},
          "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 0]]]}}]})],
)
def test_malformed_geojson_is_a_one_line_error(tmp_path, fixtures_dir, content: str) -> None:
    nav = tmp_path / "nav.geojson"
    nav.write_text(content)
    result = run("evaluate", str(nav), str(fixtures_dir / "office" / "truth.json"))
    assert result.exit_code == 1
    assert result.output.startswith("Error: ") and result.output.count("\n") == 1
    assert "Traceback" not in result.output


def test_malformed_truth_is_a_one_line_error(tmp_path) -> None:
    nav = tmp_path / "nav.geojson"
    write_navigation(nav, shapely.Point(0, 0).buffer(1.0), max_range=1.0)
    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps({"format": "occtool-scene-truth", "version": 1, "obstacles": [{"z_min": 0}]}))
    result = run("evaluate", str(nav), str(truth))
    assert result.exit_code == 1 and str(truth) in result.output and result.output.count("\n") == 1


def test_documented_disk_area_is_known(tmp_path) -> None:
    # An empty far-walled scene: the region is the max-range disk, which the CLI reports.
    run("simulate", "open", "-o", str(tmp_path), "--features", "100")
    nav = tmp_path / "nav.geojson"
    write_navigation(nav, shapely.Point(0, 0).buffer(0.5, quad_segs=128), robot_radius=0.25, max_range=0.5)
    scores = json.loads(run("evaluate", str(nav), str(tmp_path / "truth.json"), "--json").output)
    assert scores["truth_area"] == pytest.approx(math.pi * 0.25, rel=1e-4)
    assert scores["iou"] == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("sequence", [False, True])
@pytest.mark.parametrize("pose", [None, (2.0, -1.0, 0.6)])
def test_evaluate_reads_what_extract_writes(tmp_path, fixtures_dir, sequence: bool, pose) -> None:
    # The navigation module's own writer, with an unbounded model: the map is the full disk,
    # so the scores are those of the disk whatever frame or layout the file uses.
    from occtool.features import Pose
    from occtool.formats.geojson import write_navigation
    from occtool.navigation import navigation_map
    from occtool.robot import Robot

    def never_occupied(alpha, h, level):
        return np.full(np.broadcast(alpha, h, level).shape, np.inf)

    nav = navigation_map(never_occupied, robot=Robot(), max_range=1.5)
    path = tmp_path / "nav.geojson"
    write_navigation(nav, path, sequence=sequence, pose=None if pose is None else Pose(*pose[:2], yaw=pose[2]))
    truth = fixtures_dir / "office" / "truth.json"
    scores = json.loads(run("evaluate", str(path), str(truth), "--json").output)
    disk = tmp_path / "disk.geojson"
    write_navigation(nav, disk)
    reference = json.loads(run("evaluate", str(disk), str(truth), "--json").output)
    assert scores["max_range"] == 1.5 and scores["robot_radius"] == 0.25
    for key in ("iou", "violation", "area", "coverage", "exploration_accuracy"):
        assert scores[key] == pytest.approx(reference[key], rel=1e-6)
    # Exploration points all around the circle: the office's walls and table close some directions.
    assert 0.2 < reference["exploration_accuracy"] < 0.9
    assert reference["area"] == pytest.approx(nav.polygon.area)
    assert reference["violation"] > 0.05  # the disk runs into the table and the walls


def test_simulate_takes_defaults_from_a_config_file(tmp_path) -> None:
    config = tmp_path / "scene.toml"
    config.write_text("features = 120\nseed = 9\nnoise = 0.0\noutlier-rate = 0.0\n")
    out = tmp_path / "out"
    assert run("simulate", "clutter", "-o", str(out), "--config", str(config), "--seed", "2").exit_code == 0
    features, _ = simulate_scene("clutter", n_features=120, seed=2, range_noise=0.0, outlier_rate=0.0)
    np.testing.assert_allclose(read_csv_rows(out / "features.csv")[:, :3], features.points, atol=6e-5)
