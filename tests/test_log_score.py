"""Scoring a map against scans: the Nav2 agreement per beam and per cell, on a hand-made raster."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occtool.features import Features, Pose, Position
from occtool.fuse import FREE, OCCUPIED, Raster
from occtool.scoring import nav2_agreement


def _scan(index: int, ends_x: list[float]) -> Position:
    """A scan from (0.5, 0.5) whose beams run along +x and return at ``ends_x`` (world x)."""
    points = np.array([[x - 0.5, 0.0, 0.0] for x in ends_x])
    return Position(index, Features(points, np.ones(len(ends_x))), Pose(0.5, 0.5, 0.0, 0.0))


@pytest.fixture
def corridor() -> Raster:
    """One row of ten 1 m cells from (0, 0); cells 4 and 8 occupied, the rest free."""
    cells = np.full((1, 10), FREE, dtype=np.uint8)
    cells[0, [4, 8]] = OCCUPIED
    return Raster(cells, 1.0, (0.0, 0.0), np.zeros((1, 10), np.float32), np.zeros((1, 10), bool))


def test_agreement_per_beam_and_per_cell_known_answer(corridor):
    # Scan 0: two beams end in cell 8 (occupied) and cross cell 4 (occupied) before their
    # 1 m margin; one ends in cell 4. Scan 1: one beam ends in cell 6 (free, neighbours
    # free) after crossing cell 4.
    scans = [_scan(0, [8.5, 8.7, 4.5]), _scan(1, [6.5])]
    got = nav2_agreement(corridor, scans, margin=1.0)
    # Per beam: 3 of 4 returns on occupied; only the beam to 4.5 (cells 0-3) is clear.
    assert got["returns_on_occupied"] == pytest.approx(3 / 4)
    assert got["beams_clear"] == pytest.approx(1 / 4)
    assert got["scans_returns_95"] == pytest.approx(1 / 2)
    assert got["scans_beams_95"] == 0.0 and got["scans_both_95"] == 0.0
    # Per cell: scan 0's end cells {4, 8} both occupied; its traversed cells 0-7 less its own
    # end cell 4: seven, all clear (the two beams to cell 8 count their cells once). Scan 1:
    # end cell 6 not occupied; traversed cells 0-5, cell 4 occupied: 5 of 6 clear.
    assert got["endpoint_cells_on_occupied"] == pytest.approx(2 / 3)
    assert got["traversed_cells_clear"] == pytest.approx(12 / 13)
    assert got["scans_endpoint_cells_95"] == pytest.approx(1 / 2)
    assert got["scans_traversed_cells_95"] == pytest.approx(1 / 2)
    assert got["scans_cells_both_95"] == pytest.approx(1 / 2)
    assert got["scans"] == 2


def test_a_neighbouring_occupied_cell_holds_a_return(corridor):
    # Cell 7 is not occupied but its neighbour 8 is: the return agrees, per beam and per cell.
    got = nav2_agreement(corridor, [_scan(0, [7.5])], margin=1.0)
    assert got["returns_on_occupied"] == 1.0 and got["endpoint_cells_on_occupied"] == 1.0
    # Cells 0-6 are crossed, 4 among them.
    assert got["beams_clear"] == 0.0
    assert got["traversed_cells_clear"] == pytest.approx(6 / 7)


def test_beams_leaving_the_raster_cross_no_occupied_cell(corridor):
    # A beam to x = 14.5 leaves the raster after cell 9: the cells beyond count, as not occupied.
    got = nav2_agreement(corridor, [_scan(0, [14.5])], margin=1.0)
    assert got["returns_on_occupied"] == 0.0
    assert got["traversed_cells_clear"] == pytest.approx(12 / 14)  # cells 0-13, two occupied
    assert math.isclose(got["scans_traversed_cells_95"], 0.0)
