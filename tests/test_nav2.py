"""Nav2 map files: written by occtool, read back by map_server's rules."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.formats.nav2 import (
    CELL_FREE,
    CELL_OCCUPIED,
    CELL_UNKNOWN,
    read_nav2,
    write_nav2,
)


def test_round_trip_by_map_server_rules(tmp_path):
    rng = np.random.default_rng(1)
    pixels = rng.choice(np.array([254, 0, 205], dtype=np.uint8), size=(7, 11))
    yaml_path, image = write_nav2(pixels, 0.05, (-1.5, 2.25), tmp_path / "map.yaml")
    loaded = read_nav2(yaml_path)
    expected = np.select([pixels == 254, pixels == 0], [CELL_FREE, CELL_OCCUPIED], CELL_UNKNOWN)
    assert (loaded.cells == expected).all()
    assert loaded.resolution == 0.05 and loaded.origin == (-1.5, 2.25, 0.0)
    assert (loaded.negate, loaded.occupied_thresh, loaded.free_thresh, loaded.mode) == (0, 0.65, 0.196, "trinary")
    assert image.name == "map.pgm" and loaded.image == "map.pgm"


def test_unknown_pixel_stays_unknown_by_the_yaml_thresholds(tmp_path):
    # 205 is p = 50/255 = 0.196...: a free_thresh of 0.25 would load it as free.
    write_nav2(np.full((1, 1), 205, dtype=np.uint8), 0.05, (0.0, 0.0), tmp_path / "map.yaml")
    loaded = read_nav2(tmp_path / "map.yaml")
    assert loaded.free_thresh < 50 / 255 < loaded.occupied_thresh
    assert loaded.cells[0, 0] == CELL_UNKNOWN


def test_bottom_row_is_the_origin(tmp_path):
    pixels = np.full((4, 3), 254, dtype=np.uint8)
    pixels[0, 0] = 0  # the cell at the origin (lower left)
    write_nav2(pixels, 0.1, (0.0, 0.0), tmp_path / "map.yaml")
    raw = (tmp_path / "map.pgm").read_bytes()
    body = np.frombuffer(raw[-12:], dtype=np.uint8).reshape(4, 3)
    # PGM's first row is the top of the map, so the origin's pixel is in its last row.
    assert body[-1, 0] == 0 and body[0, 0] == 254
    assert read_nav2(tmp_path / "map.yaml").cells[0, 0] == CELL_OCCUPIED


def test_writer_refuses_what_is_not_an_image(tmp_path):
    with pytest.raises(InputError):
        write_nav2(np.zeros((0, 3), dtype=np.uint8), 0.05, (0, 0), tmp_path / "map.yaml")
    with pytest.raises(InputError):
        write_nav2(np.zeros((2, 3), dtype=np.float32), 0.05, (0, 0), tmp_path / "map.yaml")
    assert not list(tmp_path.iterdir())


@given(st.binary(max_size=64))
def test_any_broken_image_is_an_input_error(tmp_path_factory, data):
    folder = tmp_path_factory.mktemp("fuzz")
    (folder / "map.yaml").write_text("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.25\n")
    (folder / "map.pgm").write_bytes(data)
    try:
        loaded = read_nav2(folder / "map.yaml")
    except InputError:
        return
    assert loaded.cells.dtype == np.int8


@given(st.integers(0, 6), st.integers(0, 6), st.binary(max_size=40))
def test_a_pgm_of_the_wrong_size_is_an_input_error(tmp_path_factory, width, height, body):
    folder = tmp_path_factory.mktemp("fuzz")
    (folder / "map.yaml").write_text("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    (folder / "map.pgm").write_bytes(f"P5\n{width} {height}\n255\n".encode() + body)
    try:
        loaded = read_nav2(folder / "map.yaml")
    except InputError as exc:
        # A short file and a padded one alike: the header must say the file's length.
        assert width * height == 0 or len(body) != width * height
        assert "\n" not in str(exc) and str(exc).startswith(str(folder / "map.pgm"))
        return
    assert len(body) == width * height
    assert loaded.cells.shape == (height, width)


def test_scale_map_by_map_server_rules(tmp_path):
    from occtool.formats.nav2 import write_nav2_scale

    occupancy = np.array([[0.1, 0.3, 0.45], [0.9, np.nan, 1.0]], dtype=np.float32)
    yaml_path, image = write_nav2_scale(occupancy, 0.05, (-1.0, 0.5), tmp_path / "map.yaml")
    assert image.name == "map.png"
    loaded = read_nav2(yaml_path)
    assert (loaded.mode, loaded.occupied_thresh, loaded.free_thresh) == ("scale", 0.65, 0.25)
    # map_server: p < 0.25 free, p > 0.65 occupied, between rint(100 (p - 0.25) / 0.4); the
    # PNG holds p to 1/255, so a graded cell may move by one.
    assert loaded.cells[0, 0] == CELL_FREE
    assert abs(int(loaded.cells[0, 1]) - 12.5) <= 1.5 and abs(int(loaded.cells[0, 2]) - 50) <= 1
    assert loaded.cells[1, 0] == CELL_OCCUPIED and loaded.cells[1, 2] == CELL_OCCUPIED
    assert loaded.cells[1, 1] == CELL_UNKNOWN


def test_scale_map_is_rgba_with_the_origin_in_the_last_row(tmp_path):
    from PIL import Image

    from occtool.formats.nav2 import write_nav2_scale

    occupancy = np.zeros((3, 2), dtype=np.float32)
    occupancy[0, 0] = 1.0  # the cell at the origin (lower left)
    occupancy[2, 1] = np.nan
    write_nav2_scale(occupancy, 0.1, (0.0, 0.0), tmp_path / "map.yaml")
    with Image.open(tmp_path / "map.png") as image:
        # map_saver writes scale maps as true colour with alpha (GraphicsMagick's grey + alpha
        # loads badly), its first row the top of the map.
        assert image.mode == "RGBA"
        pixels = np.asarray(image)
    assert tuple(pixels[-1, 0]) == (0, 0, 0, 255) and tuple(pixels[0, 1])[3] == 0
    assert tuple(pixels[0, 0]) == (255, 255, 255, 255)


@given(st.lists(st.one_of(st.floats(0.0, 1.0), st.just(float("nan"))), min_size=1, max_size=30))
def test_scale_map_keeps_occupied_free_and_unknown(tmp_path_factory, values):
    from occtool.formats.nav2 import write_nav2_scale

    folder = tmp_path_factory.mktemp("scale")
    occupancy = np.array(values, dtype=np.float64).reshape(1, -1)
    write_nav2_scale(occupancy, 0.05, (0.0, 0.0), folder / "map.yaml")
    cells = read_nav2(folder / "map.yaml").cells[0]
    # Within the PNG's 1/255 of the thresholds a cell may load either way; past it, never.
    assert (cells[occupancy[0] > 0.65 + 1 / 255] == CELL_OCCUPIED).all()
    assert (cells[occupancy[0] < 0.25 - 1 / 255] == CELL_FREE).all()
    assert ((cells == CELL_UNKNOWN) == np.isnan(occupancy[0])).all()


def test_scale_writer_refuses_bad_occupancy(tmp_path):
    from occtool.formats.nav2 import write_nav2_scale

    with pytest.raises(InputError, match=r"\[0, 1\]"):
        write_nav2_scale(np.full((2, 2), 1.5), 0.05, (0, 0), tmp_path / "map.yaml")
    with pytest.raises(InputError):
        write_nav2_scale(np.zeros((2, 2), dtype=np.uint8), 0.05, (0, 0), tmp_path / "map.yaml")
    assert not list(tmp_path.iterdir())


def test_an_unread_mode_is_an_input_error(tmp_path):
    write_nav2(np.full((2, 2), 254, dtype=np.uint8), 0.05, (0.0, 0.0), tmp_path / "map.yaml")
    text = (tmp_path / "map.yaml").read_text().replace("mode: trinary", "mode: raw")
    (tmp_path / "map.yaml").write_text(text)
    with pytest.raises(InputError, match="raw"):
        read_nav2(tmp_path / "map.yaml")


@given(st.binary(max_size=80))
def test_any_broken_png_is_an_input_error(tmp_path_factory, data):
    folder = tmp_path_factory.mktemp("fuzz")
    (folder / "map.yaml").write_text("image: map.png\nmode: scale\nresolution: 0.05\norigin: [0, 0, 0]\n"
                                     "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n")
    # Behind PNG's signature, so that the bytes reach the decoder.
    (folder / "map.png").write_bytes(b"\x89PNG\r\n\x1a\n" + data)
    try:
        loaded = read_nav2(folder / "map.yaml")
    except InputError:
        return
    assert loaded.cells.dtype == np.int8


def test_a_png_too_large_to_decode_is_refused_from_its_header(tmp_path):
    import struct
    import zlib

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    # A header and a sliver of data: 8,000 x 8,000 RGBA pixels would inflate to 256 MB.
    header = struct.pack(">IIBBBBB", 8_000, 8_000, 8, 6, 0, 0, 0)
    (tmp_path / "map.png").write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
                                       + chunk(b"IDAT", zlib.compress(b"\0" * 64)))
    (tmp_path / "map.yaml").write_text("image: map.png\nmode: scale\nresolution: 0.05\norigin: [0, 0, 0]\n"
                                       "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n")
    # Decoded whole, about a gigabyte: over a limit of 500 MB, refused before Pillow sees it.
    with pytest.raises(InputError, match=r"a 8000x8000 map image needs about 1\.0 GB of memory to read, over the "
                                         r"limit of 0\.5 GB: raise it with memory_limit='2G'"):
        read_nav2(tmp_path / "map.yaml", memory_limit="500M")


def _pgm_map(folder, pixels, resolution=0.05):
    folder.mkdir(exist_ok=True)
    write_nav2(pixels, resolution, (-2.0, 3.0), folder / "map.yaml")
    return folder / "map.yaml"


def test_a_map_over_the_memory_limit_is_refused_before_its_pixels_are_read(tmp_path):
    from occtool.formats.nav2 import nav2_shape, read_memory

    yaml_path = _pgm_map(tmp_path / "map", np.full((300, 400), 254, dtype=np.uint8))
    assert nav2_shape(yaml_path) == (300, 400)
    need = read_memory(300, 400)
    assert need >= 300 * 400  # a byte a cell kept, and a strip's temporaries
    (tmp_path / "map" / "map.pgm").chmod(0o200)  # the header is read; the pixels would be too if not refused
    try:
        with pytest.raises(InputError, match=r"map\.pgm: a 400x300 map image needs about .* of memory to read, "
                                             r"over the limit of under 1 MB: raise it with memory_limit='1G'"):
            read_nav2(yaml_path, memory_limit=need - 1)
    finally:
        (tmp_path / "map" / "map.pgm").chmod(0o600)
    assert read_nav2(yaml_path, memory_limit=need).cells.shape == (300, 400)
    assert read_nav2(yaml_path, memory_limit=None).cells.shape == (300, 400)
    # Read 10 times coarser it needs less: a byte a block and one strip.
    assert read_memory(300, 400, decimate=10) < need


@given(st.integers(1, 40), st.integers(1, 40), st.integers(1, 9), st.integers(0, 2**32 - 1))
def test_a_map_read_decimated_is_its_cells_reduced_block_by_block(tmp_path_factory, rows, cols, factor, seed):
    from occtool.formats.nav2 import decimate_cells

    rng = np.random.default_rng(seed)
    pixels = rng.choice(np.array([254, 0, 205], dtype=np.uint8), size=(rows, cols), p=[0.6, 0.1, 0.3])
    yaml_path = _pgm_map(tmp_path_factory.mktemp("dec") / "map", pixels)
    whole = read_nav2(yaml_path)
    reduced = read_nav2(yaml_path, decimate=factor)
    assert reduced.decimation == factor and whole.decimation == 1 and reduced.resolution == whole.resolution
    assert reduced.cells.shape == (-(-rows // factor), -(-cols // factor))
    np.testing.assert_array_equal(reduced.cells, decimate_cells(whole.cells, factor))
    # Block by block: its largest cell (row 0 the bottom), unknown only where every cell is.
    j, i = rng.integers(0, reduced.cells.shape[0]), rng.integers(0, reduced.cells.shape[1])
    assert reduced.cells[j, i] == whole.cells[j * factor:(j + 1) * factor, i * factor:(i + 1) * factor].max()


def test_a_pgm_is_read_in_strips_of_rows(tmp_path, monkeypatch):
    from occtool.formats import nav2

    # Strips of 3 rows (and of 2 blocks of 3 rows when decimated): the same cells as one read.
    pixels = np.random.default_rng(4).choice(np.array([254, 0, 205], dtype=np.uint8), size=(17, 5))
    yaml_path = _pgm_map(tmp_path / "map", pixels)
    whole, reduced = read_nav2(yaml_path).cells, read_nav2(yaml_path, decimate=3).cells
    monkeypatch.setattr(nav2, "_READ_STRIP_CELLS", 15)
    np.testing.assert_array_equal(read_nav2(yaml_path).cells, whole)
    np.testing.assert_array_equal(read_nav2(yaml_path, decimate=3).cells, reduced)
    monkeypatch.setattr(nav2, "_READ_STRIP_CELLS", 1)
    np.testing.assert_array_equal(read_nav2(yaml_path, decimate=3).cells, reduced)


def test_a_png_map_reads_decimated_too(tmp_path):
    from occtool.formats.nav2 import decimate_cells, write_nav2_scale

    occupancy = np.random.default_rng(5).random((23, 31))
    occupancy[3:6, 4:9] = np.nan
    write_nav2_scale(occupancy, 0.1, (0.0, 0.0), tmp_path / "map.yaml")
    whole = read_nav2(tmp_path / "map.yaml")
    np.testing.assert_array_equal(read_nav2(tmp_path / "map.yaml", decimate=4).cells, decimate_cells(whole.cells, 4))


@pytest.mark.parametrize("factor", [0, -1, 1.5, True, "2"])
def test_a_decimation_is_a_whole_number_from_one(tmp_path, factor):
    yaml_path = _pgm_map(tmp_path / "map", np.full((2, 2), 254, dtype=np.uint8))
    with pytest.raises(InputError, match="decimate must be a whole number >= 1"):
        read_nav2(yaml_path, decimate=factor)


@pytest.mark.parametrize("maxval", [15, 255, 1000, 65535])
def test_a_pgm_sample_is_a_fraction_of_its_maxval(tmp_path, maxval):
    # White (maxval) is free, black occupied, 80 % grey (p = 0.2: between the thresholds) unknown.
    values = np.array([[maxval, 0, round(0.8 * maxval)]])
    dtype = np.dtype(np.uint8) if maxval < 256 else np.dtype(">u2")
    (tmp_path / "map.pgm").write_bytes(f"P5\n3 1\n{maxval}\n".encode() + values.astype(dtype).tobytes())
    (tmp_path / "map.yaml").write_text("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                                       "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert read_nav2(tmp_path / "map.yaml").cells.tolist() == [[CELL_FREE, CELL_OCCUPIED, CELL_UNKNOWN]]
