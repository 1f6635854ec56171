"""The counting-model grid (reflection map): :func:`counting_grid` from world-frame beams.

The other textbook grid of a laser's scans (Haehnel, Burgard et al.; the "counting model"
of Freiburg's mobile-robotics course): a cell's occupancy is the share of the beams
reaching it that returned there, ``hits / (hits + misses)``, where a beam *hits* the cell
holding its return and *misses* every cell it crosses before. Unlike the log-odds grid
(:mod:`occtool.grid._textbook`) every beam counts, not each scan once, and nothing is
clamped, so a wall cell grazed by a stream of beams keeps the frequency it reflected
them with. A Beta prior of ``prior`` pseudo-beams, half of them returns, pulls cells seen
by few beams towards 0.5: ``(hits + prior / 2) / (hits + misses + prior)``; ``prior = 0``
is the maximum-likelihood estimate. Cells no beam reached read 0.5.

The tallies are the per-scan ones of :class:`occtool.grid.ScanUpdates`, summed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.grid._textbook import ScanUpdates, WorldBeams, cell_values

FloatArray = NDArray[np.float64]

#: The counting model's default prior (pseudo-beams).
COUNTING_PRIOR = 1.0


def _check_prior(prior: float) -> float:
    if not (np.isfinite(prior) and prior >= 0):
        raise InputError(f"the counting model's prior must be a number of beams >= 0, got {prior}")
    return float(prior)


@dataclass(eq=False)
class CountingGrid:
    """A 2D grid of reflection probabilities: cell ``[i, j]`` spans ``[(lower + (i, j)) *
    resolution, + resolution)``.

    Parameters
    ----------
    probability
        ``(nx, ny)`` float32 occupancy, 0.5 where no beam reached.
    lower
        Integer index of cell ``[0, 0]`` on the lattice of multiples of ``resolution``.
    resolution
        Cell edge, metres.
    prior
        The Beta prior it was built with (pseudo-beams).
    """

    probability: NDArray[np.float32]
    lower: NDArray[np.int64]
    resolution: float
    prior: float

    @classmethod
    def from_updates(cls, updates: ScanUpdates, prior: float = COUNTING_PRIOR) -> CountingGrid:
        """Sum ``updates``' per-scan hits and misses per cell and turn them into probabilities."""
        prior = _check_prior(prior)
        cells = updates.shape[0] * updates.shape[1]
        hits = np.bincount(updates.key, weights=updates.hits, minlength=cells)
        seen = hits + np.bincount(updates.key, weights=updates.misses, minlength=cells)
        with np.errstate(invalid="ignore", divide="ignore"):
            p = np.where(seen > 0, (hits + 0.5 * prior) / (seen + prior), 0.5)
        return cls(p.astype(np.float32).reshape(updates.shape), updates.lower.copy(), updates.resolution, prior)

    @property
    def cells(self) -> int:
        return int(self.probability.size)

    @property
    def byte_size(self) -> int:
        """The grid at one byte a cell (its bounding box), bytes."""
        return self.cells

    def occupancy(self, points: ArrayLike) -> FloatArray:
        """Occupancy probability at ``(K, 2)`` or ``(K, 3)`` world points (z ignored); 0.5 outside."""
        values, inside = cell_values(points, self.lower, self.resolution, self.probability)
        out = np.full(inside.shape[0], 0.5)
        out[inside] = values
        return out


def counting_grid(beams: WorldBeams, resolution: float = 0.05, prior: float = COUNTING_PRIOR, *,
                  bounds: tuple[FloatArray, FloatArray] | None = None) -> CountingGrid:
    """The counting-model grid of ``beams`` (module docstring), over ``bounds`` (default: theirs).

    Parameters
    ----------
    beams
        World-frame beams (any order).
    resolution
        Cell edge, metres.
    prior
        Pseudo-beams of the Beta prior, half of them returns (0: hits / (hits + misses)).
    bounds
        ``(lower, upper)`` world corners the grid covers; beams' cells outside are dropped.
    """
    prior = _check_prior(prior)
    return CountingGrid.from_updates(ScanUpdates.from_beams(beams, resolution, bounds), prior)


__all__ = ["COUNTING_PRIOR", "CountingGrid", "counting_grid"]
