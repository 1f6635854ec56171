"""A map's expensive work on a Dask cluster (``scheduler=``, ``--scheduler``): the keyframes'
fits, the navigation maps and the raster's bands of rows run there, and the files are the
same bytes as a run in this process; a missing dask or an unreachable scheduler is one line."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from _room_log import write_room_log
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.fit import OccupancyRegressor
from occtool.fuse import load_map, map_log
from occtool.fuse._rasterise import raster_shape, rasterise
from occtool.fuse._world import DOUBTED_TRUST

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
READ = {"no_return_range": 5.0}
ROBOT = {"sensor_height": 0.3, "body_height": 0.5}
FILES = ("world.occmap", "map.pgm", "map.yaml", "map.mcap", "navigation.geojson", "obstacles.geojson",
         "frontiers.geojson")


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    import dask

    from occtool.executor import DASK_CLUSTER_CONFIG

    with dask.config.set(DASK_CLUSTER_CONFIG):
        local = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None)
        with local, distributed.Client(local) as client:
            yield client


def _estimator():
    from occtool.robot import Robot

    return OccupancyRegressor(pieces=8, robot=Robot(**ROBOT))


def test_a_two_worker_cluster_maps_the_same_bytes_as_this_process(tmp_path, cluster):
    log = tmp_path / "room.log"
    write_room_log(log, scans=12)
    here = map_log(log, tmp_path / "here", estimator=_estimator(), read_options=READ, keyframe_share=0.0)
    there = map_log(log, tmp_path / "there", estimator=_estimator(), read_options=READ, keyframe_share=0.0,
                    scheduler=cluster)
    assert here.report.positions == there.report.positions == 12
    assert (here.run.raster.cells == 254).any() and (here.run.raster.cells == 0).any()
    for name in FILES:
        assert (tmp_path / "here" / name).read_bytes() == (tmp_path / "there" / name).read_bytes(), name


def test_the_raster_in_many_bands_on_a_cluster_is_the_raster_here(cluster):
    """Bands finish in any order on the workers; they are placed by their rows."""
    from occtool.executor import DaskExecutor

    world = load_map(FIXTURES / "maps" / "intel.occmap")
    origin, nx, ny = raster_shape(world, 0.2)
    within = max(world.wall_half_width, world.wall_rim, world.doubted_wall_rim)
    here = rasterise(world, 0.2, nx, ny, origin, within, DOUBTED_TRUST)
    there = rasterise(world, 0.2, nx, ny, origin, within, DOUBTED_TRUST, tile=4, strip_cells=nx * 4,
                      executor=DaskExecutor(cluster))
    assert ny > 4 * 4 * 4  # several bands of BAND_STRIPS strips
    for name in ("cells", "probability", "explored"):
        assert np.array_equal(getattr(here, name), getattr(there, name)), name


def _map(tmp_path, *extra):
    log = tmp_path / "room.log"
    write_room_log(log, scans=3)
    return CliRunner().invoke(cli, ["map", str(log), "-o", str(tmp_path / "out"), "--sensor-height", "0.3",
                                    "--body-height", "0.5", "--no-return-range", "5", *extra])


def test_a_missing_dask_is_one_line_naming_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed fails
    result = _map(tmp_path, "--scheduler", "tcp://127.0.0.1:8786")
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit) and "Traceback" not in result.output
    assert "occtool[dask]" in result.output and len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_an_unreachable_scheduler_is_one_line_before_any_fit(tmp_path, monkeypatch):
    distributed = pytest.importorskip("distributed")

    class Refused(distributed.Client):  # as a closed port answers, without the 10 s wait
        def __init__(self, address, **kwargs):
            raise OSError(f"Timed out trying to connect to {address} after 10 s")

    monkeypatch.setattr(distributed, "Client", Refused)
    result = _map(tmp_path, "--scheduler", "tcp://127.0.0.1:1")
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit) and "Traceback" not in result.output
    assert "cannot connect to the Dask scheduler at tcp://127.0.0.1:1" in result.output
    assert not (tmp_path / "out").exists()
