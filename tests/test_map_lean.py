"""A large run's memory (issue 36): ``map_log(lean=True)`` (the command line's way) holds
only what the files need, the raster's explored flags are packed eight a byte, the free
region's tiles are decided whole, and the GeoJSON layers and the MCAP are written as they
are made; every file is the same bytes as before."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import shapely
from _room_log import write_room_log
from hypothesis import given
from hypothesis import strategies as st

from occtool.fit import OccupancyRegressor
from occtool.fuse import map_log
from occtool.fuse._outlines import SpilledNavigation
from occtool.raster import PackedFlags
from occtool.robot import Robot

READ = {"no_return_range": 5.0}
FILES = ("world.occmap", "map.pgm", "map.yaml", "map.mcap", "navigation.geojson", "obstacles.geojson",
         "frontiers.geojson")


def _estimator():
    return OccupancyRegressor(pieces=8, robot=Robot(sensor_height=0.3, body_height=0.5))


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    folder = tmp_path_factory.mktemp("lean")
    log = folder / "room.log"
    write_room_log(log, scans=12)
    full = map_log(log, folder / "full", estimator=_estimator(), read_options=READ, keyframe_share=0.0)
    lean = map_log(log, folder / "lean", estimator=_estimator(), read_options=READ, keyframe_share=0.0, lean=True)
    return folder, full, lean


def test_a_lean_run_writes_the_same_files(both):
    folder, full, lean = both
    for name in FILES:
        assert (folder / "full" / name).read_bytes() == (folder / "lean" / name).read_bytes(), name


def test_a_lean_run_lets_go_of_the_models_the_sightings_and_the_slices(both):
    _, full, lean = both
    assert len(full.models) == 12 and full.report.sightings is not None
    assert any(p.nav.slices for p in full.run.placed)
    assert lean.models == [] and lean.report.sightings is None
    assert all(p.nav.slices == [] for p in lean.run.placed)
    # What the files are made of is kept.
    assert [p.position for p in lean.run.placed] == [p.position for p in full.run.placed]
    # The polygons waited in a file, and come back to the bit.
    assert all(isinstance(p.nav, SpilledNavigation) for p in lean.run.placed)
    assert all(shapely.to_wkb(a.nav.polygon) == shapely.to_wkb(b.nav.polygon)
               for a, b in zip(lean.run.placed, full.run.placed))


def test_the_raster_keeps_its_explored_flags_packed(both):
    _, full, _ = both
    explored = full.run.raster.explored
    assert isinstance(explored, PackedFlags)
    assert explored.bits.nbytes == explored.shape[0] * -(-explored.shape[1] // 8)


@given(st.integers(1, 30), st.integers(1, 30), st.integers(0, 2**32 - 1))
def test_packed_flags_read_as_the_bool_array_they_hold(rows, cols, seed):
    rng = np.random.default_rng(seed)
    flags = rng.random((rows, cols)) < 0.4
    packed = PackedFlags((rows, cols))
    cut = int(rng.integers(0, rows + 1))
    packed[:cut], packed[cut:] = flags[:cut], flags[cut:]
    assert packed.shape == flags.shape and packed.size == flags.size
    np.testing.assert_array_equal(np.asarray(packed), flags)
    np.testing.assert_array_equal(~packed, ~flags)
    low, high = sorted(rng.integers(0, rows + 1, 2))
    np.testing.assert_array_equal(packed[low:high], flags[low:high])
    row, col = rng.integers(0, rows, 50), rng.integers(0, cols, 50)
    np.testing.assert_array_equal(packed[row, col], flags[row, col])
    assert packed[int(row[0]), int(col[0])] == flags[row[0], col[0]]


def test_the_free_regions_tiles_decided_whole_give_the_cells_tested_one_by_one(both, monkeypatch):
    from occtool.fuse import _rasterise

    _, full, _ = both
    world = full.run.world
    assert world.free_region is not None
    tiled = world.rasterise(0.05)
    monkeypatch.setattr(_rasterise, "_free_tiles", lambda free_region, boxes: None)
    one_by_one = world.rasterise(0.05)
    np.testing.assert_array_equal(tiled.cells, one_by_one.cells)
    np.testing.assert_array_equal(tiled.explored, one_by_one.explored)


def test_a_collection_is_dumped_as_json_dump_writes_it(both):
    from occtool.formats.geojson import dump_collection, run_map_layers

    _, full, _ = both
    run = full.run
    for precision in (None, 3):
        lists = run_map_layers(run.navigation, run.obstacles, run.frontiers, precision=precision)
        lazy = run_map_layers(run.navigation, run.obstacles, run.frontiers, precision=precision, lazy=True)
        for name, collection in lists.items():
            expected, written = io.StringIO(), io.StringIO()
            json.dump(collection, expected, separators=(",", ":"))
            dump_collection(lazy[name], written)
            assert written.getvalue() == expected.getvalue(), name


def test_a_consumed_log_is_used_up_as_it_is_fitted(tmp_path):
    from occtool.fuse import fuse_log
    from occtool.io import read_log

    log_path = tmp_path / "room.log"
    write_room_log(log_path, scans=6)
    kept, used = read_log(log_path, **READ), read_log(log_path, **READ)
    fused, models, report = fuse_log(kept, _estimator(), keyframe_share=0.0)
    fused_used, models_used, report_used = fuse_log(used, _estimator(), keyframe_share=0.0, consume=True)
    assert len(kept.positions) == 6 and used.positions == []
    assert report.fitted == report_used.fitted and len(models) == len(models_used) == 6
    np.testing.assert_array_equal(fused.returns, fused_used.returns)
    np.testing.assert_array_equal(fused.reaches, fused_used.reaches)
    assert [p.x for p in fused.poses] == [p.x for p in fused_used.poses]


def test_a_lean_3d_map_is_drawn_for_the_models_robot(tmp_path):
    """A 3D map's raster is its body band over the ground for the models' robot: mapped
    lean, the models are gone by then and the fused map's robot (the same one) is used."""
    rng = np.random.default_rng(4)
    floor = np.column_stack([rng.uniform(0.3, 6.0, 3000), rng.uniform(-3, 3, 3000), rng.normal(-0.08, 0.005, 3000)])
    walls = [np.column_stack([rng.uniform(0, 6, 600), np.full(600, side), rng.uniform(-0.08, 2.5, 600)])
             for side in (-3.0, 3.0)]
    scan = tmp_path / "scan.xyz"
    np.savetxt(scan, np.vstack([floor, *walls]), fmt="%.4f")
    robot = Robot(sensor_height=0.08, body_height=1.0)
    full = map_log(scan, tmp_path / "full", estimator=OccupancyRegressor(pieces=8, robot=robot), register=False,
                   world_resolution=0.2, mcap=False)
    lean = map_log(scan, tmp_path / "lean", estimator=OccupancyRegressor(pieces=8, robot=robot), register=False,
                   world_resolution=0.2, mcap=False, lean=True)
    assert full.summary["world_map"]["kind"] == "3d" and lean.models == []
    assert (full.run.raster.cells == 254).sum() > 1000
    for name in ("world.occmap", "map.pgm", "navigation.geojson", "obstacles.geojson", "frontiers.geojson"):
        assert (tmp_path / "full" / name).read_bytes() == (tmp_path / "lean" / name).read_bytes(), name
