"""The textbook 2D grids (occtool.grid.textbook_grid, counting_grid) and their tuners
(occtool.scoring.tune_grids ...), on hand-made beams."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from occtool.errors import InputError
from occtool.grid import (
    ScanUpdates,
    TextbookParams,
    WorldBeams,
    counting_grid,
    textbook_grid,
)
from occtool.scoring import tune_counting, tune_grids, tune_textbook

ONE_METRE = TextbookParams(resolution=1.0)


def beams(*scans: list[tuple[float, float, bool]], start: tuple[float, float] = (0.5, 0.5)) -> WorldBeams:
    """Scans of beams from ``start`` to ``(x, y)``, each a return or (False) a free ray."""
    rows = [(k, x, y, hit) for k, scan in enumerate(scans) for x, y, hit in scan]
    return WorldBeams(np.tile(np.array(start, float), (len(rows), 1)), np.array([[r[1], r[2]] for r in rows]),
                      np.array([r[3] for r in rows]), np.array([r[0] for r in rows], dtype=np.intp))


def test_one_beam_frees_the_cells_it_crosses_and_marks_its_end():
    grid = textbook_grid(beams([(3.5, 0.5, True)]), ONE_METRE)
    # Cells 0, 1, 2 traversed, cell 3 holds the return.
    assert grid.log_odds.shape == (4, 1)
    np.testing.assert_allclose(grid.log_odds[:, 0], [-0.4, -0.4, -0.4, 0.85], rtol=1e-6)
    assert grid.byte_size == 4
    p = grid.occupancy(np.array([[0.5, 0.5], [3.2, 0.9], [9.0, 0.5]]))
    np.testing.assert_allclose(p, [1 / (1 + np.exp(0.4)), 1 / (1 + np.exp(-0.85)), 0.5])


def test_a_free_ray_only_frees_and_unseen_cells_read_half():
    # The second scan's beam is a free ray up to (0.5, 1.5): even its last cell is freed.
    grid = textbook_grid(beams([(1.5, 0.5, True)], [(0.5, 1.5, False)]), ONE_METRE)
    assert grid.log_odds.shape == (2, 2)
    np.testing.assert_allclose(grid.log_odds, [[-0.8, -0.4], [0.85, 0.0]], rtol=1e-6)
    # Cell (1, 1), which no beam reached: probability 0.5.
    assert grid.occupancy(np.array([[1.5, 1.5]]))[0] == pytest.approx(0.5)


def test_each_scan_updates_a_cell_once_and_its_return_wins():
    # One scan, two beams: one ends in cell 1, the other passes it to cell 3. Cell 1 gets
    # l_occ once (not l_occ + l_free), cell 0 l_free once (not twice).
    scan = [(1.5, 0.5, True), (3.5, 0.5, True)]
    grid = textbook_grid(beams(scan), ONE_METRE)
    np.testing.assert_allclose(grid.log_odds[:, 0], [-0.4, 0.85, -0.4, 0.85], rtol=1e-6)
    # Per beam, as the older grid: cell 0 crossed twice, cell 1 hit once and crossed once.
    per_beam = ScanUpdates.from_beams(beams(scan), 1.0).grid(ONE_METRE, per_scan=False)
    np.testing.assert_allclose(per_beam.log_odds[:, 0], [-0.8, 0.45, -0.4, 0.85], rtol=1e-6)


def test_clamping_after_every_scan():
    # Six scans see a wall in cell 3, then six scans see through it to cell 5.
    wall = [[(3.5, 0.5, True)]] * 6
    through = [[(5.5, 0.5, True)]] * 6
    built = beams(*wall, *through)
    grid = textbook_grid(built, ONE_METRE)
    # 6 x 0.85 = 5.1 clamps to 3.5, then six misses: 3.5 - 2.4 = 1.1; cells 0-2: clamped at -2.
    assert grid.log_odds[3, 0] == pytest.approx(1.1, rel=1e-6)
    np.testing.assert_allclose(grid.log_odds[:3, 0], -2.0)
    np.testing.assert_allclose(grid.log_odds[5, 0], 3.5)
    # Clamped once at the end instead: 5.1 - 2.4 = 2.7.
    once = ScanUpdates.from_beams(built, 1.0).grid(ONE_METRE, clamp_every_scan=False)
    assert once.log_odds[3, 0] == pytest.approx(2.7, rel=1e-6)


def test_bad_settings_are_one_line_errors():
    with pytest.raises(InputError):
        TextbookParams(l_free=0.1)
    with pytest.raises(InputError):
        TextbookParams(clamp=(1.0, 3.0))
    with pytest.raises(InputError):
        TextbookParams(resolution=0.0)
    with pytest.raises(InputError):
        WorldBeams(np.zeros((2, 2)), np.ones((2, 2)), np.ones(2, bool), np.array([1, 0]))


def test_the_counting_grid_counts_every_beam_and_clamps_nothing():
    # Scan 0: a beam returns in cell 1, another passes it to cell 3. Scan 1: a free ray to cell 2.
    # Hits / misses per cell: 0: 0/3, 1: 1/2, 2: 0/2 (the free ray ends there), 3: 1/0.
    built = beams([(1.5, 0.5, True), (3.5, 0.5, True)], [(2.5, 0.5, False)])
    grid = counting_grid(built, resolution=1.0, prior=0.0)
    assert grid.probability.shape == (4, 1) and grid.byte_size == 4
    np.testing.assert_allclose(grid.probability[:, 0], [0.0, 1 / 3, 0.0, 1.0], rtol=1e-6)
    # A prior of two pseudo-beams, one of them a return; a cell no beam reached reads 0.5.
    np.testing.assert_allclose(counting_grid(built, 1.0, prior=2.0).probability[:, 0], [0.2, 0.4, 0.25, 2 / 3],
                               rtol=1e-6)
    np.testing.assert_allclose(grid.occupancy(np.array([[1.2, 0.7, 3.0], [9.0, 9.0, 0.0], [np.nan, 0.0, 0.0]])),
                               [1 / 3, 0.5, 0.5])
    # Twelve scans hitting a cell then twelve seeing through it: half, where the clamped
    # log-odds grid ends wherever its bounds left it.
    wall, through = [[(3.5, 0.5, True)]] * 12, [[(5.5, 0.5, True)]] * 12
    assert counting_grid(beams(*wall, *through), 1.0, prior=0.0).probability[3, 0] == pytest.approx(0.5)
    with pytest.raises(InputError, match="prior"):
        counting_grid(built, 1.0, prior=-1.0)


def test_the_counting_tuner_picks_on_the_training_scans_and_shares_the_traversal():
    data = [name for name, p in inspect.signature(tune_counting).parameters.items()
            if p.kind is not inspect.Parameter.KEYWORD_ONLY]
    assert data == ["training"]
    training = _room_beams(40, seed=1)
    result = tune_counting(training, resolutions=(0.1,), priors=(0.0, 1.0, 4.0), holdout=0.2, block=5, seed=0)[0.1]
    assert [c["prior"] for c in result.candidates] == [0.0, 1.0, 4.0]
    assert result.inner_auc == max(c["inner_auc"] for c in result.candidates)
    np.testing.assert_array_equal(result.grid.probability, counting_grid(training, 0.1, result.prior).probability)
    # Both tuners from one call give what each gives alone.
    textbook, counting = tune_grids(training, resolutions=(0.1,), l_occ=(0.85,), l_free=(-0.4,), clamps=((-2.0, 3.5),),
                                    priors=(0.0, 1.0, 4.0), holdout=0.2, block=5, seed=0)
    assert counting[0.1].prior == result.prior and textbook[0.1].params.l_occ == 0.85
    with pytest.raises(InputError):
        tune_grids(training, l_occ=(), priors=())


def _room_beams(n_scans: int, seed: int) -> WorldBeams:
    """Scans from random places in a 4 x 3 m box, 90 beams each, returns on its walls."""
    rng = np.random.default_rng(seed)
    starts, ends, scan = [], [], []
    for k in range(n_scans):
        x, y = rng.uniform(0.5, 3.5), rng.uniform(0.5, 2.5)
        a = np.linspace(0, 2 * np.pi, 90, endpoint=False)
        dx, dy = np.cos(a), np.sin(a)
        with np.errstate(divide="ignore"):
            t = np.minimum(np.where(dx > 0, (4 - x) / dx, np.where(dx < 0, -x / dx, np.inf)),
                           np.where(dy > 0, (3 - y) / dy, np.where(dy < 0, -y / dy, np.inf)))
        starts.append(np.tile([x, y], (90, 1)))
        ends.append(np.column_stack([x + t * dx, y + t * dy]))
        scan.append(np.full(90, k))
    return WorldBeams(np.concatenate(starts), np.concatenate(ends), np.ones(90 * n_scans, bool),
                      np.concatenate(scan).astype(np.intp))


def test_the_tuner_sees_only_the_scans_it_is_given():
    # Its only data argument is the training scans: there is no way to hand it a held-out one.
    data = [name for name, p in inspect.signature(tune_textbook).parameters.items()
            if p.kind is not inspect.Parameter.KEYWORD_ONLY]
    assert data == ["training"]
    training = _room_beams(40, seed=1)
    tuned = tune_textbook(training, resolutions=(0.1,), l_occ=(0.85, 2.5), l_free=(-0.4, -0.05),
                          clamps=((-2.0, 3.5),), holdout=0.2, block=5, seed=0)
    result = tuned[0.1]
    assert len(result.candidates) == 4
    assert result.inner_auc == max(c["inner_auc"] for c in result.candidates)
    # Rebuilt from every training scan, over their box.
    np.testing.assert_array_equal(result.grid.log_odds, textbook_grid(training, result.params).log_odds)
    # Too few scans for an inner split: the defaults, said so.
    few = tune_textbook(_room_beams(3, seed=2), resolutions=(0.1,), block=5)[0.1]
    assert few.params.l_occ == 0.85 and "not tuned" in few.note


def test_textbook_scores_hand_the_tuner_the_training_scans_only(monkeypatch):
    import occtool.scoring._log
    from occtool.features import Features, Pose, Position
    from occtool.scoring import textbook_scores

    seen = []
    real = occtool.scoring._log.tune_grids

    def spy(training, **kwargs):
        seen.append(training)
        return real(training, **kwargs)

    monkeypatch.setattr(occtool.scoring._log, "tune_grids", spy)
    room = _room_beams(12, seed=3)
    train = [Position(k, Features(np.column_stack([room.end[room.scan == k] - room.start[room.scan == k],
                                                    np.zeros(90)]), np.ones(90)),
                      Pose(*room.start[room.scan == k][0], 0.0, 0.0)) for k in range(12)]
    held_out_points = np.array([[9.0, 9.0, 0.0], [1.0, 1.0, 0.0]])
    auc, settings = textbook_scores(train, held_out_points, 1, holdout=0.2, block=3, seed=0, resolutions=(0.1,))
    assert len(seen) == 1 and seen[0].n_scans == 12
    np.testing.assert_allclose(seen[0].end, room.end)
    assert set(auc) == {"textbook_0.1m", "textbook_fixed_0.1m", "counting_0.1m"}
    assert settings["textbook_0.1m"]["bytes"] > 40 * 30 and settings["counting_0.1m"]["prior"] >= 0


def test_the_tuners_grouped_auc_is_the_points_auc():
    from occtool.scoring import grouped_auc, roc_auc

    rng = np.random.default_rng(4)
    occupied, free = rng.integers(0, 6, 300), rng.integers(0, 6, 500)
    values = np.linspace(0.1, 0.9, 6)
    grouped = grouped_auc(values, np.bincount(occupied, minlength=6).astype(float),
                          np.bincount(free, minlength=6).astype(float))
    assert grouped == pytest.approx(roc_auc(values[occupied], values[free]))
