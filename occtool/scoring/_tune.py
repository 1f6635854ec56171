"""Tuning the textbook grids on training scans only: :func:`tune_textbook` (log-odds),
:func:`tune_counting` (counting model), :func:`tune_grids` (both from one traversal).

The tuner is handed the training scans and nothing else, so it cannot see a held-out
scan: it holds out its own *inner* blocks of them (the same protocol, and the same
generator of blocks and test points, as the outer split: :func:`holdout_blocks`,
:func:`beam_test_points`), builds a grid of the inner training scans for
every candidate setting, scores each on the inner held-out beams (returns occupied, points
along the beam up to 0.1 m before its end free; ROC AUC), keeps the best setting per
resolution and rebuilds it from all the training scans it was given.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.grid import (
    COUNTING_PRIOR,
    TEXTBOOK_DEFAULTS,
    CountingGrid,
    ScanUpdates,
    TextbookGrid,
    TextbookParams,
    WorldBeams,
    probability,
)
from occtool.scoring._heldout import BLOCK, HOLDOUT, beam_test_points, holdout_blocks
from occtool.scoring._metrics import grouped_auc

FloatArray = NDArray[np.float64]

#: Candidate settings: the textbook's 0.85 / -0.4 / [-2, 3.5] and a few around it.
RESOLUTIONS = (0.05, 0.1)
#: On Intel's training scans the inner AUC peaks on a flat ridge near l_occ / -l_free = 30-40
#: (l_occ 0.85-1.5 with l_free -0.02 to -0.05); FR-079's at the weakest l_free tried first
#: (-0.02), so -0.01 was added.
L_OCC = (0.85, 1.5, 2.5)
L_FREE = (-0.4, -0.2, -0.1, -0.05, -0.02, -0.01)
CLAMPS = ((-2.0, 3.5), (-1.0, 3.5), (-2.0, 6.0))
#: The counting model's candidate priors (pseudo-beams, half of them returns; 0: none).
COUNTING_PRIORS = (0.0, 0.5, 1.0, 2.0)


@dataclass
class TunedGrid:
    """The best setting at one resolution, the grid it builds from all training scans, and the search.

    ``inner_auc`` is the chosen setting's AUC on the inner held-out scans; ``candidates``
    lists every setting tried with its inner AUC; ``note`` says why no search was made
    (too few training scans for an inner split: the defaults are used).
    """

    params: TextbookParams
    grid: TextbookGrid
    inner_auc: float
    #: The textbook's fixed setting (:data:`TEXTBOOK_DEFAULTS`) at this resolution, from all training scans.
    default_grid: TextbookGrid
    candidates: list[dict[str, Any]] = field(default_factory=list)
    note: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {**self.params.as_dict(), "inner_auc": self.inner_auc, "bytes": self.grid.byte_size,
                "note": self.note, "candidates": self.candidates}


@dataclass
class TunedCounting:
    """The best counting-model prior at one resolution and the grid it builds from all
    training scans; ``candidates`` lists every prior tried with its inner AUC."""

    prior: float
    grid: CountingGrid
    inner_auc: float
    candidates: list[dict[str, Any]] = field(default_factory=list)
    note: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {"resolution": self.grid.resolution, "prior": self.prior, "inner_auc": self.inner_auc,
                "bytes": self.grid.byte_size, "note": self.note, "candidates": self.candidates}


def _cell_counts(updates: ScanUpdates, points: FloatArray) -> FloatArray:
    """How many of ``points`` fall in each cell of ``updates``' grid, one slot more for outside."""
    index = np.floor(points / updates.resolution).astype(np.int64) - updates.lower
    inside = np.all((index >= 0) & (index < np.array(updates.shape)), axis=1)
    cells = updates.shape[0] * updates.shape[1]
    flat = np.where(inside, index[:, 0] * updates.shape[1] + index[:, 1], cells)
    return np.bincount(flat, minlength=cells + 1).astype(np.float64)


def _inner_split(training: WorldBeams, holdout: float, block: int, seed: int) -> tuple[NDArray[np.bool_] | None, str]:
    """The inner held-out scans of ``training`` (``None`` and why when too few for a split)."""
    try:
        return holdout_blocks(training.n_scans, holdout, block, seed), ""
    except InputError as exc:
        return None, f"not tuned ({exc}): the defaults"


def _inner_cells(everything: ScanUpdates, training: WorldBeams, inner_held: NDArray[np.bool_],
                 seed: int) -> tuple[ScanUpdates, FloatArray, FloatArray, NDArray[np.intp]]:
    """The inner training scans' updates (theirs among all training scans', on the same cells)
    and the inner test points counted per cell (outside the box: one more cell, 0.5), so that a
    candidate ranks the cells, not every point (the same AUC): ``updates, pos, neg, used``."""
    updates = everything.of_scans(~inner_held)
    inner = training.of_scans(inner_held)
    occupied, free = beam_test_points(inner.start[inner.hit], inner.end[inner.hit], seed=seed)
    pos, neg = _cell_counts(updates, occupied), _cell_counts(updates, free)
    return updates, pos, neg, np.flatnonzero(pos + neg)


def _search_textbook(everything: ScanUpdates, training: WorldBeams, inner_held: NDArray[np.bool_] | None,
                     note: str, seed: int, l_occ: tuple[float, ...], l_free: tuple[float, ...],
                     clamps: tuple[tuple[float, float], ...]) -> TunedGrid:
    resolution = everything.resolution
    defaults = TextbookParams(resolution, TEXTBOOK_DEFAULTS.l_occ, TEXTBOOK_DEFAULTS.l_free, TEXTBOOK_DEFAULTS.clamp)
    default_grid = everything.grid(defaults)
    if inner_held is None:
        return TunedGrid(defaults, default_grid, float("nan"), default_grid, note=note)
    updates, pos, neg, used = _inner_cells(everything, training, inner_held, seed)
    candidates = []
    best: tuple[float, TextbookParams] | None = None
    for occ, fre, clamp in itertools.product(l_occ, l_free, clamps):
        params = TextbookParams(resolution, occ, fre, clamp)
        log_odds = np.append(updates.grid(params).log_odds.ravel(), np.float32(0.0))[used]
        # Ranked as probabilities, as the points are: a residual log-odds of 1e-17 is 0.5.
        auc = grouped_auc(probability(log_odds), pos[used], neg[used])
        candidates.append({**params.as_dict(), "inner_auc": auc})
        if best is None or auc > best[0]:
            best = (auc, params)
    assert best is not None  # at least one candidate
    return TunedGrid(best[1], everything.grid(best[1]), best[0], default_grid, candidates)


def _search_counting(everything: ScanUpdates, training: WorldBeams, inner_held: NDArray[np.bool_] | None,
                     note: str, seed: int, priors: tuple[float, ...]) -> TunedCounting:
    if inner_held is None:
        return TunedCounting(COUNTING_PRIOR, CountingGrid.from_updates(everything, COUNTING_PRIOR), float("nan"),
                             note=note)
    updates, pos, neg, used = _inner_cells(everything, training, inner_held, seed)
    candidates = []
    best: tuple[float, float] | None = None
    for prior in priors:
        p = np.append(CountingGrid.from_updates(updates, prior).probability.ravel(), np.float32(0.5))[used]
        auc = grouped_auc(p, pos[used], neg[used])
        candidates.append({"prior": prior, "inner_auc": auc})
        if best is None or auc > best[0]:
            best = (auc, prior)
    assert best is not None  # at least one candidate
    return TunedCounting(best[1], CountingGrid.from_updates(everything, best[1]), best[0], candidates)


def tune_textbook(training: WorldBeams, *, resolutions: tuple[float, ...] = RESOLUTIONS,
                  l_occ: tuple[float, ...] = L_OCC, l_free: tuple[float, ...] = L_FREE,
                  clamps: tuple[tuple[float, float], ...] = CLAMPS, holdout: float = HOLDOUT, block: int = BLOCK,
                  seed: int = 0) -> dict[float, TunedGrid]:
    """Pick the textbook grid's ``l_occ``, ``l_free`` and clamp per resolution on ``training`` alone.

    Parameters
    ----------
    training
        The training scans' beams: the only data the tuner sees.
    resolutions, l_occ, l_free, clamps
        The candidate settings (every combination per resolution).
    holdout, block, seed
        The inner split of ``training``: ``holdout`` of its scans in blocks of ``block``,
        picked with ``seed`` (and the free test points drawn with it).

    Returns
    -------
    dict
        Per resolution, a :class:`TunedGrid` rebuilt from all of ``training`` with the
        setting that scored best on the inner held-out scans (the first listed on a tie).
    """
    return tune_grids(training, resolutions=resolutions, l_occ=l_occ, l_free=l_free, clamps=clamps,
                      priors=(), holdout=holdout, block=block, seed=seed)[0]


def tune_counting(training: WorldBeams, *, resolutions: tuple[float, ...] = RESOLUTIONS,
                  priors: tuple[float, ...] = COUNTING_PRIORS, holdout: float = HOLDOUT, block: int = BLOCK,
                  seed: int = 0) -> dict[float, TunedCounting]:
    """Pick the counting-model grid's prior per resolution on ``training`` alone, by the same
    inner split as :func:`tune_textbook`; per resolution a :class:`TunedCounting` rebuilt
    from all of ``training`` (the first listed on a tie)."""
    return tune_grids(training, resolutions=resolutions, l_occ=(), priors=priors, holdout=holdout,
                      block=block, seed=seed)[1]


def tune_grids(training: WorldBeams, *, resolutions: tuple[float, ...] = RESOLUTIONS,
               l_occ: tuple[float, ...] = L_OCC, l_free: tuple[float, ...] = L_FREE,
               clamps: tuple[tuple[float, float], ...] = CLAMPS, priors: tuple[float, ...] = COUNTING_PRIORS,
               holdout: float = HOLDOUT, block: int = BLOCK,
               seed: int = 0) -> tuple[dict[float, TunedGrid], dict[float, TunedCounting]]:
    """Both tuners from one traversal per resolution: the log-odds grids (none when ``l_occ``
    is empty) and the counting-model grids (none when ``priors`` is empty)."""
    log_odds_wanted = bool(l_occ)
    if not resolutions or (log_odds_wanted and not (l_free and clamps)) or not (log_odds_wanted or priors):
        raise InputError("the tuner needs at least one resolution, l_occ, l_free and clamp (or prior) to try")
    inner_held, note = _inner_split(training, holdout, block, seed)
    bounds = training.bounds()
    textbook: dict[float, TunedGrid] = {}
    counting: dict[float, TunedCounting] = {}
    for resolution in resolutions:
        everything = ScanUpdates.from_beams(training, resolution, bounds)
        if log_odds_wanted:
            textbook[resolution] = _search_textbook(everything, training, inner_held, note, seed, l_occ, l_free, clamps)
        if priors:
            counting[resolution] = _search_counting(everything, training, inner_held, note, seed, priors)
    return textbook, counting


__all__ = ["TunedCounting", "TunedGrid", "tune_counting", "tune_grids", "tune_textbook"]
