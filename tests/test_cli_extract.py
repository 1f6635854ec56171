"""``occtool extract`` end to end: model and inverse files in, GeoJSON out."""

from __future__ import annotations

import json
import math

import pytest
import shapely
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.formats.geojson import read_navigation
from occtool.formats.model import save_inverse, save_model
from occtool.tree import InverseTree


@pytest.fixture
def sphere_inverse(tmp_path):
    """An inverse file of a sphere of radius 1.2 m around the sensor at level 0.6: r = m + 0.6."""
    path = tmp_path / "sphere.inverse.json"
    save_inverse(InverseTree("linear", [[0.0, 0.0, 1.0, 0.6]], 0), path)
    return path


@pytest.fixture(scope="module")
def fitted_model(tmp_path_factory):
    """A small model really fitted to a simulated office, for a robot with its sensor at 0.8 m."""
    from occtool.fit import OccupancyRegressor
    from occtool.robot import Robot
    from occtool.simulate import simulate_scene

    features, _ = simulate_scene("office", n_features=600, seed=1)
    robot = Robot(radius=0.2, sensor_height=0.8, body_height=0.9)
    model = OccupancyRegressor(pieces=4, max_sweeps=3, robot=robot).fit(features)
    path = tmp_path_factory.mktemp("model") / "model.json"
    save_model(model, path)
    return path


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def test_stdout_carries_the_collection_when_no_output_is_given(sphere_inverse):
    result = run("extract", sphere_inverse, "--heights=-0.5", "--max-range", "1.5", "--ignore-bounds")
    assert result.exit_code == 0, result.output
    collection = json.loads(result.stdout)
    assert collection["type"] == "FeatureCollection"
    assert collection["properties"]["heights"] == [-0.5]
    polygon = shapely.geometry.shape(collection["features"][0]["geometry"])
    # At h = -0.5 the sphere is sqrt(1.2^2 - 0.5^2) away; the robot keeps 0.25 m from it.
    expected = math.sqrt(1.2**2 - 0.5**2) - 0.25
    assert polygon.area == pytest.approx(math.pi * expected**2, rel=2e-3)


def test_the_map_holds_over_the_whole_body_band_not_only_at_the_given_heights(sphere_inverse):
    # The body spans 0.05 to 1 m above the floor (sensor frame -0.95 to 0): the sphere is
    # nearest at the band's lowest height, sqrt(1.2^2 - 0.95^2), whatever height is asked for.
    result = run("extract", sphere_inverse, "--heights=-0.5", "--max-range", "1.5")
    assert result.exit_code == 0, result.output
    polygon = shapely.geometry.shape(json.loads(result.stdout)["features"][0]["geometry"])
    expected = math.sqrt(1.2**2 - 0.95**2) - 0.25
    assert polygon.area == pytest.approx(math.pi * expected**2, rel=2e-3)


def test_output_file_sequence_slices_and_precision(sphere_inverse, tmp_path):
    out = tmp_path / "nav.geojsons"
    result = run("extract", sphere_inverse, "-o", out, "--heights=-0.9,-0.5,-0.1", "--slices", "--sequence",
                 "--precision", "4", "--angles", "180", "--point-spacing", "0.5")
    assert result.exit_code == 0, result.output
    assert result.stdout == ""
    features = [json.loads(line) for line in out.read_text().splitlines()]
    kinds = [f["properties"]["kind"] for f in features]
    assert kinds.count("navigation") == 1 and kinds.count("slice") == 3 and kinds.count("exploration") == 0
    assert kinds.count("obstacle") == math.ceil(2 * math.pi * 1.5 / 0.5)
    assert all(len(str(c).split(".")[-1]) <= 4 for c in features[1]["geometry"]["coordinates"])
    back = read_navigation(out)
    assert back.n_angles == 180 and back.heights == (-0.9, -0.5, -0.1)


def test_indent_writes_a_readable_collection(sphere_inverse, tmp_path):
    out = tmp_path / "nav.geojson"
    assert run("extract", sphere_inverse, "-o", out, "--indent", "2").exit_code == 0
    text = out.read_text()
    assert text.startswith('{\n  "type": "FeatureCollection"')
    assert read_navigation(out).threshold == 0.6


def test_a_fitted_model_brings_its_slope_bounds_and_robot(fitted_model, tmp_path):
    out = tmp_path / "nav.geojson"
    result = run("extract", fitted_model, "-o", out)
    assert result.exit_code == 0, result.output
    properties = json.loads(out.read_text())["properties"]
    assert properties["sensor_height"] == 0.8 and properties["body_height"] == 0.9
    assert properties["robot_radius"] == 0.2
    # The model's pieces bound the map between cuts exactly: no margin, the whole band cut.
    assert properties["effective_threshold"] == properties["threshold"] == 0.6
    assert properties["margin"] == 0
    slices = properties["slice_heights"]
    assert len(slices) > len(properties["heights"])
    assert min(slices) == pytest.approx(0.05 - 0.8) and max(slices) == pytest.approx(0.9 - 0.8)
    # Options given on the command line override the model's robot.
    result = run("extract", fitted_model, "-o", out, "--robot-radius", "0.3", "--threshold", "0.7")
    assert result.exit_code == 0, result.output
    properties = json.loads(out.read_text())["properties"]
    assert properties["robot_radius"] == 0.3 and properties["sensor_height"] == 0.8
    assert properties["threshold"] == 0.7
    # The model's guard carries rays on to its returns by the library's default, or as told.
    from occtool.navigation import RETURN_SNAP

    assert properties["return_snap"] == RETURN_SNAP
    snapped = shapely.geometry.shape(json.loads(out.read_text())["features"][0]["geometry"])
    result = run("extract", fitted_model, "-o", out, "--robot-radius", "0.3", "--threshold", "0.7",
                 "--return-snap", "0")
    assert result.exit_code == 0, result.output
    collection = json.loads(out.read_text())
    assert collection["properties"]["return_snap"] == 0
    # Within GEOS's chords: the shrink of the two star polygons draws its corner arcs
    # apart, so the unsnapped one pokes out by a few micrometres in places (measured 6.5 um
    # and 1.8e-6 m^2 here, 12 um with 16 chords a quarter); its area alone says little.
    unsnapped = shapely.geometry.shape(collection["features"][0]["geometry"])
    assert unsnapped.difference(snapped.buffer(1e-4)).area <= 1e-9
    assert unsnapped.area <= snapped.area + 1e-5


def test_config_file_gives_defaults(sphere_inverse, tmp_path):
    config = tmp_path / "occtool.toml"
    config.write_text("[extract]\nthreshold = 0.55\nmax-range = 1.0\n")
    result = run("extract", sphere_inverse, "--config", config)
    assert result.exit_code == 0, result.output
    properties = json.loads(result.stdout)["properties"]
    assert properties["threshold"] == 0.55 and properties["max_range"] == 1.0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--heights=-1.5"], "floor"),
        (["--max-range", "0"], "max-range"),
        (["--heights=a,b"], "comma-separated"),
        (["--angles", "4"], "angles"),
    ],
)
def test_bad_options_are_one_line_errors(sphere_inverse, args, message):
    result = run("extract", sphere_inverse, *args)
    assert result.exit_code in (1, 2)
    assert message in result.stderr
    assert "Traceback" not in result.stderr


def test_a_file_that_is_not_a_model_is_refused(tmp_path):
    bogus = tmp_path / "features.csv"
    bogus.write_text("x,y,z,m\n1,0,0,0.9\n")
    out = tmp_path / "nav.geojson"
    result = run("extract", bogus, "-o", out)
    assert result.exit_code == 1
    assert "not an occtool model" in result.stderr and "Traceback" not in result.stderr
    assert not out.exists()


def test_a_robot_in_collision_writes_an_empty_polygon_and_warns(tmp_path):
    path = tmp_path / "tight.inverse.json"
    save_inverse(InverseTree("linear", [[0.0, 0.0, 1.0, -0.4]], 0), path)  # r = 0.2 at level 0.6
    result = run("extract", path, "--heights=-0.1")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["features"][0]["geometry"]["coordinates"] == []
    assert "collision" in result.stderr


@pytest.fixture
def model_set(tmp_path):
    """Two positions, each seeing a sphere of 1.2 m, the second 3 m ahead and turned left."""
    folder = tmp_path / "models"
    folder.mkdir()
    for name in ("a.json", "b.json"):
        save_inverse(InverseTree("linear", [[0.0, 0.0, 1.0, 0.6]], 0), folder / name)
    index = {
        "format": "occtool-model-set", "format_version": 1, "frame": "base_link", "poses_frame": "map",
        "models": [
            {"position": 0, "file": "a.json", "pose": {"x": 0.0, "y": 0.0, "z": 0.0, "yaw": 0.0}},
            {"position": 7, "file": "b.json", "pose": {"x": 3.0, "y": 0.0, "z": 0.0, "yaw": math.pi / 2}},
        ],
    }
    (folder / "index.json").write_text(json.dumps(index))
    return folder


def test_a_model_set_gives_one_map_per_position_in_the_world_frame(model_set, tmp_path):
    out = tmp_path / "maps.geojson"
    result = run("extract", model_set, "--world", "--heights=-0.5", "-o", out)
    assert result.exit_code == 0, result.output
    collection = json.loads(out.read_text())
    assert collection["properties"]["frame_id"] == "map"
    assert [p["position"] for p in collection["properties"]["positions"]] == [0, 7]
    second = read_navigation(out, position=7)
    assert second.frame_id == "map" and second.pose.x == 3.0
    assert second.polygon.centroid.distance(shapely.Point(3.0, 0.0)) < 1e-3
    np_first = read_navigation(out, position=0).polygon
    assert np_first.centroid.distance(shapely.Point(0.0, 0.0)) < 1e-3
    with pytest.raises(InputError, match="several positions"):
        read_navigation(out)


def test_a_model_set_to_a_folder_writes_a_file_per_position(model_set, tmp_path):
    folder = tmp_path / "maps"
    folder.mkdir()
    result = run("extract", model_set / "index.json", "--heights=-0.5", "-o", f"{folder}/")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in folder.iterdir()) == ["nav_0000.geojson", "nav_0007.geojson"]
    assert read_navigation(folder / "nav_0007.geojson").frame_id == "base_link"


def test_world_needs_a_model_set_and_poses(sphere_inverse, model_set):
    assert run("extract", sphere_inverse, "--world").exit_code == 2
    index = json.loads((model_set / "index.json").read_text())
    index["models"][1]["pose"] = None
    (model_set / "index.json").write_text(json.dumps(index))
    result = run("extract", model_set, "--world")
    assert result.exit_code == 1 and "position 7 has no pose" in result.stderr
    (model_set / "index.json").write_text("{}")
    result = run("extract", model_set)
    assert result.exit_code == 1 and "not an occtool model-set index" in result.stderr


def test_ignore_bounds_cuts_at_the_given_heights_only(fitted_model):
    result = run("extract", fitted_model, "--heights=-0.5,-0.2", "--ignore-bounds")
    assert result.exit_code == 0, result.output
    properties = json.loads(result.stdout)["properties"]
    assert properties["slice_heights"] == properties["heights"] == [-0.5, -0.2]
    assert properties["effective_threshold"] == properties["threshold"] and properties["margin"] == 0.0


def test_no_straight_line_keeps_every_point_where_the_body_fits(sphere_inverse):
    result = run("extract", sphere_inverse, "--heights=-0.5", "--no-straight-line")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["properties"]["straight_line"] is False
