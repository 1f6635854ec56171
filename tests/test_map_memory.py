"""Large runs: the raster built strip by strip is the raster cell by cell, and a run whose
estimated memory is over the user's limit is refused before any work, naming the option."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from _room_log import ROOM, write_room_log
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.fuse import load_map
from occtool.fuse._memory import check_map_memory, estimate_map_memory
from occtool.fuse._rasterise import raster_shape, rasterise
from occtool.fuse._tile_queries import cell_walls
from occtool.fuse._world import DOUBTED_TRUST, NEIGHBOURS, WorldMap
from occtool.io import read_log
from occtool.limits import memory_bytes
from occtool.raster import FREE, SpilledCells

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"


def test_the_raster_is_the_same_whatever_its_tiles_and_strips():
    """Tiles decide whole blocks of cells (inside or outside the observed region, out of
    every wall's reach): the cells, occupancy and explored flags are those of one tile
    holding the whole map, where every cell is queried on its own."""
    world = load_map(FIXTURES / "maps" / "intel.occmap")
    origin, nx, ny = raster_shape(world, 0.2)
    within = max(world.wall_half_width, world.wall_rim, world.doubted_wall_rim)
    whole = rasterise(world, 0.2, nx, ny, origin, within, DOUBTED_TRUST, tile=max(nx, ny), strip_cells=nx * ny)
    assert (whole.cells == 0).any() and (whole.cells == 254).any() and (whole.cells == 205).any()
    for tile, strip in ((5, 400), (16, 1 << 19)):
        tiled = rasterise(world, 0.2, nx, ny, origin, within, DOUBTED_TRUST, tile=tile, strip_cells=strip)
        assert np.array_equal(tiled.cells, whole.cells)
        assert np.array_equal(tiled.probability, whole.probability)
        assert np.array_equal(tiled.explored, whole.explored)
    assert np.array_equal(world.rasterise(0.2).cells, whole.cells)
    # Each band tests its cells against the regions cut to it: the answers of the whole ones.
    rows, cols = np.indices((ny, nx))
    centres = np.column_stack([origin[0] + (cols.ravel() + 0.5) * 0.2, origin[1] + (rows.ravel() + 0.5) * 0.2])
    observed = world.observed(centres).reshape(ny, nx)
    assert observed.any() and not observed.all()
    may_be_free = observed & world.free_space(centres).reshape(ny, nx)
    assert not (tiled.cells == FREE)[~may_be_free].any()
    assert np.asarray(tiled.explored, dtype=bool)[may_be_free].all()


@pytest.mark.parametrize(("columns", "rows"), [(16, 1), (48, 100), (64, 10_000), (128, 16)])
def test_the_raster_is_the_same_whatever_its_regions_blocks(monkeypatch, columns, rows):
    """Bands of rows grouped to share the regions cut once (BLOCK_ROWS), and the regions
    cut again into blocks of columns (BLOCK_COLUMNS) that their tiles are sorted against
    and their cells tested against: the raster of one tile holding the whole map."""
    from occtool.fuse import _rasterise

    world = load_map(FIXTURES / "maps" / "intel.occmap")
    origin, nx, ny = raster_shape(world, 0.1)
    within = max(world.wall_half_width, world.wall_rim, world.doubted_wall_rim)
    whole = rasterise(world, 0.1, nx, ny, origin, within, DOUBTED_TRUST, tile=max(nx, ny), strip_cells=nx * ny)
    monkeypatch.setattr(_rasterise, "BLOCK_COLUMNS", columns)
    monkeypatch.setattr(_rasterise, "BLOCK_ROWS", rows)
    blocks = _rasterise._band_blocks(world, _rasterise._centres(origin[0], 0.1, nx), 0.1, origin[1], 0, ny, 16)
    assert blocks[0].count == -(-nx // max(16, columns // 16 * 16)) > 1
    tiled = rasterise(world, 0.1, nx, ny, origin, within, DOUBTED_TRUST, strip_cells=nx * 16)
    assert np.array_equal(tiled.cells, whole.cells) and np.array_equal(tiled.probability, whole.probability)
    assert np.array_equal(tiled.explored, whole.explored)


@pytest.mark.parametrize("count", [5, 600])
def test_the_walls_from_one_query_a_cell_are_those_of_two(count):
    """The crowded cells' walls from one neighbour query a cell (cell_walls) are the numbers
    of _wall_values and _wall_distances, bit for bit: short segments on a 5 cm grid (several
    on one middle), points between them, ties at the last neighbour among them."""
    import shapely

    rng = np.random.default_rng(count)
    middles = rng.integers(0, 30, (count, 2)) * 0.05
    angle = rng.integers(0, 8, count) * (np.pi / 8)
    half = rng.integers(1, 4, count) * 0.025
    offset = np.column_stack([np.cos(angle), np.sin(angle)]) * half[:, None]
    world = WorldMap(middles - offset, middles + offset, rng.integers(0, 3, count) * 0.01,
                     rng.integers(0, 5, count) / 4, shapely.box(-1, -1, 3, 3), band=(-0.25, 0.2),
                     facing=rng.integers(-1, 2, count))
    xy = np.stack(np.meshgrid(np.arange(-10, 70) * 0.025, np.arange(-10, 70) * 0.025), axis=-1).reshape(-1, 2)
    within = max(world.wall_half_width, world.wall_rim, world.doubted_wall_rim)
    got = cell_walls(world, xy, within, DOUBTED_TRUST)
    expected = (*world._wall_values(xy), *world._wall_distances(xy, within, DOUBTED_TRUST))
    for a, b in zip(got, expected, strict=True):
        assert a.tobytes() == b.tobytes()
    assert np.isfinite(got[0]).any() and np.isfinite(got[3]).any() and not np.isfinite(got[2]).all()
    if count > NEIGHBOURS:
        distance = world._segment_tree().query(xy, k=NEIGHBOURS + 1)[0]
        assert (distance[:, -2] == distance[:, -1]).any(), "some points should tie at the last neighbour"


@pytest.fixture(scope="module")
def room_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("room") / "room.log"
    write_room_log(path, scans=10)
    return path


def test_the_estimate_finds_the_rooms_raster(room_log):
    """The raster is estimated from the positions and their returns: the room's 8 x 4.5 m at 5 cm."""
    estimate = estimate_map_memory(read_log(room_log))
    rows, columns = estimate.raster_shape
    width, height = ROOM[2] - ROOM[0], ROOM[3] - ROOM[1]
    assert abs(columns * 0.05 - width) <= 0.2 and abs(rows * 0.05 - height) <= 0.2
    coarse = estimate_map_memory(read_log(room_log), resolution=0.1)
    assert coarse.parts["raster"] < estimate.parts["raster"] / 3
    assert estimate.total == sum(estimate.parts.values())


def test_a_run_over_the_limit_is_refused_naming_the_keyword_and_the_flag(room_log):
    from occtool.cli.wording import as_flags

    log = read_log(room_log)
    assert check_map_memory(log).total < 10**9  # the default limit passes a room
    assert check_map_memory(log, memory_limit=None).total > 0
    with pytest.raises(InputError, match=r"over the limit of 1 MB: raise it with memory_limit='1G'") as caught:
        check_map_memory(log, memory_limit="1M")
    assert "--memory-limit 1G" in as_flags(str(caught.value))


@pytest.mark.parametrize(("given", "size"), [("500M", 5 * 10**8), ("8G", 8 * 10**9), (" 1.5 TB", 15 * 10**11),
                                             (4096, 4096), ("none", None), (None, None)])
def test_memory_sizes(given, size):
    assert memory_bytes(given) == size


@pytest.mark.parametrize("given", ["", "lots", "-1G", "0", "nanG", "inf", True, "1e30G"])
def test_a_memory_limit_that_is_no_size_is_refused(given):
    with pytest.raises(InputError, match="memory_limit must be a size"):
        memory_bytes(given)


def test_the_command_line_refuses_with_the_flag(room_log, tmp_path):
    """``occtool map --memory-limit 1M`` is refused in one line naming ``--memory-limit``,
    before any output is written."""
    from occtool.cli.main import cli

    if "--memory-limit" not in CliRunner().invoke(cli, ["map", "--help"]).output:
        pytest.skip("occtool map does not take --memory-limit yet (occtool.cli.options.memory_limit_option)")
    result = CliRunner().invoke(cli, ["map", str(room_log), "-o", str(tmp_path / "out"), "--memory-limit", "1M",
                                      "--sensor-height", "0.3", "--body-height", "0.5"])
    assert result.exit_code != 0
    assert "--memory-limit 1G" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "out").exists()
    bad = CliRunner().invoke(cli, ["map", str(room_log), "-o", str(tmp_path / "out"), "--memory-limit", "lots"])
    assert bad.exit_code == 2 and "--memory-limit" in bad.output


def test_map_pgm_written_in_strips_is_the_whole_image(tmp_path, monkeypatch):
    """The PGM is written a few rows at a time, top row first, with the bytes of one copy."""
    import occtool.formats.nav2 as nav2

    pixels = np.random.default_rng(0).choice(np.array([0, 205, 254], dtype=np.uint8), size=(37, 11))
    monkeypatch.setattr(nav2, "_STRIP_BYTES", 30)  # two rows a strip, the last strip one row
    _, image = nav2.write_nav2(pixels, 0.05, (0.0, 0.0), tmp_path / "map.yaml")
    data = image.read_bytes()
    header = b"P5\n# occtool fused map\n11 37\n255\n"
    assert data == header + pixels[::-1].tobytes()
    assert np.array_equal(nav2.read_nav2(tmp_path / "map.yaml").cells == -1, pixels == 205)


def test_the_memory_limit_option_passes_a_size_on_and_refuses_anything_else():
    import click

    from occtool.cli.options import memory_limit_option

    @click.command()
    @memory_limit_option
    def command(memory_limit):
        click.echo(repr(memory_limit))

    assert CliRunner().invoke(command, []).output.strip() == "'4G'"
    assert CliRunner().invoke(command, ["--memory-limit", "500M"]).output.strip() == "'500M'"
    assert CliRunner().invoke(command, ["--memory-limit", "none"]).output.strip() == "None"
    bad = CliRunner().invoke(command, ["--memory-limit", "lots"])
    assert bad.exit_code == 2 and "Invalid value for '--memory-limit': must be a size" in bad.output


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_a_scale_map_built_in_strips_is_the_whole_image(tmp_path, monkeypatch, dtype):
    """The RGBA image of a scale map is filled a few rows at a time, flipped: its pixels are
    those of the whole-array formula (grey 255 (1 - p), transparent where unknown)."""
    pytest.importorskip("PIL")
    from PIL import Image

    import occtool.formats.nav2 as nav2

    rng = np.random.default_rng(1)
    occupancy = rng.random((23, 9)).astype(dtype)
    occupancy[rng.random(occupancy.shape) < 0.3] = np.nan
    monkeypatch.setattr(nav2, "_STRIP_BYTES", 20)  # two rows a strip, the last one row
    _, image = nav2.write_nav2_scale(occupancy, 0.05, (0.0, 0.0), tmp_path / "map.yaml")
    known = np.isfinite(occupancy)
    grey = np.rint(255.0 * (1.0 - np.where(known, occupancy, 0.5))).astype(np.uint8)
    expected = np.stack([grey, grey, grey, np.where(known, 255, 0).astype(np.uint8)], axis=-1)[::-1]
    with Image.open(image) as read:
        assert np.array_equal(np.asarray(read), expected)
    occupancy[5, 5] = 1.5
    with pytest.raises(InputError, match=r"must lie in \[0, 1\]"):
        nav2.write_nav2_scale(occupancy, 0.05, (0.0, 0.0), tmp_path / "bad.yaml")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_frontiers_found_in_strips_are_those_of_the_whole_raster(seed):
    """Frontiers cut by strip boundaries are joined again (8-connected): the points, their
    order and their bits are frontiers_of's, for strips of one row up to the whole raster."""
    from occtool.fuse import frontiers_of
    from occtool.fuse._frontiers import frontiers_in_strips
    from occtool.raster import Raster

    rng = np.random.default_rng(seed)
    shape = (41, 29)
    cells = rng.choice(np.array([0, 205, 254], dtype=np.uint8), size=shape, p=[0.1, 0.3, 0.6])
    explored = rng.random(shape) < 0.5 if seed else None
    raster = Raster(cells, 0.05, (-1.0, 2.0), np.zeros(shape, np.float32), np.zeros(shape, bool), explored=explored)
    for length in (0.05, 0.15):
        whole = frontiers_of(raster, length)
        assert len(whole) >= 1
        for strip in (1, 29 * 3, 29 * 7 + 5, 10**6):
            assert np.array_equal(frontiers_in_strips(raster, length, strip_cells=strip), whole)
    raster = load_map(FIXTURES / "maps" / "fr079.occmap").rasterise(0.1)
    assert np.array_equal(frontiers_in_strips(raster, 0.5, strip_cells=5000), frontiers_of(raster))


def test_a_raster_without_occupancy_holds_two_bytes_a_cell_and_the_same_cells():
    """A large raster keeps no float32 occupancy and no conflict flags of its own; its
    cells, explored flags and counts are those of the raster that keeps them."""
    world = load_map(FIXTURES / "maps" / "intel.occmap")
    full = world.rasterise(0.2, occupancy=True)
    lean = world.rasterise(0.2, occupancy=False)
    assert lean.probability is None and full.probability is not None
    assert np.array_equal(lean.cells, full.cells) and np.array_equal(lean.explored, full.explored)
    assert lean.counts() == full.counts() and lean.conflict.strides == (0, 0)
    with pytest.raises(InputError, match="without its occupancy"):
        lean.graded()


def test_the_mcap_grid_of_a_large_raster_is_drawn_in_blocks():
    """Over the grid's cell cap each k x k block is occupied when a cell of it is, else free
    when one is; under it the grid is the cells themselves."""
    from occtool.formats.foxglove import grid_values
    from occtool.raster import FREE, OCCUPIED, UNKNOWN, Raster

    cells = np.full((5, 7), UNKNOWN, dtype=np.uint8)
    cells[0, 0] = OCCUPIED
    cells[0, 1] = FREE
    cells[3, 4] = FREE
    cells[4, 6] = OCCUPIED
    raster = Raster(cells, 0.1, (0.0, 0.0), None, np.zeros(cells.shape, dtype=bool))
    values, k = grid_values(raster)
    assert k == 1 and values.tolist() == np.select([cells == FREE, cells == OCCUPIED], [0, 100], -1).tolist()
    values, k = grid_values(raster, max_cells=12)
    assert k == 2 and values.shape == (3, 4)
    assert values[0, 0] == 100 and values[1, 2] == 0 and values[2, 3] == 100 and values[0, 1] == -1


@settings(max_examples=60, deadline=None)
@given(rows=st.integers(1, 30), cols=st.integers(1, 30), seed=st.integers(0, 2**16), cap=st.integers(1, 300))
def test_the_mcap_grid_blocks_are_the_block_rule_cell_by_cell(rows, cols, seed, cap):
    """The grid's k x k blocks (a maximum of ranks by columns, then rows) are what each block's
    cells say: 100 when one is occupied, else 0 when one is free, else -1, for any shape
    (blocks cut at the raster's edges) and strip of rows."""
    from occtool.formats.foxglove import grid_values
    from occtool.raster import OCCUPIED, UNKNOWN, Raster

    rng = np.random.default_rng(seed)
    cells = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN, 17], dtype=np.uint8), size=(rows, cols),
                       p=[0.2, 0.05, 0.7, 0.05])
    values, k = grid_values(Raster(cells, 0.1, (0.0, 0.0), None, np.zeros(cells.shape, dtype=bool)), max_cells=cap)
    assert values.shape == (-(-rows // k), -(-cols // k)) and values.dtype == np.int8
    for i in range(values.shape[0]):
        for j in range(values.shape[1]):
            block = cells[i * k:(i + 1) * k, j * k:(j + 1) * k]
            assert values[i, j] == (100 if (block == OCCUPIED).any() else 0 if (block == FREE).any() else -1)


def test_a_raster_larger_than_the_old_cell_cap_is_estimated_not_refused(room_log):
    """The cap is the memory estimate: past the MCAP grid's cap a trinary raster costs two
    bytes a cell more (its cells and explored flags), not a refusal for its cell count."""
    from occtool.fuse._memory import TRINARY_CELL_BYTES

    log = read_log(room_log)
    fine, finer = estimate_map_memory(log, resolution=0.0005), estimate_map_memory(log, resolution=0.0004)
    cells = [rows * columns for rows, columns in (fine.raster_shape, finer.raster_shape)]
    assert 50_000_000 < cells[0] < cells[1]
    assert finer.parts["raster"] - fine.parts["raster"] == TRINARY_CELL_BYTES * (cells[1] - cells[0])
    check_map_memory(log, resolution=0.0004)  # 0.2 G cells under the default 4G


def test_a_trinary_run_holds_no_occupancy_and_a_scale_map_of_it_is_drawn_again(room_log, tmp_path):
    """A trinary map's raster keeps two bytes a cell; writing the run as a scale map draws
    the occupancy again, the same as a scale run's own."""
    pytest.importorskip("PIL")
    from occtool.fit import OccupancyRegressor
    from occtool.fuse import map_log, write_run_map
    from occtool.robot import Robot

    estimator = OccupancyRegressor(pieces=8, robot=Robot(sensor_height=0.3, body_height=0.5))
    trinary = map_log(room_log, tmp_path / "t", estimator=estimator, read_options={"no_return_range": 5.0},
                      mcap=False)
    scale = map_log(room_log, tmp_path / "s", estimator=estimator, read_options={"no_return_range": 5.0},
                    mcap=False, nav2_mode="scale")
    assert trinary.run.raster.probability is None and scale.run.raster.probability is not None
    assert np.array_equal(trinary.run.raster.cells, scale.run.raster.cells)
    write_run_map(trinary.run, tmp_path / "again", nav2_mode="scale", mcap=False)
    assert (tmp_path / "again" / "map.png").read_bytes() == (tmp_path / "s" / "map.png").read_bytes()


@settings(max_examples=40, deadline=None)
@given(rows=st.integers(1, 40), cols=st.integers(1, 9), seed=st.integers(0, 2**16), step=st.integers(1, 7))
def test_spilled_cells_read_as_the_array_they_hold(tmp_path_factory, rows, cols, seed, step):
    """Cells kept in a file (a large raster's) answer slices, index arrays, comparisons and
    pickling as the array written into them a band at a time, and leave no file behind."""
    import pickle

    folder = tmp_path_factory.mktemp("spill")
    rng = np.random.default_rng(seed)
    array = rng.choice(np.array([0, 205, 254], dtype=np.uint8), size=(rows, cols))
    cells = SpilledCells((rows, cols), 205, folder)
    assert np.array_equal(np.asarray(cells), np.full((rows, cols), 205))
    for low in range(0, rows, step):
        cells[low:low + step] = array[low:low + step]
    assert cells.shape == array.shape and cells.size == array.size and len(cells) == rows
    assert np.array_equal(np.asarray(cells), array)
    low, high = sorted(rng.integers(0, rows + 1, size=2).tolist())
    assert np.array_equal(cells[low:high], array[low:high])
    row, col = rng.integers(0, rows, size=15), rng.integers(0, cols, size=15)
    assert np.array_equal(cells[row, col], array[row, col])
    assert np.array_equal(cells[-1], array[-1]) and np.array_equal(cells == 254, array == 254)
    assert np.array_equal(pickle.loads(pickle.dumps(cells)), array)
    assert not list(folder.iterdir())  # an unnamed file


def test_a_spilled_raster_is_the_raster_in_memory_in_every_file(tmp_path):
    """A raster whose cells wait in a file gives the same cells, counts, frontiers, Nav2 map
    and MCAP grid as the one held in memory."""
    from occtool.formats.foxglove import grid_values
    from occtool.formats.nav2 import write_nav2
    from occtool.fuse._frontiers import frontiers_in_strips

    world = load_map(FIXTURES / "maps" / "intel.occmap")
    origin, nx, ny = raster_shape(world, 0.1)
    within = max(world.wall_half_width, world.wall_rim, world.doubted_wall_rim)
    held = rasterise(world, 0.1, nx, ny, origin, within, DOUBTED_TRUST, occupancy=False)
    spilled = rasterise(world, 0.1, nx, ny, origin, within, DOUBTED_TRUST, occupancy=False, spill=tmp_path,
                        spill_cells=0)
    assert isinstance(spilled.cells, SpilledCells) and isinstance(held.cells, np.ndarray)
    assert np.array_equal(spilled.cells, held.cells) and spilled.counts() == held.counts()
    assert np.array_equal(frontiers_in_strips(spilled, 0.5, strip_cells=nx * 7),
                          frontiers_in_strips(held, 0.5, strip_cells=nx * 7))
    assert np.array_equal(grid_values(spilled, max_cells=nx * ny // 5)[0], grid_values(held, max_cells=nx * ny // 5)[0])
    for name in ("held", "spilled"):
        (tmp_path / name).mkdir()
    _, held_image = write_nav2(held.cells, 0.1, origin, tmp_path / "held" / "map.yaml")
    _, spilled_image = write_nav2(spilled.cells, 0.1, origin, tmp_path / "spilled" / "map.yaml")
    assert held_image.read_bytes() == spilled_image.read_bytes()
    assert sorted(path.name for path in tmp_path.iterdir()) == ["held", "spilled"]


def test_a_lean_run_keeps_its_large_raster_in_a_file_and_writes_the_same_map(room_log, tmp_path, monkeypatch):
    """``map_log(lean=True)`` keeps a raster larger than SPILL_CELLS in the output's folder
    (no file left there) and writes the files of a run that held it."""
    import occtool.fuse._rasterise as rasterising
    from occtool.fit import OccupancyRegressor
    from occtool.fuse import map_log
    from occtool.robot import Robot

    estimator = OccupancyRegressor(pieces=8, robot=Robot(sensor_height=0.3, body_height=0.5))
    options = {"estimator": estimator, "read_options": {"no_return_range": 5.0}, "mcap": False}
    held = map_log(room_log, tmp_path / "held", **options)
    monkeypatch.setattr(rasterising, "SPILL_CELLS", 0)
    spilled = map_log(room_log, tmp_path / "spilled", lean=True, **options)
    assert isinstance(spilled.run.raster.cells, SpilledCells) and isinstance(held.run.raster.cells, np.ndarray)
    for name in ("map.pgm", "world.occmap", "navigation.geojson", "frontiers.geojson"):
        assert (tmp_path / "held" / name).read_bytes() == (tmp_path / "spilled" / name).read_bytes()
    assert sorted(path.name for path in tmp_path.iterdir()) == ["held", "spilled"]


def test_a_region_cut_along_its_own_edge_keeps_only_its_polygons():
    """A region whose boundary runs along the cut's edge leaves lines there (a collection);
    the cut keeps its polygons, which answer as the region does inside the rectangle."""
    import shapely

    from occtool.fuse._rasterise import _cut

    region = shapely.MultiPolygon([shapely.box(0, 0, 2, 2), shapely.box(3, 1, 5, 2)])
    rectangle = (-1.0, -1.0, 6.0, 1.0)
    assert shapely.intersection(region, shapely.box(*rectangle)).geom_type == "GeometryCollection"
    piece = _cut(region, rectangle)
    assert piece.geom_type == "MultiPolygon" and shapely.equals(piece, shapely.box(0, 0, 2, 1))
    x, y = np.meshgrid(np.linspace(-0.9, 5.9, 35), np.linspace(-0.9, 0.9, 10))
    assert np.array_equal(shapely.contains_xy(piece, x, y), shapely.contains_xy(region, x, y))
