"""End-to-end tests of `occtool plot`: real files in, pictures of the right size, format and content out."""

from __future__ import annotations

import json
import re
import struct
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from click.testing import CliRunner

pytest.importorskip("matplotlib")

from occtool.cli.main import cli  # noqa: E402
from occtool.features import Pose, Position, RangeLog  # noqa: E402
from occtool.fit import OccupancyRegressor  # noqa: E402
from occtool.formats.geojson import write_navigation, write_navigation_set  # noqa: E402
from occtool.formats.model import save_model  # noqa: E402
from occtool.io import write_csv  # noqa: E402
from occtool.navigation import navigation_map  # noqa: E402
from occtool.robot import Robot  # noqa: E402
from occtool.simulate import simulate_scene  # noqa: E402
from occtool.tree import MinMaxTree, Op  # noqa: E402

SVG_NS = "{http://www.w3.org/2000/svg}"


def run(*args: str):
    return CliRunner().invoke(cli, ["-q", *map(str, args)], catch_exceptions=False)


def png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def svg_points(svg: bytes, gid: str) -> np.ndarray:
    root = ET.fromstring(svg)
    group = next(g for g in root.iter(f"{SVG_NS}g") if g.get("id") == gid)
    numbers = [float(v) for p in group.iter(f"{SVG_NS}path")
               for v in re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", p.get("d"))]
    return np.asarray(numbers).reshape(-1, 2)


@pytest.fixture(scope="module")
def scene_files(tmp_path_factory):
    """A small simulated office: its features as CSV, its truth, and a map extracted from a known model."""
    folder = tmp_path_factory.mktemp("plot")
    features, scene = simulate_scene("office", n_features=400, seed=3)
    write_csv(features, folder / "features.csv")
    scene.save_truth(folder / "truth.json")
    # F = max(r - 1.2 + 0.1 cos(alpha), 0.1): free out to about 1.7 m, shaped by the pan angle.
    tree = MinMaxTree("trig", [[0.1, 0.0, 0.0, 1.0, -1.2], [0.0, 0.0, 0.0, 1e-6, 0.1]], Op("max", (0, 1)))
    nav = navigation_map(tree.inverse().range, robot=Robot(), threshold=0.6, max_range=1.5, n_angles=120)
    write_navigation(nav, folder / "nav.geojson", include_slices=True)
    save_model(OccupancyRegressor(pieces=6, max_sweeps=3).fit(features), folder / "model.json")
    return {"folder": folder, "features": folder / "features.csv", "truth": folder / "truth.json",
            "nav": folder / "nav.geojson", "map": nav, "model": folder / "model.json"}


def test_features_png_has_the_requested_pixel_size(scene_files, tmp_path):
    output = tmp_path / "a.png"
    result = run("plot", "features", scene_files["features"], "-o", output, "--size", "320,240px", "--dpi", "80")
    assert result.exit_code == 0, result.output
    assert result.output.strip() == str(output)
    assert png_size(output.read_bytes()) == (320, 240)
    assert output.stat().st_size > 5000  # a picture, not a blank page


def test_model_png_with_pieces(scene_files, tmp_path):
    output = tmp_path / "b.png"
    result = run("plot", "model", scene_files["model"], "-o", output, "--level", "0.5", "--height", "-0.3",
                 "--heights", "-0.9,-0.3", "--pieces", "--resolution", "40", "--size", "9,3", "--dpi", "40")
    assert result.exit_code == 0, result.output
    assert png_size(output.read_bytes()) == (360, 120)


def test_model_level_outside_the_unit_interval_is_a_usage_error(scene_files, tmp_path):
    result = run("plot", "model", scene_files["model"], "-o", tmp_path / "b.png", "--level", "1.5")
    assert result.exit_code == 2 and "--level" in result.output


def test_nav_svg_polygon_has_the_geojson_extent(scene_files, tmp_path):
    output = tmp_path / "c.svg"
    result = run("plot", "nav", scene_files["nav"], "--features", scene_files["features"],
                 "--truth", scene_files["truth"], "-o", output, "--size", "5,5")
    assert result.exit_code == 0, result.output
    svg = output.read_bytes()
    root = ET.fromstring(svg)
    assert (root.get("width"), root.get("height")) == ("360pt", "360pt")
    # The max-range circle (radius 1.5 m about the robot) gives the drawing's scale and origin.
    circle = svg_points(svg, "max-range")
    centre = (circle.min(axis=0) + circle.max(axis=0)) / 2
    metres_per_unit = 1.5 / ((circle[:, 0].max() - circle[:, 0].min()) / 2)
    polygon = svg_points(svg, "navigation")
    x = (polygon[:, 0] - centre[0]) * metres_per_unit
    y = (centre[1] - polygon[:, 1]) * metres_per_unit  # SVG y runs down
    np.testing.assert_allclose([x.min(), y.min(), x.max(), y.max()], scene_files["map"].polygon.bounds, atol=0.02)
    ids = {g.get("id") for g in root.iter(f"{SVG_NS}g")}
    assert {"features", "truth", "obstacles", "exploration", "robot"} <= ids
    assert any(i.startswith("slice") for i in ids if i)


def test_nav_of_a_folder_of_world_frame_maps_draws_the_path(scene_files, tmp_path):
    folder = tmp_path / "maps"
    folder.mkdir()
    for index, pose in enumerate([Pose(0, 0, 0, 0), Pose(1.5, 0.5, 0, 0.5), Pose(3, 1, 0, 1.0)]):
        write_navigation(scene_files["map"], folder / f"nav{index}.geojson", pose=pose)
    output = tmp_path / "path.pdf"
    result = run("plot", "nav", folder, "-o", output)
    assert result.exit_code == 0, result.output
    assert output.read_bytes().startswith(b"%PDF")


@pytest.mark.parametrize("sequence", [False, True])
def test_nav_of_a_model_set_file_places_each_map_at_its_position(scene_files, tmp_path, sequence):
    poses = {0: Pose(0.0, 0.0, 0.0, 0.0), 1: Pose(2.0, 1.0, 0.0, 0.5)}
    features, _ = simulate_scene("corridor", n_features=100, seed=5)
    write_csv(RangeLog([Position(i, features, pose) for i, pose in poses.items()]), tmp_path / "log.csv")
    write_navigation_set([(i, scene_files["map"]) for i in poses], tmp_path / "set.geojson", sequence=sequence)
    output = tmp_path / "path.svg"
    result = run("plot", "nav", tmp_path / "set.geojson", "--features", tmp_path / "log.csv", "-o", output)
    assert result.exit_code == 0, result.output
    root = ET.fromstring(output.read_bytes())
    assert [g.get("id") for g in root.iter(f"{SVG_NS}g")].count("navigation") == 2
    # The second map sits 2 m east and 1 m north of the first: compare the drawn polygons' centres.
    centres = [svg_points(ET.tostring(g), "navigation").mean(axis=0) for g in root.iter(f"{SVG_NS}g")
               if g.get("id") == "navigation"]
    circle = svg_points(output.read_bytes(), "max-range")
    metres_per_unit = 1.5 / ((circle[:, 0].max() - circle[:, 0].min()) / 2)
    shift = (centres[1] - centres[0]) * metres_per_unit * np.array([1.0, -1.0])  # SVG y runs down
    centre = np.asarray(scene_files["map"].polygon.exterior.coords)[:-1].mean(axis=0)
    np.testing.assert_allclose(shift, poses[1].to_world(centre)[0] - centre, atol=0.03)


def test_compare_report_with_bench_renders(tmp_path):
    report = {
        "features": 400,
        "models": {
            "parametric": {
                "samples": 2000,
                "build_s": 0.3,
                "extract_s": 0.02,
                "memory_bytes": 5000,
                "file_bytes": 3000,
            },
            "grid": {"samples": 50000, "build_s": 2.0, "extract_s": 0.2, "memory_bytes": 2**22, "file_bytes": 2**20},
        },
        "polygons": {
            "parametric": {"type": "Polygon", "coordinates": [[[1, 0], [0, 1], [-1, 0], [0, -1], [1, 0]]]},
            "grid": {"type": "Polygon", "coordinates": [[[1, 1], [-1, 1], [-1, -1], [1, -1], [1, 1]]]},
        },
    }
    bench = {"scaling": [{"scale": s, "features": 500 * s,
                          "models": {"parametric": {"build_s": 0.1 * s, "memory_bytes": 4000},
                                     "grid": {"build_s": 0.5 * s * s, "memory_bytes": 2**20 * s}}} for s in (1, 2, 4)]}
    (tmp_path / "report.json").write_text(json.dumps(report))
    (tmp_path / "bench.json").write_text(json.dumps(bench))
    output = tmp_path / "d.png"
    result = run("plot", "compare", tmp_path / "report.json", "--bench", tmp_path / "bench.json", "-o", output,
                 "--size", "8,6", "--dpi", "50")
    assert result.exit_code == 0, result.output
    assert png_size(output.read_bytes()) == (400, 300)


def test_unsupported_extension_fails_fast_with_the_formats_and_writes_nothing(scene_files, tmp_path):
    result = run("plot", "features", scene_files["features"], "-o", tmp_path / "a.jpg")
    assert result.exit_code == 1
    assert result.output.startswith("Error:") and "PNG, SVG, PDF" in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("arguments, message", [
    (["--size", "wide"], "is not W,H"),
    (["--size", "0,3"], "positive"),
])
def test_bad_sizes_are_one_line_errors(scene_files, tmp_path, arguments, message):
    result = run("plot", "nav", scene_files["nav"], "-o", tmp_path / "c.png", *arguments)
    assert result.exit_code == 1 and message in result.output
    assert not (tmp_path / "c.png").exists()


def test_malformed_inputs_are_one_line_errors_naming_the_file(tmp_path):
    broken = tmp_path / "report.json"
    broken.write_text('{"models": ')
    result = run("plot", "compare", broken, "-o", tmp_path / "d.png")
    assert result.exit_code == 1 and "report.json" in result.output and "Traceback" not in result.output
    nav = tmp_path / "nav.geojson"
    nav.write_text(json.dumps({"type": "FeatureCollection", "features": []}))
    result = run("plot", "nav", nav, "-o", tmp_path / "c.png")
    assert result.exit_code == 1 and "nav.geojson" in result.output and "navigation" in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nav.geojson", "report.json"]


def test_missing_matplotlib_is_explained(scene_files, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    result = run("plot", "nav", scene_files["nav"], "-o", tmp_path / "c.png")
    assert result.exit_code == 1
    assert "Plotting needs the optional package 'matplotlib'" in result.output
    assert "pip install 'occtool[plot]'" in result.output


def test_missing_input_is_a_usage_error(tmp_path):
    result = run("plot", "nav", tmp_path / "absent.geojson", "-o", tmp_path / "c.png")
    assert result.exit_code == 2 and "does not exist" in result.output
