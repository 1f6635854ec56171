"""The combination rules: how the models that speak at a point make one occupancy there.

Log-odds (OctoMap's clamping), Dempster-Shafer (conjunctive rule, conflict, pignistic
probability) and the plain mean, summed per point over the speaking models in one pass
(:class:`_Sums`); the positions' nearest returns join the result as a noisy-or.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

COMBINATIONS = ("log_odds", "dempster_shafer", "mean")
#: Measured on Intel (docs/map.md): the combination ``FusedMap`` uses unless told.
DEFAULT_COMBINATION = "log_odds"
#: OctoMap's clamping of a single observation's probability before it becomes log-odds.
CLAMP = (0.12, 0.97)
#: Share of a model's mass committed to occupied/free in the Dempster-Shafer combination.
DS_CONFIDENCE = 0.9
#: Conflict mass above which positions are said to contradict each other at a point.
CONFLICT_FLAG = 0.3
#: Occupancy a position's return lends a query point at its spot, and the width (metres) of
#: that kernel, ``amplitude * exp(-(d / width)**2)``, joined to the models' fused occupancy
#: as a noisy-or (docs/map.md: AUC 0.954 -> 0.982 on Intel's held-out blocks).
RETURN_KERNEL = (0.8, 0.05)


@dataclass
class Evidence:
    """The fused evidence at some points (arrays of one value per point).

    ``count``: models that speak there (0: unknown); ``probability``: the fused occupancy
    (0.5 where unknown); ``belief_occupied``, ``belief_free``, ``unknown_mass`` and
    ``conflict``: the normalised Dempster-Shafer masses and the conflict before
    normalising (plausibility of occupied = 1 - belief_free).
    """

    count: NDArray[np.int32]
    probability: FloatArray
    belief_occupied: FloatArray
    belief_free: FloatArray
    unknown_mass: FloatArray
    conflict: FloatArray

    @property
    def observed(self) -> NDArray[np.bool_]:
        return self.count > 0

    @property
    def contradicted(self) -> NDArray[np.bool_]:
        return self.conflict > CONFLICT_FLAG


@dataclass
class _Sums:
    """Per-point running sums over the models that speak there."""

    n: int
    count: NDArray[np.int32] = field(init=False)
    logit: FloatArray = field(init=False)
    total: FloatArray = field(init=False)
    log_q_occ: FloatArray = field(init=False)
    log_q_free: FloatArray = field(init=False)
    #: Per point, the occupancy the nearest return lends it (:data:`RETURN_KERNEL`); None: none.
    return_kernel: FloatArray | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        self.count = np.zeros(self.n, dtype=np.int32)
        self.logit = np.zeros(self.n)
        self.total = np.zeros(self.n)
        self.log_q_occ = np.zeros(self.n)
        self.log_q_free = np.zeros(self.n)

    def add(self, index: NDArray[np.intp], occupancy: FloatArray) -> None:
        # ``index`` holds each point at most once per model, so plain fancy += is exact.
        p = np.clip(occupancy, 0.0, 1.0)
        clamped = np.clip(p, *CLAMP)
        self.count[index] += 1
        self.logit[index] += np.log(clamped) - np.log1p(-clamped)
        self.total[index] += p
        unknown = 1.0 - DS_CONFIDENCE
        self.log_q_occ[index] += np.log(DS_CONFIDENCE * p + unknown)
        self.log_q_free[index] += np.log(DS_CONFIDENCE * (1.0 - p) + unknown)

    def evidence(self, combination: str) -> Evidence:
        count = self.count
        seen = count > 0
        # Conjunctive rule through commonalities: Q(A) multiplies over sources.
        q_unknown = np.where(seen, (1.0 - DS_CONFIDENCE) ** count.astype(np.float64), 1.0)
        q_occ = np.where(seen, np.exp(self.log_q_occ), 1.0)
        q_free = np.where(seen, np.exp(self.log_q_free), 1.0)
        m_occ = q_occ - q_unknown
        m_free = q_free - q_unknown
        conflict = np.clip(1.0 - m_occ - m_free - q_unknown, 0.0, 1.0)
        norm = np.maximum(1.0 - conflict, 1e-300)
        belief_occ, belief_free, unknown_mass = m_occ / norm, m_free / norm, q_unknown / norm
        if combination == "log_odds":
            from scipy.special import expit

            probability = expit(self.logit)
        elif combination == "dempster_shafer":
            probability = belief_occ + 0.5 * unknown_mass
        else:
            probability = self.total / np.maximum(count, 1)
        probability = np.where(seen, probability, 0.5)
        if self.return_kernel is not None:
            # Noisy-or: occupied if the models say so or a return lies there.
            probability = 1.0 - (1.0 - probability) * (1.0 - self.return_kernel)
        return Evidence(count, probability, belief_occ, belief_free, unknown_mass, conflict)
