"""Log-odds: :func:`logit`, :func:`probability` and OctoMap's fusion parameters."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError

FloatArray = NDArray[np.float64]


def logit(p: ArrayLike) -> FloatArray:
    """Log-odds ``log(p / (1 - p))`` of a probability."""
    p = np.asarray(p, dtype=np.float64)
    return np.log(p) - np.log1p(-p)


def probability(log_odds: ArrayLike) -> FloatArray:
    """Probability from log-odds (the inverse of :func:`logit`)."""
    return 1.0 / (1.0 + np.exp(-np.asarray(log_odds, dtype=np.float64)))


@dataclass(frozen=True)
class LogOddsParams:
    """Log-odds fusion parameters, named and defaulted as in OctoMap.

    Parameters
    ----------
    prob_hit
        Probability an observation in the cell holding a feature stands for (0.7).
    prob_miss
        Probability an observation in a cell the ray crosses stands for (0.4).
    clamping_thres_min, clamping_thres_max
        The fused probability is clamped to this interval (0.1192, 0.971), so that a cell
        can change its state again after many observations.
    occupancy_thres
        Probability at and above which OctoMap calls a cell occupied (0.5); occtool's
        navigation uses its own ``--threshold`` instead.
    """

    prob_hit: float = 0.7
    prob_miss: float = 0.4
    clamping_thres_min: float = 0.1192
    clamping_thres_max: float = 0.971
    occupancy_thres: float = 0.5

    def __post_init__(self) -> None:
        for name in ("prob_hit", "prob_miss", "clamping_thres_min", "clamping_thres_max", "occupancy_thres"):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise InputError(f"{name} must lie strictly between 0 and 1, got {value}")
        if not self.clamping_thres_min < self.clamping_thres_max:
            raise InputError("clamping_thres_min must be below clamping_thres_max")
        if not self.prob_miss < self.prob_hit:
            raise InputError("prob_miss must be below prob_hit")

    @property
    def clamp_log_odds(self) -> tuple[float, float]:
        """The clamping thresholds in log-odds."""
        return float(logit(self.clamping_thres_min)), float(logit(self.clamping_thres_max))


OCTOMAP_DEFAULTS = LogOddsParams()
