"""How ``world.occmap`` packs a map's numbers into few bytes (:mod:`occtool.formats.occmap`
is the file): segments by tile with byte offsets, directions in steps of pi/256, region
vertices as int8 steps between anchors, facings in two bits.

Each packing here has its inverse beside it; :func:`occtool.formats.occmap.quantise`
rounds a map to what they store, so a map read back answers exactly as the one written.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: Edge of a segment tile, in units: a middle's offset in its tile fits a byte.
TILE = 256
#: The step code of a region vertex given in full (an anchor).
ANCHOR = -128
#: A segment's half-length in this unit (metres) unless one is longer than 255 of them.
HALF_UNIT = 0.002
#: Direction steps over [0, pi).
DIRECTION_STEPS = 256


def _grid(lower: np.ndarray, upper: np.ndarray, unit: float) -> tuple[np.ndarray, float]:
    """The origin and unit that hold ``lower``..``upper`` in uint16 (the unit widened if they do not)."""
    origin = np.floor(lower / unit) * unit
    span = float(np.max(upper - origin)) if upper.size else 0.0
    if span / unit > 65000:
        unit = math.ceil(span / 65000 * 1000.0) / 1000.0
        origin = np.floor(lower / unit) * unit
    return origin, unit


def _half_unit(half_length: np.ndarray) -> float:
    """The unit that holds every half-length in a byte: :data:`HALF_UNIT`, widened if need be."""
    longest = float(half_length.max()) if half_length.size else 0.0
    return max(HALF_UNIT, math.ceil(longest / 255.0 * 1e4) / 1e4)


def _segment_codes(world: Any, origin: np.ndarray, unit: float,
                   half_unit: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each segment's middle (uint16 units), direction and half-length (uint8 codes)."""
    middle = 0.5 * (world.start + world.end)
    steps, half = direction_codes(world.end - world.start, half_unit)
    return np.clip(np.round((middle - origin) / unit), 0, 65535).astype("<u2"), steps.astype(np.uint8), half.astype(
        np.uint8)


def direction_codes(span: np.ndarray, half_unit: float) -> tuple[np.ndarray, np.ndarray]:
    """The codes of segments ``start + span``: direction in steps of pi / :data:`DIRECTION_STEPS`
    over [0, pi) and half-length in ``half_unit`` (0-255), as int64 (the one coding
    :func:`_segment_codes` and :func:`occtool.fuse.merge_maps` share)."""
    direction = np.mod(np.arctan2(span[:, 1], span[:, 0]), math.pi)
    steps = np.mod(np.round(direction / (math.pi / DIRECTION_STEPS)), DIRECTION_STEPS).astype(np.int64)
    half = np.clip(np.round(0.5 * np.hypot(span[:, 0], span[:, 1]) / half_unit), 0, 255).astype(np.int64)
    return steps, half


def _segment_ends(middles: np.ndarray, steps: np.ndarray, half: np.ndarray, origin: np.ndarray, unit: float,
                  half_unit: float) -> tuple[np.ndarray, np.ndarray]:
    """End points of the coded segments (the one formula :func:`quantise` and :func:`decode` share)."""
    middle = origin + middles.astype(np.float64) * unit
    angle = steps.astype(np.float64) * (math.pi / DIRECTION_STEPS)
    reach = (half.astype(np.float64) * half_unit)[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])
    return middle - reach, middle + reach


def _narrowest(top: int) -> str:
    """The narrowest little-endian unsigned type that holds ``0..top``."""
    return "<u1" if top < 1 << 8 else "<u2" if top < 1 << 16 else "<u4"


def _tiles(middles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (stable) order that lists coded middles ``(S, 2)`` tile by tile, and each tile's
    count ``(I, J)``."""
    tile = middles.astype(np.int64) // TILE
    shape = tile.max(axis=0) + 1 if tile.size else np.zeros(2, dtype=np.int64)
    key = tile[:, 0] * shape[1] + tile[:, 1]
    counts = np.bincount(key, minlength=int(shape[0] * shape[1])).reshape(int(shape[0]), int(shape[1]))
    return np.argsort(key, kind="stable"), counts


def _tiled_middles(counts: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """The inverse of :func:`_tiles`' coding: middles in units from the tiles' counts and
    the offsets in them; ``ValueError`` if they disagree."""
    if counts.ndim != 2 or int(counts.sum()) != offsets.shape[0]:
        raise ValueError(f"tile counts for {int(counts.sum())} segments, {offsets.shape[0]} middles")
    corners = np.repeat(np.indices(counts.shape).reshape(2, -1).T, counts.ravel().astype(np.int64), axis=0)
    middles = corners * TILE + offsets.astype(np.int64)
    if middles.size and middles.max() > 65535:
        raise ValueError("a segment's middle lies past the map's grid")
    return middles


def _vertex_steps(coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(V, 2)`` in units as int8 steps from the vertex before, :data:`ANCHOR`
    where one is given in full (the first, and after a step longer than 127 units), and
    those anchors (uint16)."""
    coords = coords.astype(np.int64).reshape(-1, 2)
    step = np.diff(coords, axis=0, prepend=coords[:1])
    anchor = np.ones(coords.shape[0], dtype=bool)
    anchor[1:] = (np.abs(step[1:]) > 127).any(axis=1)
    step[anchor] = ANCHOR
    return step.astype(np.int8), coords[anchor].astype("<u2")


def _stepped_vertices(steps: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    """The inverse of :func:`_vertex_steps`; ``ValueError`` if the codes and anchors disagree."""
    code = steps.astype(np.int64) == ANCHOR
    anchor = code.all(axis=1)
    first_given = not steps.shape[0] or bool(anchor[0])
    if (code.any(axis=1) != anchor).any() or int(anchor.sum()) != anchors.shape[0] or not first_given:
        raise ValueError(f"{int(anchor.sum())} anchor codes for {anchors.shape[0]} anchors")
    walked = np.cumsum(np.where(anchor[:, None], 0, steps.astype(np.int64)), axis=0)
    group = np.cumsum(anchor) - 1
    coords = anchors.astype(np.int64)[group] + walked - walked[np.flatnonzero(anchor)][group]
    if coords.size and (coords.min() < 0 or coords.max() > 65535):
        raise ValueError("a vertex steps off the map's grid")
    return coords


def _pack_facing(facing: np.ndarray) -> np.ndarray:
    """Facings -1 / 0 / +1 as two-bit codes 2 / 0 / 1, four to a byte."""
    codes = np.where(facing > 0, 1, np.where(facing < 0, 2, 0)).astype(np.uint8)
    codes = np.concatenate([codes, np.zeros(-codes.size % 4, dtype=np.uint8)]).reshape(-1, 4)
    return (codes << np.array([0, 2, 4, 6], dtype=np.uint8)).sum(axis=1, dtype=np.uint8)


def _unpack_facing(packed: np.ndarray, n: int) -> np.ndarray:
    """The inverse of :func:`_pack_facing` for ``n`` segments; ``ValueError`` on a code 3."""
    if packed.size != -(-n // 4):
        raise ValueError(f"{packed.size} facing bytes for {n} segments")
    codes = ((packed[:, None] >> np.array([0, 2, 4, 6], dtype=np.uint8)) & 3).reshape(-1)[:n]
    if (codes == 3).any():
        raise ValueError("facing code 3")
    return np.where(codes == 1, 1, np.where(codes == 2, -1, 0)).astype(np.int8)
