"""Small statistics the fit needs, without numpy's general machinery.

``np.median`` imports ``numpy.ma`` on its first call (to ask whether its argument is a
masked array): 10-30 ms of a fresh process's CPU, paid by the first fit.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def median(values: ArrayLike) -> float:
    """``float(np.median(values))`` of a flat array: the middle value, or the mean of the
    middle two (their sum halved, as np.mean takes it); NaN if any value is NaN or there
    is none."""
    values = np.asarray(values, dtype=np.float64).ravel()
    if values.size == 0 or np.isnan(values).any():
        return float("nan")
    half = values.size // 2
    if values.size % 2:
        return float(np.partition(values, half)[half])
    ordered = np.partition(values, (half - 1, half))
    return float((ordered[half - 1] + ordered[half]) / 2.0)


__all__ = ["median"]
