"""What one position observed: its reach and first obstacle per pan bin, its nearest returns.

A local model only speaks where its position observed; these few hundred bytes, kept next
to the model (:class:`Observation`, in a model set's files), say where that is
(:class:`occtool.fuse.FusedMap` reads them). Also how many returns a degree a position
holds, which tells a scanning laser from a depth camera's clouds. Below :mod:`occtool.formats`
and :mod:`occtool.fuse`, which both use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError, ModelFormatError
from occtool.features import Features
from occtool.robot import Robot

FloatArray = NDArray[np.float64]

#: Pan-angle bins of a model's reach (the fit's own first-obstacle bins, 3 degrees).
REACH_BINS = 120
#: Reaches are kept in whole centimetres (uint16: up to 655 m).
REACH_UNIT = 0.01
#: A bin's first-obstacle value where it saw none.
NO_OBSTACLE = int(np.iinfo(np.uint16).max)


def observed_reach(features: Features, robot: Robot, focus_range: float = math.inf,
                   bins: int = REACH_BINS, window: tuple[float, float] | None = None) -> NDArray[np.uint16]:
    """Per pan bin, how far a position observed, and its first obstacle.

    Returns ``(2, bins)`` uint16 centimetres: row 0 the reach, row 1 the first obstacle
    (:data:`NO_OBSTACLE` where none). The reach is

    the least of: the first obstacle's distance widened by its cluster window (the fit's
    :func:`occtool.fit.first_obstacle_distance`, as
    :func:`occtool.scoring.in_front_of_first_obstacle` scores it), the farthest feature in
    the body band at that angle (a free ray reaches its end), and ``focus_range``. 0 where
    the position saw nothing.
    """
    from occtool.fit import FOCUS_WINDOW, FOCUS_WINDOW_ABS, angle_bins, first_obstacles_in_band

    low, high = robot.body_band
    x, y, z = features.points.T
    band = (z >= low) & (z <= high)
    alpha = np.arctan2(y[band], x[band])
    distance = np.hypot(x[band], y[band])
    seen = np.zeros(bins)
    np.maximum.at(seen, angle_bins(alpha, bins), distance)
    first = first_obstacles_in_band(features, robot, bins)
    relative, absolute = window if window is not None else (FOCUS_WINDOW, FOCUS_WINDOW_ABS)
    limit = first * (1.0 + relative) + absolute  # inf where no obstacle
    reach = np.minimum(np.minimum(seen, limit), focus_range)
    return np.vstack([_centimetres(reach), _centimetres(first)])


def _centimetres(distance: FloatArray) -> NDArray[np.uint16]:
    return np.round(np.minimum(distance / REACH_UNIT, NO_OBSTACLE)).astype(np.uint16)


def reach_from_guard(guard: Any, focus_range: float = math.inf, bins: int = REACH_BINS) -> NDArray[np.uint16]:
    """A model file's reach when its features are gone: the return guard's nearest return
    per bin (widened by the cluster window); 0 (unobserved) where the guard holds none."""
    from occtool.fit import FOCUS_WINDOW, FOCUS_WINDOW_ABS

    if guard is None:
        return np.vstack([np.zeros(bins, dtype=np.uint16), np.full(bins, NO_OBSTACLE, dtype=np.uint16)])
    per = guard.bins // bins if guard.bins % bins == 0 else None
    if per is None:
        raise InputError(f"a guard of {guard.bins} bins does not split into {bins} reach bins")
    nearest = guard.distance.reshape(bins, per).min(axis=1)
    reach = np.where(np.isfinite(nearest), nearest * (1.0 + FOCUS_WINDOW) + FOCUS_WINDOW_ABS, 0.0)
    reach = np.minimum(reach, focus_range)
    return np.vstack([_centimetres(reach), _centimetres(nearest)])


def returns_from_guard(guard: Any) -> NDArray[np.uint16]:
    """A model's nearest returns per pan bin (its return guard: ``guard.bins`` whole
    millimetres, :data:`NO_OBSTACLE` where none or beyond 65 m); all none without a guard."""
    from occtool.guard import GUARD_BINS

    if guard is None:
        return np.full(GUARD_BINS, NO_OBSTACLE, dtype=np.uint16)
    distance = np.asarray(guard.distance, dtype=np.float64)
    millimetres = np.where(np.isfinite(distance), np.floor(distance * 1000.0 + 1e-6), NO_OBSTACLE)
    return np.minimum(millimetres, NO_OBSTACLE).astype(np.uint16)


#: A return's pan angle within its bin, in 1/255ths of the bin (uint8; 0.004 degrees at one
#: degree a bin); a bin without its own return reads its centre.
OFFSET_STEPS = 255
BIN_CENTRE = 128


def nearest_returns(features: Features, robot: Robot, reach: float = math.inf, level: float | None = None,
                    bins: int | None = None) -> tuple[NDArray[np.uint16], NDArray[np.uint8]]:
    """A position's nearest return per pan bin, where it was measured.

    Among the features with evidence at or above ``level`` (``None``: above 0) in the
    robot's body band, farther than its radius and no farther than ``reach`` (the guard's
    limits: the model's level, ``focus_range`` plus the radius), each bin's nearest: its
    horizontal distance to the nearest millimetre (:data:`NO_OBSTACLE` where none, as
    :func:`returns_from_guard`) and its pan angle within the bin (:data:`OFFSET_STEPS`
    steps of the bin). Unlike the return guard, which
    also holds bins beside a return at its distance (the navigation map's margin), a bin
    holds only a return of its own, and the offset places it on its beam: at 5 cm cells
    the bin centre (up to half a degree off, 4 cm at 5 m) put walls in the next cell.
    """
    from occtool.guard import GUARD_BINS

    bins = GUARD_BINS if bins is None else int(bins)
    low, high = robot.body_band
    x, y, z = features.points.T
    distance = np.hypot(x, y)
    returned = features.evidence > 0 if level is None else features.evidence >= level
    keep = (returned & (z >= low) & (z <= high) & (distance > robot.radius)
            & (distance <= reach))
    position = (np.arctan2(y[keep], x[keep]) + math.pi) * (bins / (2.0 * math.pi))
    index = np.floor(position).astype(np.int64)
    fraction = position - index
    index = np.mod(index, bins)
    distance = distance[keep]
    millimetres = np.full(bins, NO_OBSTACLE, dtype=np.uint16)
    offsets = np.full(bins, BIN_CENTRE, dtype=np.uint8)
    if distance.size:
        order = np.lexsort((distance, index))  # by bin, nearest first
        first = order[np.r_[True, index[order][1:] != index[order][:-1]]]
        millimetres[index[first]] = np.minimum(np.round(distance[first] * 1000.0), NO_OBSTACLE - 1)
        offsets[index[first]] = np.round(np.clip(fraction[first], 0.0, 1.0) * OFFSET_STEPS).astype(np.uint8)
    return millimetres, offsets


@dataclass(frozen=True)
class Observation:
    """What one position observed, kept next to its model where its features are not: the
    reach and first obstacle per pan bin (:func:`observed_reach`) and the nearest return per
    pan bin with its angle within the bin (:func:`nearest_returns`).

    ``occtool fit LOG -o DIR/`` writes one into every model file of a set (``"observed"``,
    docs/method.md's model file), so that a map of the set sees what a map of the log sees: its reach
    where the position's free rays went and its walls where the returns fell. Without it a
    model file has only its return guard, which holds no free rays and spreads each return
    over the bins beside it (the navigation map's margin): on an inner split of Intel's
    training scans the set's world map scored 0.954 against the log's 0.982, with it 0.981.
    """

    #: ``(2, REACH_BINS)`` uint16 centimetres: the reach and the first obstacle.
    reach: NDArray[np.uint16]
    #: ``(GUARD_BINS,)`` uint16 millimetres: the nearest return (:data:`NO_OBSTACLE` for none).
    returns: NDArray[np.uint16]
    #: ``(GUARD_BINS,)`` uint8: each return's angle within its bin, in :data:`OFFSET_STEPS` steps.
    offsets: NDArray[np.uint8]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: whole numbers, ``null`` where a bin has no obstacle or return."""
        def listed(values: NDArray[np.uint16]) -> list[int | None]:
            return [None if v == NO_OBSTACLE else v for v in values.tolist()]

        return {"reach_bins": int(self.reach.shape[1]), "reach_cm": self.reach[0].tolist(),
                "first_obstacle_cm": listed(self.reach[1]), "return_bins": int(self.returns.size),
                "returns_mm": listed(self.returns), "return_offsets": self.offsets.tolist()}

    @classmethod
    def from_dict(cls, data: Any) -> Observation:
        """Read :meth:`to_dict` output; :class:`~occtool.errors.ModelFormatError` when it is malformed."""
        from occtool.guard import GUARD_BINS

        if not isinstance(data, dict):
            raise ModelFormatError("'observed' must be an object")
        if data.get("reach_bins") != REACH_BINS or data.get("return_bins") != GUARD_BINS:
            raise ModelFormatError(f"'observed' must have {REACH_BINS} reach bins and {GUARD_BINS} return bins, got "
                                   f"{data.get('reach_bins')!r} and {data.get('return_bins')!r}")

        def whole(key: str, size: int, top: int, none: bool) -> NDArray[np.int64]:
            values = data.get(key)
            if not isinstance(values, list) or len(values) != size:
                raise ModelFormatError(f"'observed.{key}' must be a list of {size} values")
            out = np.empty(size, dtype=np.int64)
            for i, value in enumerate(values):
                if value is None and none:
                    out[i] = NO_OBSTACLE
                elif isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= top:
                    out[i] = value
                else:
                    raise ModelFormatError(f"'observed.{key}' {i} is not a whole number 0-{top}"
                                           f"{' or null' if none else ''}: {value!r}")
            return out

        # A reach is clipped to NO_OBSTACLE (655 m, without a focus range); the others read null there.
        reach = np.vstack([whole("reach_cm", REACH_BINS, NO_OBSTACLE, False),
                           whole("first_obstacle_cm", REACH_BINS, NO_OBSTACLE - 1, True)]).astype(np.uint16)
        returns = whole("returns_mm", GUARD_BINS, NO_OBSTACLE - 1, True).astype(np.uint16)
        offsets = whole("return_offsets", GUARD_BINS, OFFSET_STEPS, False).astype(np.uint8)
        return cls(reach, returns, offsets)


#: A scanning laser's positions hold at most this many returns a degree in the body band
#: (median over positions: 1.1-2 on the bench's CARMEN logs, 6 on FR-079, whose positions group a few scans); denser
#: clouds (a depth camera's rows: 130 on fixtures/tum-fr3-cabinet) keep their nearest per
#: degree (the return guard's bins), as the nearest of many noisy returns in a finer bin is
#: drawn nearer than the wall.
LASER_RETURNS_PER_DEGREE = 10.0


def is_scanning_laser(densities: Any) -> bool:
    """Whether positions of these :func:`returns_per_degree` are a scanning laser's (their
    median at most :data:`LASER_RETURNS_PER_DEGREE`), not a depth camera's denser clouds."""
    return float(np.median(np.asarray(densities, dtype=np.float64))) <= LASER_RETURNS_PER_DEGREE


def returns_per_degree(features: Any, robot: Any, level: float | None = None) -> float:
    """A position's returns in the body band per degree of pan they occupy (0 without any;
    ``level``: the evidence a return needs, ``None``: any above 0)."""
    low, high = robot.body_band
    x, y, z = features.points.T
    returned = features.evidence > 0 if level is None else features.evidence >= level
    keep = returned & (z >= low) & (z <= high) & (np.hypot(x, y) > robot.radius)
    if not keep.any():
        return 0.0
    degree = np.floor(np.degrees(np.arctan2(y[keep], x[keep]))).astype(np.int64)
    return float(keep.sum()) / float(np.unique(degree).size)


def observe(model: Any, features: Features) -> Observation:
    """The :class:`Observation` of the position a fitted ``model`` was fitted to from
    ``features``: within the model's focus range (none without focus), returns at its level."""
    focus_range = float(model.focus_range) if model.focus else math.inf
    returns, offsets = nearest_returns(features, model.robot_, level=model.level)
    return Observation(observed_reach(features, model.robot_, focus_range), returns, offsets)


__all__ = ["BIN_CENTRE", "LASER_RETURNS_PER_DEGREE", "NO_OBSTACLE", "OFFSET_STEPS", "REACH_BINS", "REACH_UNIT",
           "Observation", "is_scanning_laser", "nearest_returns", "observe", "observed_reach", "reach_from_guard",
           "returns_from_guard", "returns_per_degree"]
