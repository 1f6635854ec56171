"""Where the floor lies: the lowest large horizontal layer, supported across many positions.

The most populated horizontal layer of a cloud is often not the floor: a table top seen
from above by a hand-held camera holds more returns than the floor around it, and a
scanner a few centimetres above the ground sees a layer of ground that says nothing of
what lies below the table. The floor is instead found in two steps:

* per position, :func:`lowest_layer`: among that position's returns below its sensor,
  the lowest horizontal layer (``LAYER`` thick) that holds a share of them
  (``MIN_SHARE``) and is spread over a floor-sized area in x-y (``MIN_AREA``);
* across positions, :func:`common_floor`: the per-position layers (in one world frame)
  grouped where they agree within a tolerance, and the lowest group that enough
  positions support (``MIN_POSITION_SHARE``) is the floor, at its median. A layer only
  a few positions see (a reflection, one frame pointed under a bed) is not the floor,
  and nor is a layer above another supported one (a table top).

Used by the depth folders' levelling (:func:`occtool.io.depth.estimate_floor`), by the
check of the data against the robot's sensor height (:mod:`occtool.modelset._settings`)
and by :func:`occtool.sensor.geometry_findings`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: A horizontal layer's thickness, metres (a Kinect's floor at 3 m spreads over about this).
LAYER = 0.06
#: The height histogram's bin, metres (a third of a layer: layers are windows of 3 bins).
BIN = LAYER / 3.0
#: A layer holds at least this share of its position's returns below the sensor ...
MIN_SHARE = 0.05
#: ... and at least this many of them.
MIN_POINTS = 20
#: A layer's returns cover at least this much of the x-y plane, square metres ...
MIN_AREA = 1.0
#: ... counted in square cells this wide, metres.
AREA_CELL = 0.2
#: Positions' floors agree within this height, metres.
AGREE = 0.1
#: The floor is seen by at least this share of the positions that see a layer at all ...
MIN_POSITION_SHARE = 0.2
#: ... and by at least this many (or by all of them, when fewer have a layer).
MIN_POSITIONS = 3


def lowest_layer(points: ArrayLike, top: float = np.inf) -> tuple[float, float] | None:
    """The lowest large horizontal layer among one position's returns below ``top``.

    Parameters
    ----------
    points
        ``(n, 3)`` returns in a frame whose z points up (the floor's normal).
    top
        The sensor's height in that frame: only returns lower than ``top - LAYER / 2`` count
        (a 2D laser's own plane is no layer); ``inf`` takes every return.

    Returns
    -------
    (height, share) or None
        The layer's height (the median of its returns) and the share of the returns below
        ``top`` it holds; ``None`` when no layer holds :data:`MIN_SHARE` of them and
        :data:`MIN_POINTS`, spread over :data:`MIN_AREA`.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> floor = np.column_stack([rng.uniform(-2, 2, (300, 2)), np.full(300, -1.0)])
    >>> table = np.column_stack([rng.uniform(0, 1, (900, 2)), np.full(900, -0.25)])
    >>> lowest_layer(np.vstack([floor, table]), top=0.0)
    (-1.0, 0.25)
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    below = p[p[:, 2] < top - LAYER / 2.0] if np.isfinite(top) else p[np.isfinite(p[:, 2])]
    n = below.shape[0]
    if n < MIN_POINTS:
        return None
    z = below[:, 2]
    low = float(z.min())
    edges = low + BIN * np.arange(int((float(z.max()) - low) / BIN) + 3)  # the last bin holds the highest
    counts, _ = np.histogram(z, bins=edges)
    window = np.convolve(counts, np.ones(3, dtype=np.int64), mode="same")  # bin k's layer: bins k-1 .. k+1
    supported = window >= max(MIN_POINTS, MIN_SHARE * n)
    # Runs of supported bins, lowest first: each run's fullest window is a layer.
    starts = np.flatnonzero(supported & ~np.r_[False, supported[:-1]])
    ends = np.flatnonzero(supported & ~np.r_[supported[1:], False])
    for start, end in zip(starts, ends):
        k = start + int(np.argmax(window[start:end + 1]))
        near = np.abs(z - (edges[k] + BIN / 2.0)) <= LAYER / 2.0
        cells = np.unique(np.floor(below[near, :2] / AREA_CELL).astype(np.int64), axis=0).shape[0]
        if cells * AREA_CELL ** 2 >= MIN_AREA:
            return round(float(np.median(z[near])), 6), round(float(np.count_nonzero(near)) / n, 6)
    return None


def common_floor(heights: ArrayLike, tolerance: float = AGREE) -> tuple[float, FloatArray] | None:
    """The floor the positions' lowest layers agree on: the lowest group of layers (heights
    within ``tolerance`` of their neighbours) that enough positions support.

    Parameters
    ----------
    heights
        Each position's :func:`lowest_layer` height in one world frame, NaN where it had none.

    Returns
    -------
    (floor, members) or None
        The group's median height and a boolean mask of the positions in the group;
        ``None`` when no group has :data:`MIN_POSITION_SHARE` of the positions with a layer
        and :data:`MIN_POSITIONS` of them (all of them when fewer have one).

    Examples
    --------
    >>> floor, members = common_floor([0.01, 0.75, -0.01, 0.0, 0.74, np.nan, -0.9])
    >>> floor, members.tolist()
    (0.0, [True, False, True, True, False, False, False])
    """
    h = np.asarray(heights, dtype=np.float64).ravel()
    valid = np.isfinite(h)
    n = int(np.count_nonzero(valid))
    if n == 0:
        return None
    ordered = np.sort(h[valid])
    need = max(min(MIN_POSITIONS, n), MIN_POSITION_SHARE * n)
    for group in np.split(ordered, np.flatnonzero(np.diff(ordered) > tolerance) + 1):
        if group.size >= need:
            return float(np.median(group)), valid & (h >= group[0]) & (h <= group[-1])
    return None


__all__ = ["AGREE", "LAYER", "MIN_AREA", "MIN_SHARE", "common_floor", "lowest_layer"]
