"""Real robot logs end to end (issue 4): read, group into positions, fit, extract.

The data sets are the real files in ../shared/data (the ``shared_data`` fixture skips
without them): the ROS 2 MCAP converted from the CCNY Hokuyo bag, the Intel lab CARMEN
log and OctoMap's 3D scan. Fits are kept small (few positions, few pieces) so the whole
module runs in a few seconds.
"""

from __future__ import annotations

import gzip
import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.formats.geojson import read_navigation
from occtool.io import read_log

CCNY = "ccny_hokuyo_bag/demo_ros2_converted.mcap"
INTEL = "intel_lab/intel-corrected.log.gz"
OCTOMAP = "octomap_scan/scan.dat.bz2"


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


def run(runner: CliRunner, *args: object) -> object:
    """Invoke occtool; fail with its output if it does not succeed."""
    result = runner.invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output + (result.stderr if result.stderr_bytes else "")
    return result


def messages(result: object) -> str:
    """The command's log messages with rich's line wrapping undone."""
    return " ".join(result.stderr.split())


def without_run(path: Path) -> dict:
    data = json.loads(path.read_text())
    data.pop("run")
    return data


def intel_head(shared_data: Path, folder: Path, scans: int = 16) -> Path:
    """The real Intel log up to its ``scans``-th laser scan, as a CARMEN file of its own."""
    lines = []
    count = 0
    with gzip.open(shared_data / INTEL, "rt") as handle:
        for line in handle:
            if line.startswith("FLASER"):
                count += 1
                if count > scans:
                    break
            lines.append(line)
    path = folder / "intel_head.log"
    path.write_text("".join(lines))
    return path


def navigation_polygon(path: Path, position: int | None = None) -> object:
    return read_navigation(path, position=position).polygon


# --------------------------------------------------------------------- CSV -> MCAP -> model
def test_csv_to_mcap_to_model_is_the_csv_model(runner, fixtures_dir, tmp_path):
    csv = fixtures_dir / "office" / "features.csv"
    run(runner, "convert", csv, "-o", tmp_path / "office.mcap")
    run(runner, "fit", csv, "--pieces", 8, "-o", tmp_path / "from_csv.json")
    run(runner, "fit", tmp_path / "office.mcap", "--pieces", 8, "-o", tmp_path / "from_mcap.json")
    from_csv = without_run(tmp_path / "from_csv.json")
    assert from_csv == without_run(tmp_path / "from_mcap.json")
    assert from_csv["training"]["n_features"] == 10000


@pytest.mark.slow
def test_carmen_csv_and_mcap_give_the_same_model_set(runner, shared_data, tmp_path):
    log = intel_head(shared_data, tmp_path)
    grouping = ("--position-tolerance", "1,7")
    run(runner, "convert", log, *grouping, "-o", tmp_path / "intel.csv")
    run(runner, "convert", tmp_path / "intel.csv", "-o", tmp_path / "intel.mcap")
    sets = {}
    for name, source, options in [("carmen", log, grouping), ("csv", tmp_path / "intel.csv", ()),
                                  ("mcap", tmp_path / "intel.mcap", ())]:
        folder = tmp_path / name
        folder.mkdir()
        run(runner, "fit", source, *options, "--pieces", 8, "-o", f"{folder}/")
        sets[name] = folder
    index = json.loads((sets["carmen"] / "index.json").read_text())
    assert len(index["models"]) >= 3
    for name in ("csv", "mcap"):
        other = json.loads((sets[name] / "index.json").read_text())
        # Positions, poses, stamps and feature counts survive both conversions exactly.
        assert other["models"] == index["models"]
        for entry in index["models"]:
            assert without_run(sets[name] / entry["file"]) == without_run(sets["carmen"] / entry["file"])


def test_csv_keeps_the_stamps_of_a_log(shared_data, tmp_path):
    from occtool.io import write_csv

    log = read_log(intel_head(shared_data, tmp_path), position_tolerance=(1, 7))
    write_csv(log, tmp_path / "intel.csv")
    back = read_log(tmp_path / "intel.csv")
    assert [p.stamp for p in back.positions] == [p.stamp for p in log.positions]
    assert [p.pose for p in back.positions] == [p.pose for p in log.positions]


# ------------------------------------------------------- no-return beams as free rays
def test_convert_keeps_the_no_return_beams_as_evidence_0_rows(runner, shared_data, tmp_path):
    log = intel_head(shared_data, tmp_path)
    with open(log) as handle:
        scans = [np.array(line.split()[2:182], dtype=float) for line in handle if line.startswith("FLASER")]
    no_return = sum(int((ranges == 81.83).sum()) for ranges in scans)
    assert len(scans) == 16 and no_return == 213

    result = run(runner, "-v", "convert", log, "--group-by", "message", "-o", tmp_path / "plain.csv")
    assert f"dropped {no_return} of 2880 readings as no return (readings >= 81.83 m)" in messages(result)
    plain = read_log(tmp_path / "plain.csv")
    assert not any((p.features.evidence == 0).any() for p in plain.positions)

    result = run(runner, "-v", "convert", log, "--group-by", "message", "--no-return-range", 5,
                 "-o", tmp_path / "free.csv")
    assert (f"kept {no_return} of 2880 readings with no return (readings >= 81.83 m) as free rays at 5 m "
            "with evidence 0 (--no-return-range 5)") in messages(result)
    free = read_log(tmp_path / "free.csv")
    assert len(free.positions) == len(plain.positions) == 16
    for before, after, ranges in zip(plain.positions, free.positions, scans):
        zero = after.features.evidence == 0
        assert zero.sum() == (ranges == 81.83).sum() and len(after.features) == len(before.features) + zero.sum()
        np.testing.assert_allclose(after.features.range[zero], 5.0)
        np.testing.assert_array_equal(after.features.points[~zero], before.features.points)


def test_free_rays_fit_the_same_from_the_log_and_its_conversions(runner, shared_data, tmp_path):
    log = intel_head(shared_data, tmp_path)
    options = ("--position-tolerance", "1,7", "--no-return-range", 3)
    run(runner, "convert", log, *options, "-o", tmp_path / "intel.csv")
    run(runner, "convert", tmp_path / "intel.csv", "-o", tmp_path / "intel.mcap")
    fitted = {}
    for name, source, extra in [("carmen", log, options), ("csv", tmp_path / "intel.csv", ()),
                                ("mcap", tmp_path / "intel.mcap", ())]:
        run(runner, "fit", source, *extra, "--position", 2, "--pieces", 8, "-o", tmp_path / f"{name}.json")
        fitted[name] = without_run(tmp_path / f"{name}.json")
    assert fitted["csv"] == fitted["carmen"] == fitted["mcap"]
    # The position's features include its free rays.
    position = read_log(log, position_tolerance=(1, 7), no_return_range=3).positions[2]
    assert (position.features.evidence == 0).sum() > 0
    assert fitted["carmen"]["training"]["n_features"] == len(position.features)


# --------------------------------------------------------------------------- info
def test_info_lists_the_mcap_channels(runner, shared_data, tmp_path):
    result = run(runner, "info", shared_data / CCNY)
    text = result.stdout
    assert "/scan" in text and "sensor_msgs/msg/LaserScan" in text and "360" in text
    assert "yes: range data" in text
    log = read_log(intel_head(shared_data, tmp_path, scans=3))
    from occtool.io import write_mcap

    write_mcap(log, tmp_path / "own.mcap")
    # Narrow terminals fold the topic instead of cutting it to "/occtool/featur...".
    result = run(runner, "info", tmp_path / "own.mcap")
    assert "…" not in result.stdout
    rows = [line.split("│")[1:3] for line in result.stdout.splitlines() if line.startswith("│")]
    assert "".join(topic.strip() for topic, _ in rows) == "/occtool/features"
    assert "".join(schema.strip() for _, schema in rows) == "occtool.RangeFeatures"
    assert "".join(result.stdout.split()).count(str(tmp_path / "own.mcap").replace(" ", "")) == 1


# ------------------------------------------------------------------- CCNY LaserScan MCAP
def test_ccny_laser_mcap_is_one_position_with_a_note(runner, shared_data, tmp_path):
    result = run(runner, "fit", shared_data / CCNY, "--pieces", 8, "-o", tmp_path / "model.json",
                 "--sensor-height", 0.2, "--body-height", 0.3, "--robot-radius", 0.15)
    assert "the log has no poses: its 360 scans form one position" in messages(result)
    model = json.loads((tmp_path / "model.json").read_text())
    assert model["run"]["position"] == 0
    # 360 scans x 681 beams, less the readings below range_min (no return).
    assert model["training"]["n_features"] == 360 * 681 - 13342
    # A 2D laser sees the scan plane only (h = 0): no feature is floor.
    assert model["training"]["samples_by_kind"]["floor"] == 0
    # The sensor moved during the 36 s without poses, so the merged scans hold obstacles
    # 0.29 m from the sensor: only a small robot fits (a URG-04LX platform: laser 0.2 m
    # up, body 0.3 m tall, radius 0.15 m); the 0.25 m default radius is in collision.
    run(runner, "extract", tmp_path / "model.json", "-o", tmp_path / "nav.geojson")
    polygon = navigation_polygon(tmp_path / "nav.geojson")
    assert polygon.area > 0.01 and polygon.contains(type(polygon.centroid)(0.0, 0.0))


# -------------------------------------------------------------------- OctoMap 3D scan
def test_octomap_scan_gives_a_navigation_polygon(runner, shared_data, tmp_path):
    # The floor near the scanner lies 4 to 9 cm below its origin (z -0.04 .. -0.09 within
    # 3 m): with the default 1 m sensor height it would be an obstacle ring at 0.47 m.
    result = run(runner, "-v", "fit", shared_data / OCTOMAP, "--pieces", 8, "-o", tmp_path / "model.json",
                 "--sensor-height", 0.08, "--body-height", 0.5)
    assert "constant evidence 0.9" in messages(result)
    model = json.loads((tmp_path / "model.json").read_text())
    assert model["training"]["n_features"] == 88206
    assert model["training"]["samples_by_kind"]["floor"] > 10000
    run(runner, "extract", tmp_path / "model.json", "-o", tmp_path / "nav.geojson")
    polygon = navigation_polygon(tmp_path / "nav.geojson")
    # The scan covers the front half (azimuths -91..91 deg), nearest wall about 3 m away:
    # the map fills most of the half disc of 1.5 m in front, little behind.
    assert polygon.area > 1.5
    minx, _, maxx, _ = polygon.bounds
    assert maxx > 1.4 and minx > -0.5


# --------------------------------------------------------------- Intel CARMEN model set
@pytest.mark.slow
def test_intel_model_set_extract_in_robot_and_world_frame(runner, shared_data, tmp_path):
    log_path = intel_head(shared_data, tmp_path)
    log = read_log(log_path, position_tolerance=(1, 7))
    models = tmp_path / "models"
    models.mkdir()
    run(runner, "fit", log_path, "--position-tolerance", "1,7", "-o", f"{models}/")
    index = json.loads((models / "index.json").read_text())
    assert index["format"] == "occtool-model-set"
    assert [e["position"] for e in index["models"]] == list(range(len(log.positions)))
    for entry, position in zip(index["models"], log.positions):
        assert entry["pose"] == position.pose.to_dict() and entry["stamp"] == position.stamp
        assert entry["features"] == len(position.features)
        model = json.loads((models / entry["file"]).read_text())
        assert model["run"]["position"] == entry["position"]
        assert model["training"]["n_features"] == entry["features"]

    run(runner, "extract", models, "-o", tmp_path / "robot.geojson")
    run(runner, "extract", models, "--world", "-o", tmp_path / "world.geojson")
    robot = json.loads((tmp_path / "robot.geojson").read_text())
    world = json.loads((tmp_path / "world.geojson").read_text())
    assert [p["position"] for p in world["properties"]["positions"]] == [e["position"] for e in index["models"]]

    # Position 0 (the robot turning on the spot at the start: 11 scans) has a real map.
    k = 0
    pose = index["models"][k]["pose"]
    assert world["properties"]["positions"][k]["pose"] == pose
    c, s = math.cos(pose["yaw"]), math.sin(pose["yaw"])

    def coordinates(collection: dict) -> list[np.ndarray]:
        found = []
        for feature in collection["features"]:
            if feature["properties"].get("position") != k:
                continue
            geometry = feature["geometry"]
            if geometry["type"] == "Point":
                found.append(np.array([geometry["coordinates"]]))
            else:
                found.extend(np.array(ring) for ring in geometry["coordinates"])
        return found

    in_robot, in_world = coordinates(robot), coordinates(world)
    assert len(in_robot) == len(in_world) > 10
    for local, moved in zip(in_robot, in_world):
        expected = np.column_stack([pose["x"] + c * local[:, 0] - s * local[:, 1],
                                    pose["y"] + s * local[:, 0] + c * local[:, 1]])
        np.testing.assert_allclose(moved, expected, rtol=0, atol=1e-9)
    local_polygon = navigation_polygon(tmp_path / "robot.geojson", position=k)
    world_polygon = navigation_polygon(tmp_path / "world.geojson", position=k)
    assert local_polygon.area > 1.0
    assert world_polygon.area == pytest.approx(local_polygon.area, rel=1e-9)
    # The robot stands inside its own map, in both frames.
    assert local_polygon.contains(type(local_polygon.centroid)(0.0, 0.0))
    assert world_polygon.contains(type(world_polygon.centroid)(pose["x"], pose["y"]))


@pytest.mark.slow
def test_one_position_of_the_whole_intel_log(runner, shared_data, tmp_path):
    log = read_log(shared_data / INTEL)
    assert len(log.positions) > 800 and log.has_poses
    result = runner.invoke(cli, ["fit", str(shared_data / INTEL), "-o", str(tmp_path / "all.json")])
    assert result.exit_code == 1 and "--position N" in result.output and not (tmp_path / "all.json").exists()
    models = tmp_path / "models"
    models.mkdir()
    run(runner, "fit", shared_data / INTEL, "--position", 100, "--pieces", 8, "-o", f"{models}/")
    index = json.loads((models / "index.json").read_text())
    assert [(e["position"], e["file"]) for e in index["models"]] == [(100, "model_0100.json")]
    assert index["models"][0]["pose"] == log.positions[100].pose.to_dict()
    # The same position to a file is the same model; the set's file also keeps what the
    # position observed, for a map of the set (occtool.fuse.Observation).
    run(runner, "fit", shared_data / INTEL, "--position", 100, "--pieces", 8, "-o", tmp_path / "m100.json")
    in_set = without_run(models / "model_0100.json")
    assert in_set.pop("observed")["reach_bins"] == 120
    assert without_run(tmp_path / "m100.json") == in_set


# ----------------------------------------------------------------- regression: pan weight
def test_projected_pan_weight_holds_as_the_loader_measures_it():
    """A fitted Intel position once wrote a piece with hypot(a1, a2) = 12.000000000000002
    by numpy (12.0 by math.hypot), which the model loader then refused."""
    from occtool.fit._construction import _Fitter
    from occtool.tree import MinMaxTree

    a1, a2 = -6.3453855919518025, -10.185091147822414
    assert math.hypot(a1, a2) == 12.0 and np.hypot(a1, a2) > 12.0
    fitter = SimpleNamespace(k_angle=2, lower=np.array([-12.0, -12.0, -8.0, 0.25, -np.inf]),
                             upper=np.array([12.0, 12.0, 8.0, np.inf, np.inf]), p=SimpleNamespace(a_max=12.0))
    fitter.project_rows = lambda rows: _Fitter.project_rows(fitter, rows)  # what project calls
    piece = _Fitter.project(fitter, np.array([a1, a2, 0.5, 1.0, -0.2]))
    tree = MinMaxTree("trig", piece[None, :], 0)
    assert tree.angle_weight.max() <= 12.0
