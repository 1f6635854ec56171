"""The ``.occmap`` file: one world map (:class:`occtool.fuse.WorldMap`) on disk, versioned and checked.

Layout (little-endian)::

    8 bytes   magic  b"\\x89OCCMAP\\n"
    4 bytes   uint32 header length H
    H bytes   UTF-8 JSON header: format version, unit, origin, the map's settings,
              and each array's name, dtype and shape in the order they follow
    ...       the arrays' bytes, back to back
    4 bytes   uint32 CRC-32 of everything before it

Arrays (version 4): the segments in the order of the square tiles of :data:`TILE` units
(1.28 m at 5 mm) their middles lie in, tile ``(i, j)`` (``i`` along x) before ``(i, j + 1)``;
``tile_counts`` uint8 ``(I, J)`` (uint16 if a tile holds more than 255), the segments of
each tile; ``middles`` uint8 ``(S, 2)``, each middle's offset in units from its tile's
corner (version 3 stored the middle as two uint16 units from ``origin``: two bytes more a
segment); ``directions`` uint8 ``(S,)``, its direction in [0, pi) in steps of pi/256;
``half_lengths`` uint8 ``(S,)`` in the header's ``half_unit`` (2 mm unless a segment is
longer than 1.02 m); ``thickness`` and ``trust`` uint8 ``(S,)`` (millimetres,
1/255ths): 6 bytes a segment, where version 3 took 8 and version 1, its two end points,
10 (``segments`` uint16 ``(S, 4)``, still read); ``facing`` uint8 ``(ceil(S / 4),)``, the side each segment
was seen from in two bits (0 both, 1 the left of its direction, 2 the right; segment ``i``
in bits ``2 (i mod 4)`` of byte ``i // 4``; absent in versions 1 and 2: every segment
faces both); ``positions`` uint16 ``(P, 2)`` in units, the run's
positions (the free level rises away from them; absent in version 1). The observed region
as shapely's ragged arrays, its vertices as steps: ``region_steps`` int8 ``(V, 2)``, each
vertex's step in units from the one before, or -128, -128 where it is the next of the
``region_anchors`` uint16 ``(A, 2)`` (the first vertex and every step longer than 127
units; version 3 stored every vertex as ``region_coords`` uint16), and its
``region_offsets_*`` uint16 (uint32 past 65,535 vertices; uint32 in version 3). A map is
quantised to this precision when it is built (:func:`quantise`, which also lists its
segments in the file's order), so a map read back answers exactly as the one written;
files of versions 1-3 are read into that order too.
:func:`decode` checks the magic, the version, the sizes, the checksum and every value:
a damaged or foreign file is one :class:`~occtool.errors.InputError`.

This module knows the file, not the map: :func:`encode` takes anything with a world map's
attributes, and :func:`quantise` and :func:`decode` give the numbers as :class:`MapArrays`,
which :mod:`occtool.fuse` makes a :class:`~occtool.fuse.WorldMap` of
(:func:`occtool.fuse.load_map`).
"""

from __future__ import annotations

import json
import math
import os
import struct
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from occtool.errors import InputError

MAGIC = b"\x89OCCMAP\n"
FORMAT_VERSION = 4
#: Versions :func:`decode` reads.
READS = (1, 2, 3, 4)
#: Edge of a segment tile, in units: a middle's offset in its tile fits a byte.
TILE = 256
#: The step code of a region vertex given in full (an anchor).
ANCHOR = -128
#: A segment's half-length in this unit (metres) unless one is longer than 255 of them.
HALF_UNIT = 0.002
#: Direction steps over [0, pi).
DIRECTION_STEPS = 256
#: A header longer than this is not an occmap header (bytes).
MAX_HEADER = 1 << 20
_DTYPES = {"int8": np.int8, "uint8": np.uint8, "uint16": np.uint16, "uint32": np.uint32}
#: Coordinates are stored in this unit (metres) unless a map is too wide for it: 5 mm.
UNIT = 0.005


@dataclass
class MapArrays:
    """A world map's numbers at the file's precision, its segments in the file's order:
    what :func:`quantise` rounds a map to and :func:`decode` reads, the keywords of
    :class:`occtool.fuse.WorldMap` (``settings`` the scalar ones but ``band``) and the
    file's grid (``unit``, ``origin``; ``half_unit`` ``None`` in a version 1 file)."""

    start: np.ndarray
    end: np.ndarray
    thickness: np.ndarray
    trust: np.ndarray
    region: Any
    band: tuple[float, float]
    positions: np.ndarray | None
    facing: np.ndarray
    settings: dict[str, float]
    unit: float
    origin: np.ndarray
    half_unit: float | None
    #: The file's format version (:data:`FORMAT_VERSION` for a map quantised here).
    version: int = FORMAT_VERSION

    def params(self) -> dict[str, Any]:
        """The scalar settings as a map's ``params()`` gives them (the header's ``settings``)."""
        return {"band": list(self.band), **self.settings}


def unreadable(name: str, why: str) -> InputError:
    """The one error a damaged or foreign map file gives."""
    return InputError(f"{name}: not a readable occtool map ({why})")


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
    span = world.end - world.start
    direction = np.mod(np.arctan2(span[:, 1], span[:, 0]), math.pi)
    steps = np.mod(np.round(direction / (math.pi / DIRECTION_STEPS)), DIRECTION_STEPS).astype(np.uint8)
    half = np.clip(np.round(0.5 * np.hypot(span[:, 0], span[:, 1]) / half_unit), 0, 255).astype(np.uint8)
    return np.clip(np.round((middle - origin) / unit), 0, 65535).astype("<u2"), steps, half


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


def quantise(world: Any, unit: float | None = None) -> MapArrays:
    """``world``'s numbers rounded to what the file stores and its segments listed tile by
    tile, as the file lists them (same settings)."""
    import shapely

    unit = UNIT if unit is None else float(unit)
    lower, upper = world.bounds
    origin, unit = _grid(lower, upper, unit)

    def snap(xy: np.ndarray) -> np.ndarray:
        return origin + np.clip(np.round((xy - origin) / unit), 0, 65535) * unit

    half_unit = _half_unit(0.5 * np.hypot(*(world.end - world.start).T))
    middles, steps, half = _segment_codes(world, origin, unit, half_unit)
    # In the file's order, so that a map read back lists its segments as this one does.
    order, _ = _tiles(middles)
    start, end = _segment_ends(middles[order], steps[order], half[order], origin, unit, half_unit)
    # The stored direction lies in [0, pi): a segment turned round faces the other way.
    turned = ((world.end - world.start)[order] * (end - start)).sum(axis=1)
    facing = np.where(np.hypot(*(end - start).T) > 1e-12, np.sign(turned), 0).astype(np.int8) * world.facing[order]
    thickness = np.clip(np.round(world.thickness[order] * 1000.0), 0, 255) / 1000.0
    trust = np.clip(np.round(world.trust[order] * 255.0), 0, 255) / 255.0
    region = world.region
    if not region.is_empty:
        # On the file's grid and valid there (origin is a whole number of units), then
        # through the loader's own arithmetic, so that a map read back is this one.
        region = _areal(shapely.transform(_areal(shapely.set_precision(region, unit)), snap))
    params = world.params()
    band = params.pop("band")
    return MapArrays(start, end, thickness, trust, region, (band[0], band[1]), snap(world.positions), facing, params,
                     unit, origin, half_unit)


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


def _areal(geometry: Any) -> Any:
    """The polygonal part of ``geometry`` as one MultiPolygon (make_valid may add lines)."""
    import shapely

    parts = shapely.get_parts(geometry)
    polygons = []
    for part in parts:
        if isinstance(part, shapely.Polygon):
            polygons.append(part)
        elif isinstance(part, (shapely.MultiPolygon, shapely.GeometryCollection)):
            polygons.extend(p for p in shapely.get_parts(part) if isinstance(p, shapely.Polygon))
    return shapely.MultiPolygon([p for p in polygons if not p.is_empty])


def _arrays(world: Any) -> tuple[dict[str, Any], list[tuple[str, np.ndarray]]]:
    import shapely

    unit = getattr(world, "unit", None)
    origin = getattr(world, "origin", None)
    half_unit = getattr(world, "half_unit", None)
    if unit is None or origin is None or half_unit is None:
        world = quantise(world)
        unit, origin, half_unit = world.unit, world.origin, world.half_unit

    def units(xy: np.ndarray) -> np.ndarray:
        return np.clip(np.round((xy - origin) / unit), 0, 65535).astype("<u2")

    middles, steps, half = _segment_codes(world, origin, unit, half_unit)
    order, counts = _tiles(middles)  # the identity for a map quantise() made or decode() read
    arrays = [("tile_counts", counts.astype(_narrowest(int(counts.max(initial=0))))),
              ("middles", (middles[order] % TILE).astype(np.uint8).reshape(-1, 2)),
              ("directions", steps[order]), ("half_lengths", half[order]),
              ("thickness", np.clip(np.round(world.thickness[order] * 1000.0), 0, 255).astype(np.uint8)),
              ("trust", np.clip(np.round(world.trust[order] * 255.0), 0, 255).astype(np.uint8)),
              ("facing", _pack_facing(world.facing[order]))]
    arrays.append(("positions", units(world.positions).reshape(-1, 2)))
    region = _areal(world.region) if not world.region.is_empty else shapely.MultiPolygon()
    if not region.is_empty:
        _, coords, offsets = shapely.to_ragged_array([region])
        vertex_steps, anchors = _vertex_steps(units(coords))
        arrays += [("region_steps", vertex_steps), ("region_anchors", anchors)]
        wide = "<u2" if coords.shape[0] < 1 << 16 else "<u4"  # the offsets run to the vertex count
        for n, offset in enumerate(offsets):
            arrays.append((f"region_offsets_{n}", np.asarray(offset, dtype=wide)))
    header = {"format": "occtool.occmap", "version": FORMAT_VERSION, "unit": unit, "half_unit": half_unit,
              "origin": [float(origin[0]), float(origin[1])], "settings": world.params(),
              "arrays": [[name, str(a.dtype.name), list(a.shape)] for name, a in arrays]}
    return header, arrays


def array_bytes(world: Any) -> int:
    """Bytes of ``world``'s arrays in its file (the header and checksum aside)."""
    return int(sum(a.nbytes for _, a in _arrays(world)[1]))


def encode(world: Any) -> bytes:
    """The file's bytes for ``world``."""
    header, arrays = _arrays(world)
    text = json.dumps(header, sort_keys=True, separators=(",", ":")).encode("utf-8")
    body = MAGIC + struct.pack("<I", len(text)) + text + b"".join(a.astype(a.dtype.newbyteorder("<")).tobytes()
                                                                   for _, a in arrays)
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def save_map(world: Any, path: str | os.PathLike[str], *, overwrite: bool = True) -> int:
    """Write ``world`` to ``path`` through a temporary file; returns the bytes written."""
    from occtool._files import atomic_write

    data = encode(world)
    with atomic_write(path, "wb", overwrite=overwrite) as stream:
        stream.write(data)
    return len(data)


def decode(data: bytes, name: str = "occmap") -> MapArrays:
    """A world map's numbers from the file's bytes; :class:`InputError` naming ``name`` if damaged."""
    import shapely

    def fail(why: str) -> InputError:
        return unreadable(name, why)

    if len(data) < len(MAGIC) + 8 or not data.startswith(MAGIC):
        raise fail("no occmap signature")
    (stored,) = struct.unpack("<I", data[-4:])
    if zlib.crc32(data[:-4]) & 0xFFFFFFFF != stored:
        raise fail("checksum mismatch: the file is damaged or truncated")
    (length,) = struct.unpack("<I", data[len(MAGIC):len(MAGIC) + 4])
    start = len(MAGIC) + 4
    if length > MAX_HEADER or start + length > len(data) - 4:
        raise fail("header length out of range")
    try:
        header = json.loads(data[start:start + length].decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise fail(f"header is not JSON: {exc.msg if hasattr(exc, 'msg') else exc}") from None
    if not isinstance(header, dict) or header.get("format") != "occtool.occmap":
        raise fail("header does not name the occmap format")
    version = header.get("version")
    if version not in READS:
        raise fail(f"format version {version!r}, this occtool reads {', '.join(map(str, READS[:-1]))} and {READS[-1]}")
    try:
        unit = float(header["unit"])
        half_unit = float(header["half_unit"]) if version >= 2 else None
        origin = np.array(header["origin"], dtype=np.float64).reshape(2)
        settings = dict(header["settings"])
        layout = [(str(n), _DTYPES[str(t)], tuple(int(s) for s in shape)) for n, t, shape in header["arrays"]]
    except (KeyError, TypeError, ValueError) as exc:
        raise fail(f"header field missing or malformed: {exc}") from None
    if not (math.isfinite(unit) and unit > 0 and np.isfinite(origin).all()
            and (half_unit is None or (math.isfinite(half_unit) and half_unit > 0))):
        raise fail("unit, half_unit or origin is not a finite positive number")
    offset = start + length
    arrays: dict[str, np.ndarray] = {}
    for array_name, dtype, shape in layout:
        if any(s < 0 for s in shape):
            raise fail(f"array {array_name} has a negative size")
        size = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
        if offset + size > len(data) - 4:
            raise fail(f"array {array_name} runs past the end of the file")
        arrays[array_name] = np.frombuffer(data, dtype=np.dtype(dtype).newbyteorder("<"), count=size //
                                           np.dtype(dtype).itemsize, offset=offset).reshape(shape).astype(dtype)
        offset += size
    if offset != len(data) - 4:
        raise fail(f"{len(data) - 4 - offset} bytes after the last array")
    try:
        if half_unit is None:  # version 1: both end points
            segments = arrays["segments"].reshape(-1, 4).astype(np.float64) * unit
            first, last = origin + segments[:, :2], origin + segments[:, 2:]
        else:
            middles = (_tiled_middles(arrays["tile_counts"], arrays["middles"].reshape(-1, 2)) if version >= 4
                       else arrays["middles"].reshape(-1, 2))
            first, last = _segment_ends(middles, arrays["directions"].reshape(-1),
                                        arrays["half_lengths"].reshape(-1), origin, unit, half_unit)
        thickness = arrays["thickness"].astype(np.float64) / 1000.0
        trust = arrays["trust"].astype(np.float64) / 255.0
        facing = (_unpack_facing(arrays["facing"].reshape(-1), first.shape[0]) if version >= 3
                  else np.zeros(first.shape[0], dtype=np.int8))
        if version < 4:  # into the file's order, as a map quantise() made
            order, _ = _tiles(np.clip(np.round((0.5 * (first + last) - origin) / unit), 0, None))
            first, last, thickness, trust, facing = (a[order] for a in (first, last, thickness, trust, facing))
    except (KeyError, ValueError) as exc:
        raise fail(f"segment arrays missing or misshapen: {exc}") from None
    region = shapely.MultiPolygon()
    if "region_coords" in arrays or "region_steps" in arrays:
        try:
            vertices = (_stepped_vertices(arrays["region_steps"].reshape(-1, 2),
                                          arrays["region_anchors"].reshape(-1, 2))
                        if version >= 4 else arrays["region_coords"].reshape(-1, 2))
        except (KeyError, ValueError) as exc:
            raise fail(f"observed region is malformed: {exc}") from None
        coords = origin + vertices.astype(np.float64) * unit
        offsets = [arrays[f"region_offsets_{n}"].astype(np.int64) for n in range(3) if f"region_offsets_{n}" in arrays]
        try:
            region = shapely.from_ragged_array(shapely.GeometryType.MULTIPOLYGON, coords, tuple(offsets))[0]
        except (ValueError, IndexError, shapely.errors.ShapelyError) as exc:
            raise fail(f"observed region is malformed: {exc}") from None
    try:
        band = settings.pop("band")
        positions = (origin + arrays["positions"].reshape(-1, 2).astype(np.float64) * unit
                     if "positions" in arrays else None)
        band = (float(band[0]), float(band[1]))
        scalars = {k: float(v) for k, v in settings.items()}
    except (TypeError, KeyError, IndexError, ValueError) as exc:
        raise fail(str(exc)) from None
    return MapArrays(first, last, thickness, trust, region, band, positions, facing, scalars, unit, origin, half_unit,
                     version)


def read_map(path: str | os.PathLike[str]) -> MapArrays:
    """:func:`decode` of a ``.occmap`` file (``occtool map`` writes ``DIR/world.occmap``);
    a file that cannot be read or is damaged is an :class:`InputError`."""
    try:
        with open(path, "rb") as stream:
            data = stream.read()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the map: {exc.strerror or exc}") from None
    return decode(data, str(path))


__all__ = ["FORMAT_VERSION", "MAGIC", "UNIT", "MapArrays", "array_bytes", "decode", "encode", "quantise", "read_map",
           "save_map", "unreadable"]
