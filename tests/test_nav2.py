"""Nav2 map files: written by occtool, read back by map_server's rules."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.io.nav2 import (
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
    except InputError:
        assert width * height == 0 or len(body) < width * height
        return
    assert loaded.cells.shape == (height, width)
