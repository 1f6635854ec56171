"""The scores: ROC AUC (of points, and of points counted per group), polygon IoU.

Nothing here imports above numpy, scipy and shapely, so every scorer (the grid tuner
included) can use them."""

from __future__ import annotations

from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray

from occtool._stats import roc_auc

FloatArray = NDArray[np.float64]

#: Grid (metres) every overlay of the scoring snap-rounds to. GEOS's overlay in floating
#: precision can return a wildly wrong result, silently, when two inputs have nearly
#: coincident edges (locationtech/jts#1000, shapely/shapely#1871): the intersection of two
#: polygons that only share an edge, its ends an ulp apart, can come out with square metres
#: of area. The scoring makes such edges by construction (grown footprints that touch, a
#: region traced to the obstacles it then has removed); snap-rounding to a fixed grid is
#: robust, and a nanometre changes no area measurably.
OVERLAY_GRID = 1e-9


def grouped_auc(values: NDArray[np.floating[Any]], occupied: FloatArray, free: FloatArray) -> float:
    """ROC AUC of points grouped by score: ``occupied[g]`` and ``free[g]`` points score
    ``values[g]`` (ties half: the figure :func:`roc_auc` gives the points). The grid tuner
    counts its test points per cell and ranks the cells, not every point."""
    distinct, inverse = np.unique(values, return_inverse=True)
    pos = np.bincount(inverse, weights=occupied, minlength=distinct.size)
    neg = np.bincount(inverse, weights=free, minlength=distinct.size)
    if pos.sum() == 0 or neg.sum() == 0:
        return float("nan")
    below = np.cumsum(neg) - neg
    return float(np.sum(pos * (below + 0.5 * neg)) / (pos.sum() * neg.sum()))


def polygon_iou(a: shapely.Geometry, b: shapely.Geometry) -> float:
    """Intersection over union of two areas; 1 when both are empty."""
    area_a, area_b = float(a.area), float(b.area)
    if area_a == 0.0 and area_b == 0.0:
        return 1.0
    overlap = float(shapely.intersection(a, b, grid_size=OVERLAY_GRID).area)
    union = area_a + area_b - overlap
    return overlap / union if union > 0 else 0.0


__all__ = ["OVERLAY_GRID", "grouped_auc", "polygon_iou", "roc_auc"]
