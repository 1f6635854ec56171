"""Real depth frames: fixtures/tum-fr3-cabinet (58 Kinect key frames of TUM RGB-D's
freiburg3_cabinet, 320x240, with their poses; SOURCE.md there) mapped by ``occtool map``
as the README gives it, and scored on held-out frames as bench/depth.py scores them."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from occtool.cli.main import cli

FIXTURE = Path(__file__).resolve().parent.parent / "fixtures" / "tum-fr3-cabinet"
# The cabinet as the source repository's data/truth_objects.txt gives it: centre x, y and
# half sizes along x and y (its yaw, 3.10 rad, is within 2 degrees of the world's x).
CABINET = (-1.52988, 0.456476, 0.396318, 0.222742)

pytest.importorskip("PIL")


@pytest.fixture(scope="module")
def mapped(tmp_path_factory):
    out = tmp_path_factory.mktemp("cabinet") / "map"
    # The cell the README's command chooses on this folder (summary.json), given: the
    # inner split that chooses it is tested in test_map3d.
    result = CliRunner().invoke(cli, ["map", str(FIXTURE / "depth.txt"), "-o", str(out), "--sensor-height", "0.95",
                                      "--world-resolution", "0.4"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return out


def test_the_folder_reads_as_tum_with_its_own_intrinsics():
    from occtool.io import read_log

    log = read_log(FIXTURE, group_by="message", depth_features=2000)
    assert len(log.positions) == 58
    assert not any("ROS default" in note or "TUM's freiburg" in note for note in log.notes)  # camera-intrinsics.txt
    heights = [p.pose.z for p in log.positions]
    assert 0.8 < float(np.median(heights)) < 1.1  # a hand-held camera about 0.95 m above the floor plane


def test_the_map_has_the_cabinet_and_the_floor_round_it_free(mapped):
    from occtool.formats.nav2 import CELL_FREE, CELL_OCCUPIED, CELL_UNKNOWN, read_nav2

    loaded = read_nav2(mapped / "map.yaml")

    def cell(x: float, y: float) -> int:
        i = int(np.floor((x - loaded.origin[0]) / loaded.resolution))
        j = int(np.floor((y - loaded.origin[1]) / loaded.resolution))
        inside = 0 <= j < loaded.cells.shape[0] and 0 <= i < loaded.cells.shape[1]
        return int(loaded.cells[j, i]) if inside else CELL_UNKNOWN

    cx, cy, hx, hy = CABINET
    for (x, y), (ox, oy) in (((cx + hx, cy), (1, 0)), ((cx - hx, cy), (-1, 0)),
                             ((cx, cy + hy), (0, 1)), ((cx, cy - hy), (0, -1))):
        # Each side's surface occupied within 5 cm; the floor 40 cm outside it free (nearer,
        # the 3D map's 0.4 m patches reach past the surface and no cell within
        # occtool.fuse._projection.FREE_RIM of an occupied one is free).
        assert CELL_OCCUPIED in [cell(x + d * ox, y + d * oy) for d in (-0.05, 0.0, 0.05)], (x, y)
        assert cell(x + 0.4 * ox, y + 0.4 * oy) == CELL_FREE, (x, y)
    assert cell(cx, cy) != CELL_FREE
    # The floor between the camera and the cabinet: 30 % and 50 % of the way from each
    # position of the path to the cabinet's centre (measured: 22 and 16 of 22 free; half
    # way is 0.2-0.3 m from the cabinet, where its 0.4 m patches and their rim reach).
    path = np.array(json.loads((mapped / "summary.json").read_text())["path"])
    assert len(path) >= 15
    for share, least in ((0.3, 0.9), (0.5, 0.7)):
        free = [cell(*(p + share * (np.array([cx, cy]) - p))) == CELL_FREE for p in path]
        assert np.mean(free) >= least, (share, free)
    world_bytes = (mapped / "world.occmap").stat().st_size
    assert 0 < world_bytes < 20_000  # measured 3.7 KB


@pytest.mark.slow
def test_held_out_frames_score_as_the_bench_reports():
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
    import depth  # bench/depth.py

    figures = depth.held_out_3d(FIXTURE / "depth.txt", holdout=0.2, block=5)
    assert figures["frames"] == 58 and figures["held_out"] == 10
    auc = figures["auc"]
    # Measured 0.833 for the local models, 0.646 for the 5 cm 3D log-odds grid, 0.786 for OctoMap.
    assert auc["parametric (local models)"] > 0.75
    assert auc["parametric (local models)"] > auc["grid 3D"]
