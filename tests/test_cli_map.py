"""`occtool map` and `occtool evaluate-log` end to end on a synthetic room log."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _room_log import ROOM, write_room_log
from click.testing import CliRunner

from occtool.cli.main import cli

LASER = ("--sensor-height", "0.3", "--body-height", "0.5")


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def mapped(tmp_path_factory):
    folder = tmp_path_factory.mktemp("map")
    log = folder / "room.log"
    write_room_log(log, scans=40)
    out = folder / "out" / "deeper"
    result = run("map", log, "-o", out, *LASER)
    assert result.exit_code == 0, result.output
    return log, out


def test_writes_every_output(mapped):
    _, out = mapped
    names = sorted(p.name for p in out.iterdir())
    assert names == ["frontiers.geojson", "map.mcap", "map.pgm", "map.yaml", "navigation.geojson",
                     "obstacles.geojson", "summary.json", "world.occmap"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["positions"] >= 10 and summary["fused_map_bytes"] > 0 and summary["frame"] == "map"


def test_nav2_map_puts_walls_where_they_are(mapped):
    from occtool.formats.nav2 import CELL_FREE, CELL_OCCUPIED, CELL_UNKNOWN, read_nav2

    _, out = mapped
    loaded = read_nav2(out / "map.yaml")

    def cell(x, y):
        i = int(np.floor((x - loaded.origin[0]) / loaded.resolution))
        j = int(np.floor((y - loaded.origin[1]) / loaded.resolution))
        # map_server knows nothing outside the image: unknown.
        inside = 0 <= j < loaded.cells.shape[0] and 0 <= i < loaded.cells.shape[1]
        return loaded.cells[j, i] if inside else CELL_UNKNOWN

    _x0, _y0, _x1, y1 = ROOM
    # The wall's surface: its returns' cell, on one side of y1 or the other.
    assert CELL_OCCUPIED in (cell(1.0, y1 - 0.02), cell(1.0, y1 + 0.02))
    # A wall's uncertain edge (occtool.fuse._world.WALL_RIM) is never free; past it, free.
    assert cell(1.0, y1 - 0.15) in (CELL_OCCUPIED, CELL_UNKNOWN)
    assert cell(1.0, y1 - 0.3) == CELL_FREE
    assert cell(1.0, 0.25) == CELL_FREE
    # Behind the wall: not free.
    assert cell(1.0, y1 + 0.15) != CELL_FREE
    assert cell(1.0, y1 + 1.5) == CELL_UNKNOWN


def test_scale_nav2_map_grades_what_the_trinary_map_rounds(mapped, tmp_path):
    from occtool.formats.nav2 import CELL_FREE, CELL_OCCUPIED, CELL_UNKNOWN, read_nav2

    log, trinary_out = mapped
    out = tmp_path / "scale"
    result = run("map", log, "-o", out, *LASER, "--nav2-mode", "scale", "--no-mcap")
    assert result.exit_code == 0, result.output
    assert (out / "map.png").is_file() and not (out / "map.pgm").exists()
    scale, trinary = read_nav2(out / "map.yaml"), read_nav2(trinary_out / "map.yaml")
    assert scale.mode == "scale" and scale.cells.shape == trinary.cells.shape and scale.origin == trinary.origin
    # Unknown only where nothing observed: never where the trinary map says free or occupied.
    assert not (scale.cells == CELL_UNKNOWN)[trinary.cells != CELL_UNKNOWN].any()
    # Graded cells between free and occupied (a wall's edge, free space far from positions).
    assert ((scale.cells > 0) & (scale.cells < 100)).any()

    def cell(x, y):
        i = int(np.floor((x - scale.origin[0]) / scale.resolution))
        j = int(np.floor((y - scale.origin[1]) / scale.resolution))
        inside = 0 <= j < scale.cells.shape[0] and 0 <= i < scale.cells.shape[1]
        return scale.cells[j, i] if inside else CELL_UNKNOWN

    _x0, _y0, _x1, y1 = ROOM
    assert CELL_OCCUPIED in (cell(1.0, y1 - 0.02), cell(1.0, y1 + 0.02))
    assert cell(1.0, 0.25) == CELL_FREE and cell(1.0, y1 + 0.15) != CELL_FREE


def test_scale_mode_without_pillow_is_one_line_before_any_work(mapped, tmp_path, monkeypatch):
    import sys

    log, _ = mapped
    monkeypatch.setitem(sys.modules, "PIL", None)  # import PIL now raises ImportError
    result = CliRunner().invoke(cli, ["-q", "map", str(log), "-o", str(tmp_path / "out"), *LASER,
                                      "--nav2-mode", "scale"])
    assert result.exit_code != 0
    message = result.output.strip()
    assert len(message.splitlines()) == 1 and "--nav2-mode scale" in message and "occtool[png]" in message
    assert not (tmp_path / "out").exists()


def test_geojson_layers_hold_one_geometry_type_each(mapped):
    _, out = mapped
    for name, kind in (("navigation", "Polygon"), ("obstacles", "Point"), ("frontiers", "Point")):
        data = json.loads((out / f"{name}.geojson").read_text())
        assert data["type"] == "FeatureCollection" and data["properties"]["frame"] == "map"
        assert {f["geometry"]["type"] for f in data["features"]} <= {kind}
    assert json.loads((out / "navigation.geojson").read_text())["features"]


def test_mcap_uses_foxglove_schemas_and_decodes(mapped):
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    _log, out = mapped
    with open(out / "map.mcap", "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        messages = list(reader.iter_decoded_messages())
    by_topic = {}
    for schema, channel, message, decoded in messages:
        by_topic.setdefault(channel.topic, []).append((schema.name, message, decoded))
    assert {name for name, _, _ in by_topic["/map"]} == {"foxglove.Grid"}
    assert {name for name, _, _ in by_topic["/positions"]} == {"foxglove.SceneUpdate"}
    summary = json.loads((out / "summary.json").read_text())
    scenes = by_topic["/positions"]
    assert len(scenes) == summary["positions"]
    # One message per position on its own time: the log's stamps start at 10 s.
    times = [message.log_time for _, message, _ in scenes]
    assert times == sorted(times) and times[0] == 10_000_000_000
    entity = scenes[0][2].entities[0]
    assert entity.frame_id == "map" and entity.lines
    (_, _, grid), = by_topic["/map"]
    assert grid.frame_id == "map" and grid.column_count == summary["raster"]["columns"]
    values = np.frombuffer(grid.data, dtype=np.int8).reshape(-1, grid.column_count)
    from occtool.formats.nav2 import read_nav2

    assert (values == read_nav2(out / "map.yaml").cells).all()


@pytest.fixture(scope="module")
def model_set(mapped, tmp_path_factory):
    log, _ = mapped
    models = tmp_path_factory.mktemp("set") / "models"
    models.mkdir()
    assert run("fit", log, "-o", f"{models}/", *LASER).exit_code == 0
    return models


def test_map_of_a_model_set(model_set, tmp_path):
    result = run("map", model_set, "-o", tmp_path / "out", "--no-mcap")
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["fitted_here"] is False and summary["positions"] >= 10
    assert not (tmp_path / "out" / "map.mcap").exists()


def test_a_model_set_map_takes_the_robot_options(model_set, tmp_path):
    def area(*options):
        out = tmp_path / "-".join(options)
        result = run("map", model_set, "-o", out, "--no-mcap", *options)
        assert result.exit_code == 0, result.output
        return json.loads((out / "summary.json").read_text())["navigation_area_m2"]

    # The set was fitted for a 0.25 m robot: a wider one has less room, a narrower one more.
    fitted, narrow, wide = area(), area("--robot-radius", "0.1"), area("--robot-radius", "0.4")
    assert narrow > fitted > wide > 0
    assert area("--robot-radius", "0.25") == fitted


@pytest.mark.parametrize("option", [("--pieces", "8"), ("-L", "8"), ("--no-guard",), ("--no-return-range", "5"),
                                    ("--keyframe-share", "0"), ("--seed", "3"), ("--no-loop-closure",)])
def test_a_model_set_map_refuses_what_applies_to_a_log(model_set, tmp_path, capsys, option):
    from occtool.cli.main import _run

    code = _run(["-q", "map", str(model_set), "-o", str(tmp_path / "out"), *option])
    message = capsys.readouterr().err.strip()
    assert code == 2 and len(message.splitlines()) == 1, message
    flag = {"-L": "--pieces"}.get(option[0], option[0])
    assert message.startswith(f"Error: {flag} applies to a log, not to a model set")
    assert not (tmp_path / "out").exists()


def test_bad_input_is_one_line_and_writes_nothing(tmp_path):
    # Two positions without poses: they cannot be placed in one map.
    log = tmp_path / "two.csv"
    log.write_text("x,y,z,m,position\n1,0,0,0.9,0\n0,1,0,0.9,0\n1,0,0,0.9,1\n0,1,0,0.9,1\n")
    result = CliRunner().invoke(cli, ["-q", "map", str(log), "-o", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert len(result.output.strip().splitlines()) == 1 and "no pose" in result.output
    assert not (tmp_path / "out").exists()


def test_a_log_without_poses_is_one_position_at_the_origin(tmp_path):
    from _room_log import room_ranges

    ranges = room_ranges(1.0, 0.25, 0.0)
    angles = -np.pi / 2 + np.arange(180) * np.pi / 180
    log = tmp_path / "scan.xyz"
    log.write_text("".join(f"{r * np.cos(a):.4f} {r * np.sin(a):.4f} 0\n" for r, a in zip(ranges, angles)))
    result = run("-q", "map", log, "-o", tmp_path / "out", "--no-mcap", "--evidence", "0.9", *LASER)
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["positions"] == 1 and summary["path"] == [[0.0, 0.0]]


def test_no_overwrite_refuses_before_work(mapped):
    log, out = mapped
    before = (out / "map.pgm").stat().st_mtime_ns
    result = CliRunner().invoke(cli, ["map", str(log), "-o", str(out), "--no-overwrite", *LASER])
    assert result.exit_code == 1 and "exists already" in result.output
    assert (out / "map.pgm").stat().st_mtime_ns == before


def test_evaluate_log_prints_the_figures(mapped, tmp_path):
    log, _ = mapped
    # --json FILE: the figures to FILE, the text still printed (bare --json or '-': JSON on stdout).
    result = run("evaluate-log", log, "--block", "5", "--holdout", "0.2", "--json", tmp_path / "figures.json", *LASER)
    assert result.exit_code == 0, result.output
    assert "AUC fused_log_odds" in result.output and "issue" not in result.output
    figures = json.loads((tmp_path / "figures.json").read_text())
    expected = {"fused_log_odds", "fused_dempster_shafer", "fused_mean", "grid", "textbook_0.05m", "textbook_0.1m",
                "world", "nav2_map",
                "textbook_fixed_0.05m", "textbook_fixed_0.1m", "counting_0.05m", "counting_0.1m"}
    from occtool.grid import octomap_available

    if octomap_available():
        expected.add("octomap")
        # A build that was timed (not a default 0) and took less than the whole command.
        assert figures["octomap_bytes"] > 0 and 0 < figures["octomap_s"] < 60
        # OctoMap's defaults (0.7 / 0.4, clamped to [0.1192, 0.971]) are the textbook grid's fixed
        # settings at the same 5 cm: scored on the same points, the two maps agree.
        assert figures["auc"]["octomap"] == pytest.approx(figures["auc"]["textbook_fixed_0.05m"], abs=0.01)
    assert set(figures["auc"]) == expected
    assert figures["auc"]["fused_log_odds"] > 0.9
    assert figures["auc"]["textbook_0.05m"] > 0.5 and figures["textbook"]["textbook_0.1m"]["bytes"] > 0
    assert 0 < figures["fused_positions"] <= figures["training_positions"]
    assert 0 <= figures["nav2"]["scans_cells_both_95"] <= 1


def test_evaluate_log_without_pyoctomap_says_so(mapped, monkeypatch):
    import sys

    # An import of a module set to None in sys.modules raises ImportError, as when not installed.
    monkeypatch.setitem(sys.modules, "pyoctomap", None)
    log, _ = mapped
    result = run("evaluate-log", log, "--block", "5", "--holdout", "0.2", *LASER)
    assert result.exit_code == 0, result.output
    assert "Traceback" not in result.output
    line = next(line for line in result.output.splitlines() if "OctoMap:" in line)
    assert "not scored" in line and "occtool[octomap]" in line
    assert "AUC octomap" not in result.output


def test_keyframe_share_zero_fits_every_position(mapped, tmp_path):
    log, out = mapped
    result = run("map", log, "-o", tmp_path / "every", "--keyframe-share", "0", "--no-mcap", *LASER)
    assert result.exit_code == 0, result.output
    every = json.loads((tmp_path / "every" / "summary.json").read_text())
    default = json.loads((out / "summary.json").read_text())
    assert every["not_keyframes"] == 0
    assert default["positions"] + default["not_keyframes"] == every["positions"]
    assert default["positions"] < every["positions"]


def test_origin_writes_wgs84_that_round_trips(mapped, tmp_path):
    pytest.importorskip("pyproj")
    from occtool.formats.wgs84 import Georeference

    log, out = mapped
    result = run("map", log, "-o", tmp_path / "geo", "--origin", "47.0,8.0,30", "--no-mcap", *LASER)
    assert result.exit_code == 0, result.output
    metric = json.loads((out / "obstacles.geojson").read_text())
    geo = json.loads((tmp_path / "geo" / "obstacles.geojson").read_text())
    assert geo["properties"]["frame"] == "WGS84"
    xy = np.array([f["geometry"]["coordinates"] for f in metric["features"]])
    lonlat = np.array([f["geometry"]["coordinates"] for f in geo["features"]])
    back = Georeference(47.0, 8.0, 30.0).from_lonlat(lonlat)
    assert np.abs(back - xy).max() < 0.01


def test_bad_origin_is_a_usage_error(mapped, tmp_path):
    log, _ = mapped
    result = CliRunner().invoke(cli, ["map", str(log), "-o", str(tmp_path / "x"), "--origin", "95,0"])
    assert result.exit_code == 2 and not (tmp_path / "x").exists()


def test_plot_map_draws_the_folder(mapped, tmp_path):
    pytest.importorskip("matplotlib")
    _, out = mapped
    picture = tmp_path / "map.png"
    result = run("plot", "map", out, "-o", picture, "--size", "300,300px")
    assert result.exit_code == 0, result.output
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["path"]) == summary["positions"]


def test_plot_map_walls_have_a_trust_colour_bar(mapped):
    pytest.importorskip("matplotlib")
    from occtool.plot import map_figure

    _, out = mapped
    plain = map_figure(out, size=(4.0, 4.0))
    assert len(plain.axes) == 1  # no walls, no key
    figure = map_figure(out, size=(4.0, 4.0), walls=True)
    assert len(figure.axes) == 2
    bar = figure.axes[1]
    assert "trust" in bar.get_ylabel() and bar.get_ylim() == (0.0, 1.0)
    # The key's colours are the ones the walls are drawn in (trust 0 pale, 1 dark red).
    from occtool.fuse import load_map

    walls = next(c for c in figure.axes[0].collections if c.get_label() == "walls (world.occmap)")
    cmap = next(c.get_cmap() for c in bar.collections if c.get_cmap().name == "wall trust")
    trust = load_map(out / "world.occmap").trust
    assert len(trust) and np.allclose(cmap(trust)[:, :3], walls.get_colors()[:, :3], atol=0.01)


def test_plot_map_draws_a_scale_map_in_greys(mapped, tmp_path):
    pytest.importorskip("matplotlib")
    from PIL import Image

    log, _ = mapped
    out = tmp_path / "scale"
    assert run("map", log, "-o", out, *LASER, "--nav2-mode", "scale", "--no-mcap").exit_code == 0
    picture = tmp_path / "picture.png"
    result = run("plot", "map", out, "-o", picture, "--size", "400,400px")
    assert result.exit_code == 0, result.output
    with Image.open(picture) as image:
        pixels = np.asarray(image.convert("RGB")).reshape(-1, 3).astype(int)
    grey = (pixels[:, 0] == pixels[:, 1]) & (pixels[:, 1] == pixels[:, 2])
    # Graded cells in greys other than black and white; unknown in pale blue, not grey.
    assert (grey & (pixels[:, 0] > 20) & (pixels[:, 0] < 235)).any()
    assert (np.abs(pixels - [199, 217, 237]).max(axis=1) <= 3).any()


def test_the_library_map_writes_what_the_command_writes(mapped, tmp_path):
    from occtool.fit import OccupancyRegressor
    from occtool.fuse import map_log
    from occtool.robot import Robot

    log, out = mapped
    estimator = OccupancyRegressor(robot=Robot(sensor_height=0.3, body_height=0.5))
    result = map_log(log, tmp_path / "lib", estimator=estimator)
    assert [p.name for p in result.written] == ["world.occmap", "map.yaml", "map.pgm", "map.mcap", "navigation.geojson",
                                               "obstacles.geojson", "frontiers.geojson", "summary.json"]
    for name in ("world.occmap", "map.pgm", "navigation.geojson", "obstacles.geojson", "frontiers.geojson"):
        assert (tmp_path / "lib" / name).read_bytes() == (out / name).read_bytes(), name
    assert json.loads((tmp_path / "lib" / "summary.json").read_text()) == json.loads(json.dumps(result.summary))
    assert result.report is not None and result.registration is None
    assert result.summary["positions"] == len(result.models) == result.report.positions


def test_robot_overrides_name_robot_fields(model_set, tmp_path):
    from occtool.errors import InputError
    from occtool.fuse import map_model_set

    with pytest.raises(InputError, match="no robot field wheels"):
        map_model_set(model_set, tmp_path / "out", robot_overrides={"wheels": 4.0})
