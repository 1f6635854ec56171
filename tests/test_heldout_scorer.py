"""bench/heldout.py, the independent scorer: its AUC, its Nav2 reader, its CARMEN parser and split."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))

import heldout  # noqa: E402

from occtool.errors import InputError  # noqa: E402


def test_auc_known_answers():
    # Occupied 0.9, 0.5; free 0.5, 0.1, 0.3: pairs won 3 + (0.5 tie + 2) = 5.5 of 6.
    assert heldout.auc(np.array([0.9, 0.5]), np.array([0.5, 0.1, 0.3])) == pytest.approx(5.5 / 6)
    assert heldout.auc(np.ones(3), np.ones(4)) == pytest.approx(0.5)
    assert heldout.auc(np.array([2.0, 3.0]), np.array([0.0, 1.0])) == 1.0
    assert heldout.auc(np.array([0.0]), np.array([1.0, 2.0])) == 0.0
    rng = np.random.default_rng(0)
    a, b = rng.integers(0, 5, 200).astype(float), rng.integers(0, 5, 300).astype(float)
    brute = np.mean((a[:, None] > b[None, :]) + 0.5 * (a[:, None] == b[None, :]))
    assert heldout.auc(a, b) == pytest.approx(brute)
    # Grouped by score (the tuner's shortcut): the same figure.
    values = np.arange(5.0)
    grouped = heldout.grouped_auc(values, np.bincount(a.astype(int), minlength=5).astype(float),
                                  np.bincount(b.astype(int), minlength=5).astype(float))
    assert grouped == pytest.approx(brute)


def test_nav2_reader_against_occtools_writer(tmp_path):
    from occtool.formats.nav2 import write_nav2

    # Row 0 is the bottom (y = origin y): occupied at (col 1, row 0), unknown along the top row.
    pixels = np.full((3, 4), 254, dtype=np.uint8)
    pixels[0, 1] = 0
    pixels[2, :] = 205
    write_nav2(pixels, 0.5, (-1.0, 2.0), tmp_path / "map.yaml")
    loaded = heldout.read_nav2(tmp_path / "map.yaml")
    assert loaded.resolution == 0.5 and loaded.origin == (-1.0, 2.0, 0.0)
    expected = np.where(pixels == 0, 1.0, np.where(pixels == 254, 0.0, 0.5))
    np.testing.assert_array_equal(loaded.value, expected)
    # World points: the occupied cell spans x -0.5..0, y 2..2.5; off the map reads unknown.
    points = np.array([[-0.25, 2.25], [-0.75, 2.25], [0.2, 3.2], [5.0, 5.0]])
    np.testing.assert_array_equal(loaded.lookup(points), [1.0, 0.0, 0.5, 0.5])


def test_nav2_reader_of_a_scale_png_against_occtools_writer(tmp_path):
    from occtool.formats.nav2 import write_nav2_scale

    occupancy = np.array([[0.1, 0.45, 0.9], [np.nan, 0.2, 0.3]])
    write_nav2_scale(occupancy, 0.5, (0.0, 0.0), tmp_path / "map.yaml")
    loaded = heldout.read_nav2(tmp_path / "map.yaml")
    # map_server's cell / 100: free below 0.25, occupied above 0.65, between graded in
    # hundredths of the way (the PNG holds p to 1/255), transparent unknown.
    assert loaded.value[0, 0] == 0.0 and loaded.value[0, 2] == 1.0 and loaded.value[1, 0] == 0.5
    assert loaded.value[0, 1] == pytest.approx(0.5, abs=0.011) and loaded.value[1, 1] == 0.0
    assert loaded.value[1, 2] == pytest.approx(0.125, abs=0.011)
    # Before the thresholds: the pixels' own occupancy (to 1/255), transparent still 0.5.
    pixels = heldout.read_nav2(tmp_path / "map.yaml", thresholds=False).value
    assert pixels[0] == pytest.approx([0.1, 0.45, 0.9], abs=0.003)
    assert pixels[1] == pytest.approx([0.5, 0.2, 0.3], abs=0.003)


def test_nav2_reader_follows_negate_and_thresholds(tmp_path):
    (tmp_path / "m.pgm").write_bytes(b"P5\n# c\n3 1\n255\n" + bytes([0, 128, 255]))
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 1\norigin: [0, 0, 0]\nnegate: 1\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: trinary\n")
    # negate: p = v / 255: 0 free, 128 (0.50) unknown, 255 occupied.
    np.testing.assert_array_equal(heldout.read_nav2(tmp_path / "m.yaml").value, [[0.0, 0.5, 1.0]])
    (tmp_path / "bad.yaml").write_text("image: m.pgm\n")
    with pytest.raises(InputError):
        heldout.read_nav2(tmp_path / "bad.yaml")


def test_carmen_parser_split_and_test_points(tmp_path):
    path = tmp_path / "tiny.log"
    ranges = ["2.05"] * 179 + ["81.83"]
    lines = ["# comment", "ODOM 0 0 0 0 0 0 1 host 1"]
    for k in range(100):
        lines.append("FLASER 180 " + " ".join(ranges if k % 10 else ["81.83"] * 180)
                     + f" {k * 0.1} 1.0 0.0 0 0 0 {k} host {k}")
    path.write_text("\n".join(lines) + "\n")
    scans = heldout.parse_carmen(path)
    assert len(scans) == 100 and scans.lines[1].startswith("FLASER 180 2.05")
    # Beam 0 points right (-90 degrees), beam 90 forward; 81.83 repeats: no return.
    assert scans.angles[0, 0] == pytest.approx(-np.pi / 2) and scans.angles[0, 90] == pytest.approx(0.0)
    assert scans.no_return[1, 179] and not scans.no_return[1, 0] and scans.no_return[0].all()
    assert heldout.held_out(100, seed=0).sum() in (20, 40)  # one block of the three
    held = heldout.held_out(910, seed=3)
    assert held.sum() == 80 and (heldout.held_out(910, seed=3) == held).all()
    # Written apart from occtool's, it picks the same blocks as evaluate-log does.
    from occtool.scoring import holdout_blocks

    assert (holdout_blocks(910, 0.1, 40, seed=3) == held).all()
    starts = np.flatnonzero(np.diff(np.concatenate([[0], held.astype(int)])) == 1)
    assert all(s % 40 == 0 for s in starts)
    occupied, free = heldout.test_points(scans.take(np.arange(100) == 1))
    # One scan, 179 returns 2.05 m out: free points at 0.1 ... 1.9 m (19 a beam).
    assert occupied.shape == (179, 2) and free.shape == (179 * 19, 2)
    forward = free[np.abs(free[:, 1] - 1.0) < 1e-9]
    np.testing.assert_allclose(np.sort(forward[:, 0]) - 0.1, np.arange(1, 20) * 0.1, atol=1e-9)
    with pytest.raises(InputError):
        heldout.held_out(30, seed=0)
    (tmp_path / "bad.log").write_text("FLASER 180 1 2 3\n")
    with pytest.raises(InputError):
        heldout.parse_carmen(tmp_path / "bad.log")


def test_textbook_grid_of_one_beam():
    # One beam from (0.5, 0.5) to (3.5, 0.5) at 1 m: cells 0-2 free, 3 occupied.
    start, end = np.array([[0.5, 0.5]]), np.array([[3.5, 0.5]])
    box = (np.array([0.5, 0.5]), np.array([3.5, 0.5]))
    updates = heldout.scan_updates(start, end, np.array([True]), np.array([0]), 1, 1.0, box)
    np.testing.assert_allclose(updates.log_odds(0.85, -0.4, (-2.0, 3.5))[:, 0], [-0.4, -0.4, -0.4, 0.85])


def test_counting_grid_tallies_every_beam():
    # Two beams of one scan along y = 0.5 on a 1 m grid from x 0: one returns in cell 3, one
    # (a free ray) crosses cells 0-2 and ends in cell 2 without a return; a third beam of
    # another scan returns in cell 2. Misses count each beam, not once a scan.
    start = np.array([[0.5, 0.5], [0.5, 0.5], [0.5, 0.5]])
    end = np.array([[3.5, 0.5], [2.5, 0.5], [2.5, 0.5]])
    hit = np.array([True, False, True])
    hits, misses = heldout.beam_counts(start, end, hit, 1.0, np.array([0, 0]), (4, 1))
    np.testing.assert_array_equal(hits, [0, 0, 1, 1])
    np.testing.assert_array_equal(misses, [3, 3, 2, 0])
    p = heldout.counting_probability(np.append(hits, 0), np.append(misses, 0), prior=0.0)
    np.testing.assert_allclose(p, [0.0, 0.0, 1 / 3, 1.0, 0.5])
    # A prior of two beams, one of them a return, pulls every seen cell towards 0.5.
    np.testing.assert_allclose(heldout.counting_probability(hits, misses, prior=2.0), [0.2, 0.2, 0.4, 2 / 3])


def test_fused_row_says_not_available_without_the_map(tmp_path):
    # Either occtool.fuse has no load_map yet or the folder holds no world.occmap: a row, not an error.
    row = heldout.fused_row(tmp_path, np.zeros((3, 2)), 1)
    assert row["auc"] is None and row["note"].startswith("not available")
    assert heldout.nav2_row(tmp_path, np.zeros((3, 2)), 1)["note"].startswith("not available")


def _split(log, seed, world, best, world_bytes=40_000, grid_bytes=100_000):
    grids = [{"model": f"{family} 0.1 m, tuned on the training scans", "resolution": 0.1, "auc": auc,
              "bytes": grid_bytes, "family": family} for family, auc in (("log-odds", best), ("counting", best - 0.01))]
    return {"log": log, "seed": seed, "rows": [{"model": "fused map (world.occmap)", "auc": world,
                                                "bytes": world_bytes}, *grids]}


def test_the_every_split_target_fails_on_any_log_and_split():
    good = [_split("a-corrected.log.gz", s, 0.99, 0.98) for s in (0, 1, 2)]
    [(label, value, passed)] = heldout.every_split_target({"logs": good})
    assert passed and "3 splits of 1 logs" in value and "+0.0100" in value
    lost = good + [_split("b-corrected.log.gz", 1, 0.97, 0.98)]
    [(_, value, passed)] = heldout.every_split_target({"logs": lost})
    assert not passed and "b 1: 0.9700 < 0.9800" in value
    big = good + [_split("c-corrected.log.gz", 2, 0.99, 0.98, world_bytes=200_000)]
    [(_, value, passed)] = heldout.every_split_target({"logs": big})
    assert not passed and "c 2: 200 KB > 100 KB" in value
    # Issue 20's per-log targets stay the bench split's (seed 0).
    rows = heldout.heldout_targets({"logs": good})
    assert [row[0] for row in rows].count("a-corrected.log.gz: world.occmap and the Nav2 map scored") == 1
    assert heldout.every_split_target(None) == []
