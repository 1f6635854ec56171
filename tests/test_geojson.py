"""Navigation maps written as GeoJSON and read back."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely
from hypothesis import given
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.features import Pose
from occtool.formats.geojson import navigation_features, navigation_to_geojson, read_navigation, write_navigation
from occtool.navigation import navigation_map
from occtool.robot import Robot

ROBOT = Robot(radius=0.25)


def room_with_door(alpha, h, level):
    """A round room of radius 1 m with a 0.8 m doorway straight ahead."""
    alpha, h = np.broadcast_arrays(alpha, h)
    return np.where(np.abs(alpha) < math.asin(0.4), np.inf, np.sqrt(1.0 + np.square(h)))


@pytest.fixture(scope="module")
def nav():
    return navigation_map(room_with_door, robot=ROBOT, heights=[-0.9, -0.5, -0.1], max_range=1.5)


def kinds(collection):
    return [f["properties"]["kind"] for f in collection["features"]]


def test_the_collection_holds_the_polygon_points_and_metadata(nav):
    collection = navigation_to_geojson(nav)
    assert collection["type"] == "FeatureCollection"
    assert kinds(collection).count("navigation") == 1
    assert kinds(collection).count("obstacle") == len(nav.obstacle_points) > 0
    assert kinds(collection).count("exploration") == len(nav.exploration_points) > 0
    for feature in collection["features"]:
        kind = feature["properties"]["kind"]
        if kind in ("obstacle", "exploration"):
            assert feature["geometry"]["type"] == "Point"
            assert feature["properties"]["reinforcement"] == (-1 if kind == "obstacle" else 1)
    properties = collection["properties"]
    assert properties["frame_id"] == "base_link" and properties["units"] == "m"
    assert "not longitude/latitude" in properties["crs_note"]
    assert properties["heights"] == [-0.9, -0.5, -0.1]
    assert properties["threshold"] == 0.6 and properties["effective_threshold"] == 0.6
    assert properties["robot_radius"] == 0.25 and properties["max_range"] == 1.5
    assert properties["sensor_height"] == 1.0 and properties["body_height"] == 1.0
    json.dumps(collection, allow_nan=False)  # strict JSON


def test_the_outer_ring_is_counter_clockwise(nav):
    ring = navigation_to_geojson(nav)["features"][0]["geometry"]["coordinates"][0]
    assert shapely.LinearRing(ring).is_ccw


def test_slices_are_included_on_request(nav):
    collection = navigation_to_geojson(nav, include_slices=True)
    slices = [f for f in collection["features"] if f["properties"]["kind"] == "slice"]
    assert [f["properties"]["height"] for f in slices] == [-0.9, -0.5, -0.1]
    assert "slice" not in kinds(navigation_to_geojson(nav))


@pytest.mark.parametrize("sequence", [False, True])
def test_write_then_read_gives_the_same_map(nav, tmp_path, sequence):
    from dataclasses import replace

    nav = replace(nav, return_snap=0.3)
    path = tmp_path / "nav.geojson"
    write_navigation(nav, path, sequence=sequence, include_slices=True)
    back = read_navigation(path)
    assert back.polygon.equals_exact(nav.polygon, 1e-12)
    np.testing.assert_array_equal(back.obstacle_points, nav.obstacle_points)
    np.testing.assert_array_equal(back.exploration_points, nav.exploration_points)
    assert [s.height for s in back.slices] == [s.height for s in nav.slices]
    assert all(a.polygon.equals_exact(b.polygon, 1e-12) for a, b in zip(back.slices, nav.slices))
    for name in ("threshold", "effective_threshold", "heights", "robot_radius", "max_range", "n_angles",
                 "point_spacing", "sensor_height", "body_height", "frame_id", "straight_line", "return_snap"):
        assert getattr(back, name) == getattr(nav, name), name


def test_a_sequence_is_one_feature_per_line(nav, tmp_path):
    path = tmp_path / "nav.geojsons"
    write_navigation(nav, path, sequence=True)
    lines = path.read_text().splitlines()
    features = [json.loads(line) for line in lines]
    assert len(features) == 1 + len(nav.obstacle_points) + len(nav.exploration_points)
    assert all(f["type"] == "Feature" for f in features)
    # With no collection, the navigation feature carries the map's parameters.
    assert features[0]["properties"]["kind"] == "navigation"
    assert features[0]["properties"]["frame_id"] == "base_link"


def test_record_separators_are_accepted(nav, tmp_path):
    path = tmp_path / "nav.geojsons"
    path.write_text("".join("\x1e" + json.dumps(f) + "\n" for f in navigation_features(nav, with_metadata=True)))
    assert read_navigation(path).polygon.equals_exact(nav.polygon, 1e-12)


def test_precision_rounds_the_coordinates(nav):
    collection = navigation_to_geojson(nav, precision=3)
    coordinates = np.asarray(collection["features"][0]["geometry"]["coordinates"][0])
    np.testing.assert_array_equal(coordinates, np.round(coordinates, 3))
    assert np.abs(coordinates - np.asarray(nav.polygon.exterior.coords)).max() <= 5e-4 + 1e-12


@given(x=st.floats(-50, 50), y=st.floats(-50, 50), yaw=st.floats(-math.pi, math.pi))
def test_a_pose_moves_the_map_into_the_world_frame(x, y, yaw):
    nav = navigation_map(room_with_door, robot=ROBOT, heights=[-0.5], n_angles=72)
    pose = Pose(x=x, y=y, yaw=yaw)
    collection = navigation_to_geojson(nav, pose=pose)
    assert collection["properties"]["frame_id"] == "map"
    assert collection["properties"]["pose"]["yaw"] == yaw
    world = shapely.geometry.shape(collection["features"][0]["geometry"])
    assert world.area == pytest.approx(nav.polygon.area, rel=1e-9)
    assert world.contains(shapely.Point(x, y))
    first_point = collection["features"][1]["geometry"]["coordinates"]
    np.testing.assert_allclose(first_point, pose.to_world(nav.obstacle_points[:1])[0], atol=1e-9)


def test_an_empty_map_round_trips(tmp_path):
    with pytest.warns(UserWarning):
        nav = navigation_map(lambda a, h, m: np.full(np.broadcast(a, h).shape, 0.1), robot=ROBOT)
    path = tmp_path / "empty.geojson"
    write_navigation(nav, path)
    assert json.loads(path.read_text())["features"][0]["geometry"] == {"type": "Polygon", "coordinates": []}
    assert read_navigation(path).polygon.is_empty


def test_writing_to_dash_goes_to_stdout(nav, capsys):
    write_navigation(nav, "-")
    assert json.loads(capsys.readouterr().out)["type"] == "FeatureCollection"


def test_a_failed_write_leaves_no_file(nav, tmp_path):
    path = tmp_path / "nav.geojson"
    broken = navigation_map(room_with_door, robot=ROBOT, heights=[-0.5])
    object.__setattr__(broken, "threshold", float("nan"))  # written as null, fine
    object.__setattr__(broken, "heights", ("not a number",))
    with pytest.raises(ValueError):
        write_navigation(broken, path)
    assert not path.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty"),
        ("{not json", "not valid GeoJSON"),
        ('{"type": "FeatureCollection"}', "'features' list"),
        ('[1, 2]', "not a GeoJSON Feature"),
        ('{"type": "FeatureCollection", "features": []}', "found 0"),
        ('{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"kind": "navigation"},'
         ' "geometry": {"type": "Point", "coordinates": [0, 0]}}]}', "not a Polygon"),
        ('{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"kind": "navigation"},'
         ' "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [1]]]}}]}', "malformed"),
        ('{"type": "FeatureCollection", "properties": {"threshold": "high"}, "features": [{"type": "Feature",'
         ' "properties": {"kind": "navigation"}, "geometry": {"type": "Polygon", "coordinates": []}}]}', "threshold"),
        ('{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"kind": "obstacle"},'
         ' "geometry": {"type": "Point", "coordinates": [NaN, 0]}}]}', "finite"),
        ('{"type": "Feature", "properties": {"kind": "slice"}, "geometry": null}', "height"),
        ('{"type": "Feature", "properties": {"kind": "exploration"}, "geometry": {"type": "Point", "coordinates": []}}',
         "no coordinates"),
        ('{"type": "Feature", "properties": {"kind": "navigation"}, "geometry": {"type": "Polygon", "coordinates": []}}\n'  # noqa: E501
         '{"type": "Feature", "properties": {"kind": "navigation"}, "geometry": {"type": "Polygon", "coordinates": []}}',  # noqa: E501
         "found 2"),
    ],
)
def test_malformed_files_are_rejected_with_the_reason(tmp_path, text, message):
    path = tmp_path / "bad.geojson"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as raised:
        read_navigation(path)
    assert str(path) in str(raised.value)


# ---------------------------------------------------------------- the layers of a run's map
def small_run_map():
    """A run map's layers by hand: a region of two parts, one with a hole and a clockwise
    shell, points that need rounding (the raster and world map are not written here)."""
    from occtool.fuse import RunMap

    hollow = shapely.Polygon([(0, 0), (0, 2.00049), (3.123456, 2), (3, 0)],  # clockwise shell
                             [[(1, 0.5), (2, 0.5), (2, 1.5), (1, 1.5)]])
    region = shapely.MultiPolygon([hollow, shapely.box(4.0, 0.0, 4.5, 0.75)])
    obstacles = np.array([[0.123456, -0.5], [3.5, 2.987654321]])
    frontiers = np.array([[4.25, 1.0004999]])
    return RunMap(fused=None, world=None, raster=None, placed=[], navigation=region,
                  obstacles=obstacles, frontiers=frontiers)


def test_the_run_map_layers_say_what_they_hold():
    from occtool.formats.geojson import run_map_layers

    run = small_run_map()
    layers = run_map_layers(run.navigation, run.obstacles, run.frontiers, precision=3)
    navigation = layers["navigation"]["features"]
    assert [f["geometry"]["type"] for f in navigation] == ["Polygon", "Polygon"]
    shell, hole = (shapely.LinearRing(ring) for ring in navigation[0]["geometry"]["coordinates"])
    assert len(navigation[0]["geometry"]["coordinates"]) == 2 and hole.is_valid
    assert shapely.Polygon(shell, [hole]).area == pytest.approx(run.navigation.geoms[0].area, abs=0.01)
    assert [f["geometry"]["coordinates"] for f in layers["obstacles"]["features"]] == [[0.123, -0.5], [3.5, 2.988]]
    assert [f["geometry"]["coordinates"] for f in layers["frontiers"]["features"]] == [[4.25, 1.0]]
    for name, kind in (("navigation", "navigation"), ("obstacles", "obstacle"), ("frontiers", "frontier")):
        assert layers[name]["properties"]["kind"] == kind
        assert layers[name]["properties"]["frame"] == "map" and layers[name]["properties"]["units"] == "m"
        assert {f["properties"]["kind"] for f in layers[name]["features"]} == {kind}
    # At full precision the rings follow RFC 7946: the clockwise shell is turned.
    full = run_map_layers(run.navigation, run.obstacles, run.frontiers)["navigation"]["features"]
    assert shapely.LinearRing(full[0]["geometry"]["coordinates"][0]).is_ccw
    assert not shapely.LinearRing(full[0]["geometry"]["coordinates"][1]).is_ccw


def test_the_run_map_layers_in_wgs84():
    pytest.importorskip("pyproj")
    from occtool.formats.geojson import run_map_layers
    from occtool.formats.wgs84 import Georeference

    run = small_run_map()
    where = Georeference(48.0, 7.8, 30.0)
    layers = run_map_layers(run.navigation, run.obstacles, run.frontiers, georeference=where, precision=7)
    assert layers["obstacles"]["properties"]["frame"] == "WGS84"
    lon, lat = layers["frontiers"]["features"][0]["geometry"]["coordinates"]
    assert lon == pytest.approx(7.8, abs=1e-3) and lat == pytest.approx(48.0, abs=1e-3)


def test_a_negative_simplify_tolerance_is_one_line():
    from occtool.formats.geojson import run_map_layers

    run = small_run_map()
    with pytest.raises(InputError, match="simplify tolerance must be a number of metres >= 0, got -1"):
        run_map_layers(run.navigation, run.obstacles, run.frontiers, simplify=-1.0)


def test_a_collection_is_dumped_without_the_cyclic_collector_and_leaves_it_as_it_was():
    """Each feature of a dumped collection is made and encoded with the cyclic collector
    paused (its lists go with their reference counts); the collector is left as found, a
    paused block inside another does not start it, and the text is json.dump's."""
    import gc
    import io
    import json

    from occtool.formats.geojson import dump_collection
    from occtool.limits import collector_paused

    seen = []

    def features():
        for k in range(3):
            seen.append(gc.isenabled())
            yield {"type": "Feature", "properties": {"k": k}, "geometry": {"type": "Point", "coordinates": [k, 0.5]}}

    assert gc.isenabled()
    written, expected = io.StringIO(), io.StringIO()
    dump_collection({"type": "FeatureCollection", "features": features()}, written)
    json.dump({"type": "FeatureCollection", "features": list(features())}, expected, separators=(",", ":"))
    assert written.getvalue() == expected.getvalue() and seen[:3] == [False] * 3 and gc.isenabled()
    with collector_paused():
        with collector_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()
    assert gc.isenabled()
    gc.disable()
    try:
        with collector_paused():
            pass
        assert not gc.isenabled()
    finally:
        gc.enable()
