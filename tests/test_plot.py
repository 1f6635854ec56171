"""Tests of occtool.plot: formats, sizes, atomic output, and that what is drawn is where the data says."""

from __future__ import annotations

import math
import re
import struct
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("matplotlib")

from shapely import affinity  # noqa: E402
from shapely.geometry import Point, Polygon, mapping  # noqa: E402

from occtool import plot  # noqa: E402
from occtool.errors import InputError, MissingDependencyError, ModelFormatError  # noqa: E402
from occtool.features import Features, Pose, Position, RangeLog  # noqa: E402
from occtool.formats.geojson import write_navigation  # noqa: E402
from occtool.navigation import NavigationMap, Slice, navigation_map  # noqa: E402
from occtool.robot import Robot  # noqa: E402
from occtool.tree import MinMaxTree, Op  # noqa: E402

SMALL = (3.0, 2.5)
DPI = 40.0
SVG_NS = "{http://www.w3.org/2000/svg}"


# --- helpers ---------------------------------------------------------------------------------


def png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def hand_map(polygon: Polygon, *, obstacles=((0.6, 0.1),), exploration=((-1.0, 0.0), (0.0, 1.0)),
             slices=((-0.9, 1.1), (-0.4, 1.05))) -> NavigationMap:
    """A robot-frame navigation map with known geometry."""
    return NavigationMap(
        polygon=polygon,
        slices=[Slice(h, Point(0, 0).buffer(radius, 16)) for h, radius in slices],
        obstacle_points=np.asarray(obstacles, float).reshape(-1, 2),
        exploration_points=np.asarray(exploration, float).reshape(-1, 2),
        threshold=0.6, effective_threshold=0.6, heights=tuple(h for h, _ in slices), robot_radius=0.25,
        max_range=1.2, n_angles=360, point_spacing=0.25,
    )


def notched_disc() -> Polygon:
    return Point(0, 0).buffer(1.0, 32).difference(Point(1.0, 0.2).buffer(0.45, 16))


def ring_features(n: int = 200, seed: int = 0) -> Features:
    rng = np.random.default_rng(seed)
    angle = rng.uniform(-np.pi, np.pi, n)
    distance = rng.uniform(1.0, 3.0, n)
    return Features.from_xyz(distance * np.cos(angle), distance * np.sin(angle), rng.uniform(-1.0, 0.5, n),
                             rng.uniform(0.0, 1.0, n))


def svg_path_points(d: str) -> np.ndarray:
    numbers = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", d)]
    return np.asarray(numbers).reshape(-1, 2)


def svg_group_points(svg: bytes, gid: str) -> np.ndarray:
    root = ET.fromstring(svg)
    group = next(g for g in root.iter(f"{SVG_NS}g") if g.get("id") == gid)
    return np.concatenate([svg_path_points(p.get("d")) for p in group.iter(f"{SVG_NS}path")])


def data_bounds_from_svg(figure, svg: bytes, gid: str) -> tuple[float, float, float, float]:
    """Map an SVG group's path back into data coordinates through the axes' frame in the SVG."""
    ax = figure.axes[0]
    frame = svg_group_points(svg, "axes-frame")
    left, right = frame[:, 0].min(), frame[:, 0].max()
    top, bottom = frame[:, 1].min(), frame[:, 1].max()
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    points = svg_group_points(svg, gid)
    x = x0 + (points[:, 0] - left) / (right - left) * (x1 - x0)
    y = y0 + (bottom - points[:, 1]) / (bottom - top) * (y1 - y0)  # SVG y grows downwards
    return x.min(), y.min(), x.max(), y.max()


# --- formats, sizes and files ---------------------------------------------------------------


@pytest.mark.parametrize("name, expected", [("a.png", "png"), ("b.SVG", "svg"), ("dir.x/c.Pdf", "pdf")])
def test_output_format_follows_the_extension(name, expected):
    assert plot.output_format(name) == expected


@pytest.mark.parametrize("name", ["a.jpg", "b", "c.png.txt"])
def test_unsupported_extension_names_the_supported_formats(name):
    with pytest.raises(InputError, match="PNG, SVG, PDF"):
        plot.output_format(name)


@pytest.mark.parametrize("text, dpi, expected", [("7,6", 100, (7.0, 6.0)), ("800,600px", 100, (8.0, 6.0)),
                                                 ("300x150px", 50, (6.0, 3.0)), (" 4.5, 3 ", 72, (4.5, 3.0))])
def test_parse_size_in_inches_or_pixels(text, dpi, expected):
    assert plot.parse_size(text, dpi) == pytest.approx(expected)


@given(width=st.integers(1, 5000), height=st.integers(1, 5000), dpi=st.floats(10, 600))
def test_a_pixel_size_gives_those_pixels_back(width, height, dpi):
    inches = plot.parse_size(f"{width}x{height}px", dpi)
    assert inches[0] * dpi == pytest.approx(width) and inches[1] * dpi == pytest.approx(height)


@pytest.mark.parametrize("text", ["7", "a,b", "0,5", "-1,2", "1,2,3", "nan,2"])
def test_parse_size_rejects_bad_sizes(text):
    with pytest.raises(InputError):
        plot.parse_size(text)


def test_every_format_has_the_requested_size(tmp_path):
    figure = plot.new_figure((3.0, 2.0), dpi=50)
    figure.add_subplot().plot([0, 1], [0, 1])
    png = plot.save_figure(figure, tmp_path / "a.png").read_bytes()
    assert png_size(png) == (150, 100)
    svg = ET.fromstring(plot.save_figure(figure, tmp_path / "a.svg").read_bytes())
    assert svg.get("width") == "216pt" and svg.get("height") == "144pt"  # 72 points per inch
    pdf = plot.save_figure(figure, tmp_path / "a.pdf").read_bytes()
    assert pdf.startswith(b"%PDF")
    box = re.search(rb"/MediaBox \[\s*0 0 ([\d.]+) ([\d.]+)\s*\]", pdf)
    assert box and (float(box.group(1)), float(box.group(2))) == (216.0, 144.0)


def test_a_failed_render_leaves_the_old_file_and_no_temporary(tmp_path):
    from matplotlib.artist import Artist

    class Broken(Artist):
        def draw(self, renderer):
            raise RuntimeError("renderer failed")

    target = tmp_path / "out.png"
    target.write_bytes(b"old picture")
    figure = plot.new_figure(SMALL, DPI)
    figure.add_subplot().add_artist(Broken())
    with pytest.raises(RuntimeError, match="renderer failed"):
        plot.save_figure(figure, target)
    assert target.read_bytes() == b"old picture"
    assert [p.name for p in tmp_path.iterdir()] == ["out.png"]


def test_unsupported_extension_writes_nothing(tmp_path):
    figure = plot.new_figure(SMALL, DPI)
    with pytest.raises(InputError):
        plot.save_figure(figure, tmp_path / "out.gif")
    assert list(tmp_path.iterdir()) == []


def test_missing_matplotlib_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(MissingDependencyError, match=r"pip install 'occtool\[plot\]'"):
        plot.require_matplotlib()


def test_figures_do_not_touch_pyplot_state():
    before = sys.modules.get("matplotlib.pyplot")
    plot.features_figure(RangeLog([Position(0, ring_features(20))]), size=SMALL, dpi=DPI)
    if before is None:
        assert "matplotlib.pyplot" not in sys.modules
    else:
        assert before.get_fignums() == []


# --- navigation maps --------------------------------------------------------------------------


def test_a_map_extracted_from_a_model_round_trips_through_geojson_into_the_picture(tmp_path):
    tree = radial_tree()
    nav = navigation_map(tree.inverse().range, robot=Robot(), threshold=0.6, max_range=1.5, n_angles=90)
    path = tmp_path / "nav.geojson"
    write_navigation(nav, path, include_slices=True)
    figure = plot.navigation_figure([plot.read_navigation(path)], source=str(path), size=SMALL, dpi=DPI)
    ax = figure.axes[0]
    drawn = next(p for p in ax.patches if p.get_gid() == "navigation").get_path().vertices
    np.testing.assert_allclose([*drawn.min(axis=0), *drawn.max(axis=0)], nav.polygon.bounds, atol=1e-9)
    assert len([p for p in ax.patches if (p.get_gid() or "").startswith("slice")]) == len(nav.slices) > 0
    assert "nav.geojson" in ax.get_title() and "threshold 0.6" in ax.get_title()


def test_polygon_with_a_hole_renders_its_hole():
    from matplotlib.patches import PathPatch

    # Shell and hole both counter-clockwise, as some writers leave them.
    angles = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    circle = np.column_stack([np.cos(angles), np.sin(angles)])
    ring = Polygon(2.0 * circle, [0.3 * circle + (0.5, 0.0)])
    figure = plot.new_figure((1.0, 1.0), dpi=100)
    figure.set_layout_engine("none")
    ax = figure.add_axes((0, 0, 1, 1))
    ax.set_axis_off()
    ax.set_xlim(-2, 2)
    ax.set_ylim(-2, 2)
    ax.add_patch(PathPatch(plot.geometry_path(ring), facecolor="black", edgecolor="none"))
    figure.canvas.draw()
    pixels = np.asarray(figure.canvas.buffer_rgba())[:, :, :3].mean(axis=2)

    def at(x: float, y: float) -> float:
        return pixels[int(round((2 - y) / 4 * 99)), int(round((x + 2) / 4 * 99))]

    assert at(0.5, 0.0) > 200  # the hole stays white
    assert at(-1.0, 0.0) < 50  # the shell is filled


radii = st.lists(st.floats(0.3, 3.0), min_size=5, max_size=24)
poses = st.builds(Pose, x=st.floats(-20, 20), y=st.floats(-20, 20), yaw=st.floats(-np.pi, np.pi))


@settings(max_examples=30)
@given(radii=radii, pose=poses)
def test_drawn_polygon_matches_the_geojson_in_any_pose(radii, pose):
    angles = np.linspace(0, 2 * np.pi, len(radii), endpoint=False)
    polygon = Polygon(np.column_stack([np.cos(angles) * radii, np.sin(angles) * radii]))
    nav = hand_map(polygon)
    figure = plot.new_figure(SMALL, DPI)
    artists = plot.draw_navigation(figure.add_subplot(), nav, pose=pose)
    drawn = artists["navigation"].get_path().vertices
    moved = affinity.translate(affinity.rotate(polygon, pose.yaw, origin=(0, 0), use_radians=True), pose.x, pose.y)
    np.testing.assert_allclose([*drawn.min(axis=0), *drawn.max(axis=0)], moved.bounds, atol=1e-9)
    obstacles = artists["obstacles"].get_offsets()
    np.testing.assert_allclose(obstacles, pose.to_world(nav.obstacle_points), atol=1e-9)
    assert artists["range"].center == pytest.approx((pose.x, pose.y))


def test_navigation_figure_svg_polygon_extent_matches_the_geojson():
    polygon = notched_disc()
    nav = hand_map(polygon)
    figure = plot.navigation_figure([nav], size=(5.0, 5.0), dpi=DPI)
    import io

    buffer = io.BytesIO()
    figure.savefig(buffer, format="svg")
    bounds = data_bounds_from_svg(figure, buffer.getvalue(), "navigation")
    np.testing.assert_allclose(bounds, polygon.bounds, atol=0.01)
    legend = [t.get_text() for t in figure.legends[0].get_texts()]
    assert any("obstacle points (1, reinforcement -1)" in t for t in legend)
    assert any("exploration points (2, reinforcement +1)" in t for t in legend)
    assert any("navigation area (F < 0.6)" in t for t in legend)
    title = figure.axes[0].get_title()
    assert "threshold 0.6" in title and "-0.90, -0.40 m" in title and "robot radius 0.25 m" in title


def test_several_positions_are_drawn_in_the_world_frame_along_the_path():
    polygon = notched_disc()
    poses_ = [Pose(0.0, 0.0, 0.0, 0.0), Pose(2.0, 1.0, 0.0, np.pi / 2)]
    maps = [hand_map(polygon).in_world(p) for p in poses_]
    figure = plot.navigation_figure(maps, size=SMALL, dpi=DPI)
    ax = figure.axes[0]
    patches = [p for p in ax.patches if p.get_gid() == "navigation"]
    assert len(patches) == 2
    second = patches[1].get_path().vertices
    turned = affinity.translate(affinity.rotate(polygon, 90, origin=(0, 0)), 2.0, 1.0)
    np.testing.assert_allclose([*second.min(axis=0), *second.max(axis=0)], turned.bounds, atol=1e-9)
    path = next(line for line in ax.lines if line.get_gid() == "path")
    np.testing.assert_allclose(path.get_xydata(), [[0, 0], [2, 1]])
    assert not any(p.get_gid().startswith("slice") for p in ax.patches)
    assert "2 positions, map frame" in ax.get_title()


def test_several_maps_without_poses_are_refused():
    nav = hand_map(notched_disc())
    with pytest.raises(InputError, match="no pose for each"):
        plot.navigation_figure([nav, nav], size=SMALL, dpi=DPI)


def test_truth_obstacles_are_drawn_where_the_scene_has_them():
    from occtool.simulate import build_scene

    scene = build_scene("office")
    nav = hand_map(notched_disc())
    figure = plot.navigation_figure([nav], truth=scene, size=SMALL, dpi=DPI)
    truth = [p for p in figure.axes[0].patches if p.get_gid() in ("truth", "truth-passable")]
    assert len(truth) == len(scene.obstacles)
    for patch, obstacle in zip(truth, scene.obstacles):
        np.testing.assert_allclose(patch.get_path().vertices.min(axis=0), obstacle.polygon.bounds[:2], atol=1e-12)
        blocks = obstacle.z_min < scene.robot.body_height and obstacle.z_max > scene.robot.ground_clearance
        assert (patch.get_gid() == "truth") == blocks


# --- features -------------------------------------------------------------------------------


def test_features_are_projected_on_the_floor_brightest_on_top():
    features = ring_features(300)
    figure = plot.features_figure(RangeLog([Position(0, features)], source="ring.csv"), size=SMALL, dpi=DPI)
    ax = figure.axes[0]
    scatter = next(c for c in ax.collections if c.get_gid() == "features")
    offsets = scatter.get_offsets()
    order = np.argsort(features.evidence, kind="stable")
    np.testing.assert_allclose(offsets, features.points[order, :2])
    assert np.all(np.diff(scatter.get_array()) >= 0)  # higher evidence drawn later, on top
    brightness = scatter.to_rgba(np.array([0.1, 0.9]))[:, :3].mean(axis=1)
    assert brightness[1] > brightness[0]
    assert any(p.get_gid() == "robot" and p.center == (0.0, 0.0) for p in ax.patches)
    assert "ring.csv" in ax.get_title() and "300 features" in ax.get_title()
    assert ax.get_aspect() == 1.0


def test_a_multi_position_log_is_drawn_in_the_world_frame():
    parts = [ring_features(50, seed) for seed in (1, 2)]
    poses_ = [Pose(0.0, 0.0, 0.0, 0.0), Pose(4.0, -1.0, 0.0, 1.0)]
    log = RangeLog([Position(i, f, p) for i, (f, p) in enumerate(zip(parts, poses_))])
    figure = plot.features_figure(log, size=SMALL, dpi=DPI)
    scatter = next(c for c in figure.axes[0].collections if c.get_gid() == "features")
    world = np.concatenate([p.to_world(f.points[:, :2]) for f, p in zip(parts, poses_)])
    evidence = np.concatenate([f.evidence for f in parts])
    np.testing.assert_allclose(scatter.get_offsets(), world[np.argsort(evidence, kind="stable")])
    path = next(line for line in figure.axes[0].lines if line.get_gid() == "path")
    np.testing.assert_allclose(path.get_xydata(), [[0.0, 0.0], [4.0, -1.0]])
    single = plot.features_figure(log, position=1, size=SMALL, dpi=DPI)
    assert "position 1" in single.axes[0].get_title()


def test_a_multi_position_log_without_poses_asks_for_a_position():
    log = RangeLog([Position(0, ring_features(10)), Position(1, ring_features(10, 3))], source="two.csv")
    with pytest.raises(InputError, match="position=N"):
        plot.features_figure(log, size=SMALL, dpi=DPI)


# --- models ---------------------------------------------------------------------------------


def radial_tree() -> MinMaxTree:
    """F = max(r - 1, 0.2 + 0.1 alpha-free constant): piece 0 rises with r, piece 1 is flat at 0.2."""
    return MinMaxTree("linear", [[0.0, 0.0, 1.0, -1.0], [0.0, 0.0, 1e-6, 0.2]], Op("max", (0, 1)))


def test_projection_keeps_exactly_the_samples_above_the_level():
    tree = radial_tree()
    xy, values = plot.occupied_projection(tree, 0.4, heights=[-0.5, 0.0], max_range=3.0, angles=36, ranges=30)
    assert len(xy) > 0 and np.all(values > 0.4)
    # F = r - 1 > 0.4 means r > 1.4; the horizontal distance is sqrt(r^2 - h^2) >= sqrt(1.4^2 - 0.5^2).
    distance = np.hypot(xy[:, 0], xy[:, 1])
    assert distance.min() > np.sqrt(1.4**2 - 0.25) - 1e-9
    assert distance.max() == pytest.approx(3.0)
    # At h = 0 every sample beyond 1.4 m is kept: 36 angles x the ranges in (1.4, 3].
    horizontal = np.linspace(0.1, 3.0, 30)
    assert np.sum(np.isclose(values, horizontal[horizontal > 1.4][0] - 1.0)) == 36


def test_heatmap_is_the_model_at_the_chosen_height():
    tree = radial_tree()
    x, y, values = plot.evaluate_on_floor_grid(tree, -0.5, extent=2.0, resolution=8)
    gx, gy = np.meshgrid(x, y)
    expected = tree.predict(np.arctan2(gy, gx), -0.5, np.sqrt(gx**2 + gy**2 + 0.25))
    np.testing.assert_allclose(values, expected)
    assert x[0] == pytest.approx(-1.75) and x[-1] == pytest.approx(1.75)


def test_model_figure_colours_regions_by_active_piece():
    tree = radial_tree()
    figure = plot.model_figure(tree, level=0.4, height=0.0, extent=2.0, pieces=True, resolution=20,
                               source="m.json", size=(6, 2.5), dpi=DPI)
    pieces = next(im for ax in figure.axes for im in ax.images if im.get_gid() == "active-pieces")
    array = np.asarray(pieces.get_array())
    axis = -2.0 + 0.2 * (np.arange(20) + 0.5)
    gx, gy = np.meshgrid(axis, axis)
    # max(r - 1, 0.2) takes piece 1 while r < 1.2 and piece 0 beyond.
    np.testing.assert_array_equal(array, np.where(np.hypot(gx, gy) > 1.2, 0, 1))
    assert "2 linear pieces" in figure.get_suptitle() and "level 0.4" in figure.get_suptitle()
    heat = next(im for ax in figure.axes for im in ax.images if im.get_gid() == "occupancy-heatmap")
    assert heat.get_extent() == [-2.0, 2.0, -2.0, 2.0]


def test_pieces_panel_needs_a_model_that_can_tell():
    class Smooth:
        def predict(self, alpha, h, r):
            return np.clip(np.asarray(r) / 4.0, 0, 1)

    with pytest.raises(InputError, match="linear piece"):
        plot.model_figure(Smooth(), pieces=True, size=SMALL, dpi=DPI)
    figure = plot.model_figure(Smooth(), level=0.5, extent=3.0, resolution=10, size=SMALL, dpi=DPI)
    assert len([ax for ax in figure.axes if ax.images or ax.collections]) >= 2


def test_level_outside_the_unit_interval_is_refused():
    with pytest.raises(InputError, match="level"):
        plot.model_figure(radial_tree(), level=1.5)


# --- comparison report ----------------------------------------------------------------------


def report(with_polygons: bool = True) -> dict:
    document = {
        "features": 500,
        "models": {"parametric": {"samples": 2500, "build_s": 0.2, "extract_s": 0.01, "memory_bytes": 4096,
                                  "file_bytes": 2000},
                   "grid": {"samples": 90000, "build_s": 1.5, "extract_s": 0.3, "memory_bytes": 8 * 2**20,
                            "file_bytes": 10**6}},
    }
    if with_polygons:
        document["polygons"] = {"parametric": mapping(notched_disc()), "grid": mapping(Point(0, 0).buffer(0.8, 8))}
    return document


BENCH = [{"scale": s, "features": 1000 * s,
          "models": {"parametric": {"build_s": 0.1 * s, "extract_s": 0.01, "memory_bytes": 10_000},
                     "grid": {"build_s": s * s, "extract_s": 0.1 * s, "memory_bytes": 2**20 * s * s}}}
         for s in (1, 2, 4, 8)]


def test_compare_draws_each_models_polygon_and_the_scaling_curves():
    figure = plot.compare_figure(report(), bench=BENCH, source="cmp.json", size=(8, 5), dpi=DPI)
    polygons = {p.get_gid(): p for ax in figure.axes for p in ax.patches if (p.get_gid() or "").startswith("polygon")}
    assert set(polygons) == {"polygon-parametric", "polygon-grid"}
    vertices = polygons["polygon-parametric"].get_path().vertices
    np.testing.assert_allclose([*vertices.min(axis=0), *vertices.max(axis=0)], notched_disc().bounds, atol=1e-12)
    lines = {line.get_gid(): line for ax in figure.axes for line in ax.lines if line.get_gid()}
    grid_time = lines["time-grid-features"]
    np.testing.assert_allclose(grid_time.get_xdata(), [1000, 2000, 4000, 8000])
    np.testing.assert_allclose(grid_time.get_ydata(), [1.1, 4.2, 16.4, 64.8])
    np.testing.assert_allclose(lines["memory-grid-scale"].get_ydata(), [1, 4, 16, 64])
    assert all(ax.get_xscale() == "log" and ax.get_yscale() == "log" for ax in grid_time.axes.figure.axes
               if any((line.get_gid() or "").startswith(("time", "memory")) for line in ax.lines))
    assert "cmp.json" in figure.get_suptitle() and "500 features" in figure.get_suptitle()


def test_compare_without_polygons_or_bench_draws_the_report_numbers():
    figure = plot.compare_figure(report(with_polygons=False), size=SMALL, dpi=DPI)
    bars = {ax.get_gid(): ax.containers[0] for ax in figure.axes if ax.containers}
    heights = [bar.get_height() for bar in bars["bars-build_s"]]
    assert heights == [0.2, 1.5]


def test_compare_with_nothing_to_draw_is_an_error():
    with pytest.raises(ModelFormatError, match="nothing|no models"):
        plot.compare_figure({"features": 3}, source="empty.json")


def test_scaling_series_accepts_flat_rows_and_skips_incomplete_ones():
    rows = [{"model": "octomap", "features": n, "build_s": n / 100, "memory_bytes": n * 10} for n in (10, 100)]
    rows.append({"model": "octomap", "features": 1000})  # no numbers: skipped
    series = plot.scaling_series({"scaling": rows})
    assert [(s.model, s.variable) for s in series] == [("octomap", "features")]
    np.testing.assert_allclose(series[0].seconds, [0.1, 1.0])


def test_pictures_render_to_every_format(tmp_path):
    nav = hand_map(notched_disc())
    figure = plot.navigation_figure([nav], log=RangeLog([Position(0, ring_features(50))]), size=SMALL, dpi=DPI)
    sizes = {}
    for suffix in ("png", "svg", "pdf"):
        written = plot.save_figure(figure, tmp_path / f"nav.{suffix}")
        sizes[suffix] = written.stat().st_size
    assert png_size((tmp_path / "nav.png").read_bytes()) == (120, 100)
    assert all(size > 1000 for size in sizes.values())
    assert b'id="navigation"' in (tmp_path / "nav.svg").read_bytes()
    assert Path(tmp_path / "nav.pdf").read_bytes().startswith(b"%PDF")


# --- frames, empty maps, extents ------------------------------------------------------------


def test_robot_frame_maps_are_placed_at_the_logs_poses():
    poses_ = [Pose(1.0, 2.0, 0.0, 0.3), Pose(-1.0, 0.5, 0.0, -1.2)]
    log = RangeLog([Position(i, ring_features(30, i), p) for i, p in enumerate(poses_)])
    maps = [hand_map(notched_disc()), hand_map(Point(0, 0).buffer(0.7, 12))]
    figure = plot.navigation_figure(maps, log=log, size=SMALL, dpi=DPI)
    ax = figure.axes[0]
    drawn = [p.get_path().vertices for p in ax.patches if p.get_gid() == "navigation"]
    for vertices, nav, pose in zip(drawn, maps, poses_):
        expected = nav.in_world(pose).polygon.bounds
        np.testing.assert_allclose([*vertices.min(axis=0), *vertices.max(axis=0)], expected, atol=1e-9)
    robots = [p.center for p in ax.patches if p.get_gid() == "robot"]
    np.testing.assert_allclose(robots, [(1.0, 2.0), (-1.0, 0.5)])
    scatter = next(c for c in ax.collections if c.get_gid() == "features")
    world = np.concatenate([p.pose.to_world(p.features.points[:, :2]) for p in log.positions])
    evidence = np.concatenate([p.features.evidence for p in log.positions])
    np.testing.assert_allclose(scatter.get_offsets(), world[np.argsort(evidence, kind="stable")])


def test_maps_of_a_set_are_matched_to_log_positions_by_number():
    poses_ = {4: Pose(1.0, 0.0, 0.0, 0.0), 9: Pose(5.0, 5.0, 0.0, 1.0)}
    log = RangeLog([Position(i, ring_features(10, i), p) for i, p in poses_.items()])
    maps = [hand_map(notched_disc()), hand_map(notched_disc())]
    figure = plot.navigation_figure(maps, positions=[9, 4], log=log, size=SMALL, dpi=DPI)
    robots = [p.center for p in figure.axes[0].patches if p.get_gid() == "robot"]
    np.testing.assert_allclose(robots, [(5.0, 5.0), (1.0, 0.0)])
    with pytest.raises(InputError, match="no pose for each"):
        plot.navigation_figure(maps, positions=[9, 7], log=log, size=SMALL, dpi=DPI)


def test_a_world_frame_map_is_not_moved_twice():
    pose = Pose(3.0, 1.0, 0.0, 0.5)
    placed = hand_map(notched_disc()).in_world(pose)
    assert plot.map_in_frame(placed, pose) is placed
    with pytest.raises(InputError, match="frame already"):
        plot.map_in_frame(placed, Pose(0.0, 0.0, 0.0, 0.0))


def test_an_empty_map_says_so_on_the_picture():
    empty = hand_map(Polygon(), obstacles=(), exploration=())
    figure = plot.new_figure(SMALL, DPI)
    artists = plot.draw_navigation(figure.add_subplot(), empty)
    assert "empty" in artists["empty_note"].get_text()
    assert artists["empty"].center == (0.0, 0.0)
    assert len(artists["obstacles"].get_offsets()) == 0
    # Along a path each empty map is ringed, and the legend counts them once.
    poses_ = [Pose(0, 0, 0, 0), Pose(2, 0, 0, 0), Pose(4, 0, 0, 0)]
    maps = [hand_map(notched_disc()).in_world(poses_[0]), empty.in_world(poses_[1]), empty.in_world(poses_[2])]
    figure = plot.navigation_figure(maps, size=SMALL, dpi=DPI)
    rings = [p for p in figure.axes[0].patches if p.get_gid() == "empty"]
    assert [r.center for r in rings] == [(2.0, 0.0), (4.0, 0.0)]
    legend = [t.get_text() for t in figure.legends[0].get_texts()]
    assert "empty navigation polygon (2 of 3)" in legend
    assert "obstacle points (1 in all, reinforcement -1)" in legend
    assert not figure.axes[0].texts


class Inverted:
    """A tree with the estimator's inverse_range, as a fitted OccupancyRegressor has it."""

    def __init__(self, tree: MinMaxTree) -> None:
        self.tree_ = tree
        self.inverse_range = tree.inverse().range

    def predict(self, alpha, h, r):
        return self.tree_.predict(alpha, h, r)


def test_model_extent_follows_where_the_level_is_reached():
    # F = max(r - 1, 0.2) reaches 0.4 at r = 1.4: horizontally 1.4 m at h = 0, less below;
    # the median over the body band's heights (-0.95, -0.475, 0) is at h = -0.475.
    expected = 2.0 * math.sqrt(1.4**2 - 0.475**2)
    assert plot.model_extent(Inverted(radial_tree()), 0.4, Robot()) == pytest.approx(expected)
    assert plot.model_extent(radial_tree(), 0.4, Robot(), default=4.0) == 4.0


def test_folders_give_their_geojson_maps_in_order(tmp_path):
    for name in ("b.geojson", "a.geojson", "index.json"):
        (tmp_path / name).write_text("{}")
    assert [p.name for p in plot.expand_navigation_paths([tmp_path])] == ["a.geojson", "b.geojson"]
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no .geojson"):
        plot.expand_navigation_paths([tmp_path / "empty"])


def test_a_given_title_replaces_the_automatic_one():
    log = RangeLog([Position(0, ring_features(20))])
    assert plot.features_figure(log, title="Lab, run 3", size=SMALL, dpi=DPI).axes[0].get_title() == "Lab, run 3"
    nav = hand_map(notched_disc())
    assert plot.navigation_figure([nav], title="Map", size=SMALL, dpi=DPI).axes[0].get_title() == "Map"
    figure = plot.model_figure(radial_tree(), title="Model", extent=2.0, resolution=10, size=SMALL, dpi=DPI)
    assert figure.get_suptitle() == "Model"


def test_bench_results_json_is_drawn_with_its_headline_report_and_both_sweeps():
    def row(sweep: str, **size):
        n = size.get("features", 10_000) * size.get("scale", 1)
        return {"sweep": sweep, **size, "scale_fixed" if sweep == "features" else "features_fixed": 1,
                "models": {"parametric": {"build_s": 1e-4 * n ** 0.5, "extract_s": 0.01, "memory_bytes": 6000},
                           "grid": {"build_s": 1e-6 * n, "extract_s": 0.05, "memory_bytes": 8 * n}}}

    results = {"scaling": [row("scale", scale=s) for s in (1, 2, 4)] + [row("features", features=n)
                                                                       for n in (1000, 10_000)],
               "headline_report": report(), "meta": {"resolution": 0.05}}
    figure = plot.compare_figure(results, source="results.json", size=(10, 6), dpi=DPI)
    lines = {line.get_gid(): line for ax in figure.axes for line in ax.lines if line.get_gid()}
    assert set(lines) == {f"{kind}-{model}-{variable}" for kind in ("time", "memory")
                          for model in ("parametric", "grid") for variable in ("scale", "features")}
    np.testing.assert_allclose(lines["time-grid-scale"].get_xdata(), [1, 2, 4])
    np.testing.assert_allclose(lines["memory-grid-features"].get_ydata(), np.array([8000, 80_000]) / 2**20)
    assert any(p.get_gid() == "polygon-grid" for ax in figure.axes for p in ax.patches)


def test_a_single_map_of_a_set_draws_its_own_positions_features():
    log = RangeLog([Position(i, ring_features(10 + i, i), Pose(float(i), 0.0, 0.0, 0.0)) for i in range(3)])
    figure = plot.navigation_figure([hand_map(notched_disc())], positions=[2], log=log, size=SMALL, dpi=DPI)
    scatter = next(c for c in figure.axes[0].collections if c.get_gid() == "features")
    assert len(scatter.get_offsets()) == 12
    with pytest.raises(InputError, match="position=N"):
        plot.navigation_figure([hand_map(notched_disc())], log=log, size=SMALL, dpi=DPI)


# --- a run's map (plot map): reduced to the picture's pixels, walls kept ---------------------


def _map_folder(folder: Path, pixels: np.ndarray, resolution: float = 0.05) -> Path:
    from occtool.formats.nav2 import write_nav2

    folder.mkdir()
    write_nav2(pixels, resolution, (-2.0, 3.0), folder / "map.yaml")
    return folder


def test_a_small_map_is_drawn_cell_for_cell(tmp_path):
    pixels = np.full((30, 40), 254, dtype=np.uint8)
    pixels[5:25, 17] = 0
    pixels[:, :3] = 205
    folder = _map_folder(tmp_path / "map", pixels)
    figure = plot.map_figure(folder, size=(6.0, 6.0), dpi=100.0)
    image = figure.axes[0].images[0]
    drawn = np.asarray(image.get_array())
    assert drawn.shape == (30, 40, 3)
    np.testing.assert_allclose(image.get_extent(), (-2.0, -2.0 + 40 * 0.05, 3.0, 3.0 + 30 * 0.05))
    assert (drawn[5:25, 17] == 0).all() and (drawn[:, :3] == 0.75).all() and (drawn[:, 20:] == 1).all()


@given(st.integers(0, 1499), st.integers(0, 999))
@settings(max_examples=5)
def test_a_one_cell_wall_in_a_big_map_stays_black(tmp_path_factory, column, row):
    from occtool.plot._map import decimate

    # 1,500 x 1,000 cells on a 200 x 200 pixel figure: blocks of 10 x 10 cells at least.
    pixels = np.full((1000, 1500), 254, dtype=np.uint8)
    pixels[:, column] = 0  # a wall one cell thick, along the map
    pixels[row, :] = 0  # and one across it
    folder = _map_folder(tmp_path_factory.mktemp("big") / "map", pixels)
    figure = plot.map_figure(folder, size=(2.0, 2.0), dpi=100.0)
    image = figure.axes[0].images[0]
    drawn = np.asarray(image.get_array())
    assert drawn.shape[0] * drawn.shape[1] <= 200 * 200 and drawn.dtype == np.float32
    factor = math.ceil(1500 / drawn.shape[1])
    assert factor >= 10
    # Every block the walls cross is black, every other block white (row 0: the map's bottom).
    black = np.zeros(drawn.shape[:2], dtype=bool)
    black[:, column // factor] = True
    black[row // factor, :] = True
    assert ((drawn[..., 0] == 0) == black).all()
    left, right, bottom, top = image.get_extent()
    assert (left, bottom) == (-2.0, 3.0) and 0 <= right - (-2.0 + 1500 * 0.05) < factor * 0.05
    assert 0 <= top - (3.0 + 1000 * 0.05) < factor * 0.05
    # The reduction keeps the darkest known cell: unknown only where every cell is unknown.
    cells = np.array([[-1, -1, 0, -1], [-1, -1, -1, 40]], dtype=np.int8)
    assert decimate(cells, 2).tolist() == [[-1, 40]]


def test_the_reduction_is_the_blockwise_maximum(tmp_path):
    from occtool.formats import nav2
    from occtool.plot import _map

    rng = np.random.default_rng(3)
    cells = rng.choice(np.array([-1, 0, 37, 100], dtype=np.int8), size=(203, 157), p=[0.5, 0.4, 0.05, 0.05])
    for factor in (1, 2, 7, 16, 300):
        # Strips of a few rows at a time give the same result as one pass.
        saved, nav2._DECIMATE_STRIP_CELLS = nav2._DECIMATE_STRIP_CELLS, 3 * 157 * factor * factor
        try:
            reduced = _map.decimate(cells, factor)
        finally:
            nav2._DECIMATE_STRIP_CELLS = saved
        rows, cols = -(-203 // factor), -(-157 // factor)
        expected = np.array([[cells[i * factor:(i + 1) * factor, j * factor:(j + 1) * factor].max()
                              for j in range(cols)] for i in range(rows)], dtype=np.int8)
        assert (reduced == expected).all()
    with pytest.raises(InputError):
        _map.decimate(cells, 0)
