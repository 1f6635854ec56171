"""What every position of a run saw, per pan bin: the world map's input (:class:`RunReturns`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.observation import (
    BIN_CENTRE,
    NO_OBSTACLE,
    OFFSET_STEPS,
    REACH_UNIT,
    is_scanning_laser,
    nearest_returns,
    observed_reach,
    returns_per_degree,
)

FloatArray = NDArray[np.float64]

#: Pan bins of the positions' nearest returns the walls are fitted to, for a scanning laser
#: (half a degree: every beam at that spacing; chosen on inner splits, docs/map.md; a
#: scanning laser's positions hold at most
#: :data:`occtool.observation.LASER_RETURNS_PER_DEGREE` returns a degree).
SIGHTING_BINS = 720


@dataclass
class RunReturns:
    """What every position of a run saw, per pan bin: the world frame's input to :func:`build_world_map`.

    ``poses`` ``(P, 4)`` x, y, z, yaw of each viewpoint (a position, or each scan of one that
    gathers several: :func:`returns_of_positions`); ``ranges`` ``(P, bins)`` the horizontal distance to
    each bin's nearest return, or where the bin has none how far the position saw (its
    farthest free ray, or a model's reach; 0 where it saw nothing): an array, or the uint16 it
    is made of (:class:`StoredRanges`, as :func:`returns_of_positions` and
    :func:`returns_of_fused` keep it), read a block of positions at a time; ``returned`` ``(P, bins)``
    whether the bin holds a return; ``offsets`` ``(P, bins)`` uint8 its pan angle within the
    bin in :data:`occtool.fuse.OFFSET_STEPS` steps (the centre where unknown);
    ``scanning_laser`` whether the positions' returns are a scanning laser's (few a degree,
    :data:`LASER_RETURNS_PER_DEGREE`), whose walls :func:`build_world_map` lets face one side.
    """

    poses: FloatArray
    ranges: FloatArray | StoredRanges
    returned: NDArray[np.bool_]
    offsets: NDArray[np.uint8]
    scanning_laser: bool = False

    def __len__(self) -> int:
        return int(self.poses.shape[0])

    def return_points(self, within: float, beyond: float = -math.inf) -> tuple[FloatArray, NDArray[np.int64]]:
        """World ``(N, 2)`` returns no farther than ``within`` from their position (and farther
        than ``beyond``), and the position of each (a block of positions at a time: the
        temporaries are a block's)."""
        bins = self.ranges.shape[1]
        blocks = range(0, len(self), _POSITIONS_AT_ONCE)

        def kept(low: int) -> NDArray[np.bool_]:
            ranges = self.ranges[low:low + _POSITIONS_AT_ONCE]
            return self.returned[low:low + _POSITIONS_AT_ONCE] & (ranges <= within) & (ranges > beyond)

        # Counted first, then written in place: never the blocks' arrays beside their concatenation.
        counts = [int(np.count_nonzero(kept(low))) for low in blocks]
        points, owners = np.empty((sum(counts), 2)), np.empty(sum(counts), dtype=np.int64)
        at = 0
        for low, count in zip(blocks, counts):
            k, b = np.nonzero(kept(low))
            k += low
            alpha = -math.pi + (b + self.offsets[k, b] / OFFSET_STEPS) * (2.0 * math.pi / bins) + self.poses[k, 3]
            r = self.ranges[k, b]
            points[at:at + count, 0] = self.poses[k, 0] + r * np.cos(alpha)
            points[at:at + count, 1] = self.poses[k, 1] + r * np.sin(alpha)
            owners[at:at + count] = k
            at += count
        return points, owners


def returns_of_fused(fused: Any) -> RunReturns:
    """:class:`RunReturns` of a :class:`FusedMap`'s own positions: its returns, and where a
    bin has none the model's reach there (:func:`position_ranges`)."""
    if fused.returns is None:
        raise InputError("this fused map keeps no returns: a world map needs them")
    # Read from the fused map's own returns and reaches, not held as float64 beside them.
    ranges = StoredRanges(fused.returns, fused.reaches)
    offsets = (fused.return_offsets if fused.return_offsets is not None
               else np.full(ranges.shape, BIN_CENTRE, dtype=np.uint8))
    return RunReturns(fused._pose_array.copy(), ranges, fused.returns != NO_OBSTACLE, np.asarray(offsets),
                      scanning_laser=bool(fused.scanning_laser))


def returns_of_positions(positions: Any, robot: Any, *, focus_range: float = math.inf,
                         level: float | None = None, bins: int | None = None) -> RunReturns:
    """:class:`RunReturns` of a log's positions (each with features and a pose), fitted or
    not: their nearest returns in each of ``bins`` pan bins
    (:func:`occtool.observation.nearest_returns` at ``level``) and their reach
    (:func:`occtool.observation.observed_reach`). A run's keyframes are a share of its
    positions; the others' returns still place walls. A position that gathers several scans
    (:attr:`occtool.features.Position.scan_origins`) gives a row for each, measured from the
    scan's own sensor: every scan's nearest returns, not only the position's (a robot standing
    still while people pass by keeps the walls behind them; FR-079's 4,311 training scans are
    1,342 positions, docs/figures.md). ``bins=None``: :data:`SIGHTING_BINS`
    for a scanning laser's positions, the return guard's one a degree for denser clouds
    (:data:`LASER_RETURNS_PER_DEGREE`)."""
    from occtool.guard import GUARD_BINS

    positions = list(positions)
    if not positions:
        raise InputError("no positions to read returns from")
    laser = is_scanning_laser([returns_per_degree(p.features, robot, level) for p in positions])
    if bins is None:
        bins = SIGHTING_BINS if laser else GUARD_BINS
    rows = sum(len(_scans(item)) for item in positions)
    returns = np.empty((rows, bins), dtype=np.uint16)
    offsets = np.empty((rows, bins), dtype=np.uint8)
    poses = np.empty((rows, 4))
    reaches, of_position = [], np.empty(rows, dtype=np.intp)
    row = 0
    for k, item in enumerate(positions):  # a loop over scans, each vectorised over its features
        # How far the position saw, where a scan's bin holds no return (its scans' origins
        # lie within the grouping's tolerance, a few decimetres, of the position's).
        reaches.append(observed_reach(item.features, robot, focus_range))
        for pose, features in _scans_of(item):
            returns[row], offsets[row] = nearest_returns(features, robot, level=level, bins=bins)
            poses[row] = pose.x, pose.y, pose.z, pose.yaw
            of_position[row] = k
            row += 1
    # Each scan's row reads its position's reaches (a tenth of its returns' bytes).
    return RunReturns(poses, StoredRanges(returns, np.stack(reaches)[of_position]), returns != NO_OBSTACLE, offsets,
                      scanning_laser=laser)


def _scans(position: Any) -> NDArray[np.int64]:
    """How many features each scan of a position holds (:func:`occtool.features.scans_apart`;
    one scan of them all when it keeps none)."""
    from occtool.features import scans_apart

    sizes = scans_apart(position)
    return np.array([position.features.points.shape[0]], dtype=np.int64) if sizes is None else sizes


def _scans_of(position: Any) -> Any:
    """``(pose, features)`` of each scan a position gathers, measured from its own sensor
    (:attr:`occtool.features.Position.scan_origins`; the position's yaw), or the position's
    own when it holds one scan."""
    from occtool.features import Features, Pose

    sizes = _scans(position)
    features, pose = position.features, position.pose
    if sizes.size == 1:
        yield pose, features
        return
    origins = position.scan_origins
    ends = np.cumsum(sizes)
    origins = np.asarray(origins, dtype=np.float64)
    sensors = pose.to_world(origins[:, :2])
    for origin, sensor, end, size in zip(origins, sensors, ends, sizes):
        points = features.points[end - size:end] - origin
        kept = (np.abs(points) > 0.0).any(axis=1)  # a point at the scan's own sensor has no direction
        yield (Pose(float(sensor[0]), float(sensor[1]), pose.z + origin[2], pose.yaw),
               Features(points[kept], features.evidence[end - size:end][kept]))


def position_ranges(fused: Any) -> FloatArray:
    """``(P, bins)`` each position's range per return bin: its nearest return, or where it had
    none its reach in that direction (0 where it saw nothing), metres."""
    if fused.returns is None:
        raise InputError("this fused map keeps no returns: a world map needs them")
    return _ranges(fused.returns, fused.reaches)


def _ranges(returns: NDArray[np.uint16], reaches: NDArray[np.uint16]) -> FloatArray:
    """Nearest returns ``(P, bins)`` (millimetres) where a bin has one, else the reach
    (``(P, 2, coarse bins)`` centimetres, row 0) of the coarser bin its centre lies in, metres
    (a block of positions at a time: the temporaries are a block's)."""
    coarse = _coarse_bins(returns.shape[1], reaches.shape[2])
    out = np.empty(returns.shape, dtype=np.float64)
    for low in range(0, returns.shape[0], _POSITIONS_AT_ONCE):
        high = low + _POSITIONS_AT_ONCE
        out[low:high] = _in_metres(returns[low:high], reaches[low:high, 0][:, coarse])
    return out


def _coarse_bins(bins: int, coarse: int) -> NDArray[np.intp]:
    """The coarse reach bin (of ``coarse``) each of ``bins`` return bins' centres lies in."""
    centre = (np.arange(bins) + 0.5) / bins
    return np.minimum((centre * coarse).astype(np.intp), coarse - 1)


def _in_metres(returns: NDArray[np.uint16], reaches: NDArray[np.uint16]) -> FloatArray:
    """Nearest returns (millimetres) where there is one, else the reaches beside them
    (centimetres, the same shape), in metres."""
    return np.where(returns != NO_OBSTACLE, returns.astype(np.float64) / 1000.0,
                    reaches.astype(np.float64) * REACH_UNIT)


class StoredRanges:
    """:func:`position_ranges`' ``(P, bins)`` float64 metres, kept as the uint16 they are
    made of (nearest returns in millimetres, reaches in centimetres: 2.4 bytes a bin, not 8;
    campus x10's 18,330 positions' 720 bins 106 -> 35 MB) and made as they are read, a block
    of positions at a time, by the same arithmetic: the same numbers, bit for bit. Reads rows
    (``[rows]``: an index, a slice or an index array), elements (``[rows, bins]``, index
    arrays) and anything else through the whole array (``np.asarray``)."""

    def __init__(self, returns: NDArray[np.uint16], reaches: NDArray[np.uint16]) -> None:
        self.returns, self.reaches = returns, reaches
        self._coarse = _coarse_bins(returns.shape[1], reaches.shape[2])

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.returns.shape[0]), int(self.returns.shape[1]))

    def __len__(self) -> int:
        return self.shape[0]

    def __array__(self, dtype: Any = None, copy: Any = None) -> FloatArray:
        whole = _ranges(self.returns, self.reaches)
        return whole if dtype is None else whole.astype(dtype)

    def __getitem__(self, key: Any) -> Any:
        if isinstance(key, tuple) and len(key) == 2 and not any(isinstance(k, slice) for k in key):
            rows, bins = (np.asarray(k) for k in key)
            if rows.dtype.kind in "iu" and bins.dtype.kind in "iu":
                return _in_metres(self.returns[rows, bins], self.reaches[rows, 0, self._coarse[bins]])
        elif isinstance(key, (int, np.integer, slice)) or (
                isinstance(key, np.ndarray) and key.ndim == 1 and key.dtype.kind in "iu"):
            if isinstance(key, (int, np.integer)):
                return _ranges(self.returns[key:key + 1 or None], self.reaches[key:key + 1 or None])[0]
            return _ranges(self.returns[key], self.reaches[key])
        return np.asarray(self)[key]


#: Positions whose ranges or returns are worked on at once (bounds the temporaries: ~6 MB a
#: float64 array of 1,024 positions' 720 bins).
_POSITIONS_AT_ONCE = 1024


__all__ = ["SIGHTING_BINS", "RunReturns", "StoredRanges", "position_ranges", "returns_of_fused", "returns_of_positions"]
