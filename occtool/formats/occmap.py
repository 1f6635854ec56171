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
:func:`decode` checks the magic, the checksum, the version, every array's name, dtype and
shape against the bytes present, every count and offset against the others (before shapely
or numpy index with them) and every number's range (:data:`MIN_UNIT`,
:data:`occtool.limits.MAX_WORLD_COORDINATE`, :data:`occtool.limits.MAX_DISTANCE`);
:func:`read_map` checks the file (regular, at most :data:`occtool.limits.MAX_MAP_BYTES`,
the signature and header length) before reading its body. A damaged, crafted or foreign
file is one :class:`~occtool.errors.InputError` naming it.

This module knows the file, not the map: :func:`encode` takes anything with a world map's
attributes, and :func:`quantise` and :func:`decode` give the numbers as :class:`MapArrays`,
which :mod:`occtool.fuse` makes a :class:`~occtool.fuse.WorldMap` of
(:func:`occtool.fuse.load_map`).
"""

from __future__ import annotations

import json
import math
import os
import stat
import struct
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from occtool.errors import InputError
from occtool.formats._occmap_packing import (
    TILE,
    _grid,
    _half_unit,
    _narrowest,
    _pack_facing,
    _segment_codes,
    _segment_ends,
    _stepped_vertices,
    _tiled_middles,
    _tiles,
    _unpack_facing,
    _vertex_steps,
)

MAGIC = b"\x89OCCMAP\n"
FORMAT_VERSION = 4
#: Versions :func:`decode` reads.
READS = (1, 2, 3, 4)
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


def quantise(world: Any, unit: float | None = None) -> MapArrays:
    """``world``'s numbers rounded to what the file stores and its segments listed tile by
    tile, as the file lists them (same settings)."""

    unit = UNIT if unit is None else float(unit)
    lower, upper = world.bounds
    origin, unit = _grid(lower, upper, unit)
    snap = _snapping(origin, unit)

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
    region = _region_on_grid(world.region, origin, unit)
    params = world.params()
    band = params.pop("band")
    return MapArrays(start, end, thickness, trust, region, (band[0], band[1]), snap(world.positions), facing, params,
                     unit, origin, half_unit)


def _snapping(origin: np.ndarray, unit: float) -> Any:
    """Points rounded to the file's grid (``origin``, ``unit``), by the loader's arithmetic."""

    def snap(xy: np.ndarray) -> np.ndarray:
        return origin + np.clip(np.round((xy - origin) / unit), 0, 65535) * unit

    return snap


def _region_on_grid(region: Any, origin: np.ndarray, unit: float) -> Any:
    """A region on the file's grid and valid there (origin is a whole number of units), then
    through the loader's own arithmetic, so that a map read back is this one."""
    import shapely

    if region.is_empty:
        return region
    return _areal(shapely.transform(_areal(shapely.set_precision(region, unit)), _snapping(origin, unit)))


def quantise_region(region: Any, lower: np.ndarray, upper: np.ndarray, unit: float | None = None) -> Any:
    """The region :func:`quantise` gives a map whose :attr:`~occtool.fuse.WorldMap.bounds`
    are ``lower``, ``upper`` and whose region is ``region``: a region on such a map's grid
    without the map's segments made and rounded beside it."""
    origin, grid_unit = _grid(lower, upper, UNIT if unit is None else float(unit))
    return _region_on_grid(region, origin, grid_unit)


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


def framed(header: bytes, payload: bytes) -> bytes:
    """A file of any version: the magic, the header's length and text, the payload, and the
    CRC-32 of all that (the framing :func:`decode` and the version-5 reader check)."""
    body = MAGIC + struct.pack("<I", len(header)) + header + payload
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def write_file(data: bytes, path: str | os.PathLike[str], *, overwrite: bool = True) -> int:
    """Write a map's bytes to ``path`` through a temporary file; returns the bytes written."""
    from occtool._files import atomic_write

    with atomic_write(path, "wb", overwrite=overwrite) as stream:
        stream.write(data)
    return len(data)


def encode(world: Any) -> bytes:
    """The file's bytes for ``world``."""
    header, arrays = _arrays(world)
    text = json.dumps(header, sort_keys=True, separators=(",", ":")).encode("utf-8")
    return framed(text, b"".join(a.astype(a.dtype.newbyteorder("<")).tobytes() for _, a in arrays))


def save_map(world: Any, path: str | os.PathLike[str], *, overwrite: bool = True) -> int:
    """Write ``world`` to ``path`` through a temporary file; returns the bytes written."""
    return write_file(encode(world), path, overwrite=overwrite)


#: Smallest unit (metres) of a file's grid and of its half-lengths: a micrometre, far finer
#: than any map is written at (5 mm), coarse enough that no coordinate divides to infinity.
MIN_UNIT = 1e-6
#: Deepest the header's JSON nests (it nests 4 deep: ``"arrays": [[name, dtype, [shape]]]``).
MAX_HEADER_DEPTH = 8
#: Most tiles along x or y: a middle's 65,535 units hold 256 tiles of :data:`TILE`.
MAX_TILES = 65536 // TILE


def _schema(version: int) -> dict[str, tuple[tuple[str, ...], tuple[int, ...] | None]]:
    """The arrays a file of ``version`` may hold: each one's dtypes and the sizes after its
    first (``None``: two sizes of at most :data:`MAX_TILES`, the tile counts)."""
    schema: dict[str, tuple[tuple[str, ...], tuple[int, ...] | None]] = {
        "thickness": (("uint8",), ()), "trust": (("uint8",), ()), "positions": (("uint16",), (2,))}
    if version == 1:
        schema["segments"] = (("uint16",), (4,))
    else:
        schema["middles"] = (("uint8",) if version >= 4 else ("uint16",), (2,))
        schema["directions"] = schema["half_lengths"] = (("uint8",), ())
    if version >= 3:
        schema["facing"] = (("uint8",), ())
    if version >= 4:
        schema["tile_counts"] = (("uint8", "uint16", "uint32"), None)
        schema["region_steps"] = (("int8",), (2,))
        schema["region_anchors"] = (("uint16",), (2,))
        wide: tuple[str, ...] = ("uint16", "uint32")
    else:
        schema["region_coords"] = (("uint16",), (2,))
        wide = ("uint32",)
    for n in range(3):
        schema[f"region_offsets_{n}"] = (wide, ())
    return schema


def _short(value: Any) -> str:
    """``repr(value)``, cut to fit a one-line message."""
    text = repr(value)
    return text if len(text) <= 40 else text[:30] + "..." + text[-6:]


def _number(value: Any) -> float:
    """``value`` as a finite float; ``ValueError`` for anything else (a boolean, a string)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{_short(value)} is not a finite number")
    return float(value)


def _grid_fields(header: dict[str, Any], version: int) -> tuple[float, float | None, np.ndarray, dict[str, Any]]:
    """The header's unit, half-unit, origin and settings, checked in range (``ValueError``, ``KeyError``)."""
    from occtool.limits import MAX_DISTANCE, MAX_WORLD_COORDINATE

    unit = _number(header["unit"])
    half_unit = _number(header["half_unit"]) if version >= 2 else None
    corner = header["origin"]
    if not (isinstance(corner, list) and len(corner) == 2):
        raise ValueError(f"origin {_short(corner)} is not two numbers")
    origin = np.array([_number(corner[0]), _number(corner[1])])
    if unit < MIN_UNIT:
        raise ValueError(f"unit {unit:g} m is below {MIN_UNIT:g} m")
    if not (np.abs(origin).max() <= MAX_WORLD_COORDINATE
            and np.abs(origin + 65535 * unit).max() <= MAX_WORLD_COORDINATE):
        raise ValueError(f"a grid of {unit:g} m from {origin.tolist()} reaches past {MAX_WORLD_COORDINATE:g} m")
    if half_unit is not None and not MIN_UNIT <= half_unit <= MAX_DISTANCE / 255:
        raise ValueError(f"half_unit {half_unit:g} m is outside [{MIN_UNIT:g}, {MAX_DISTANCE / 255:g}]")
    settings = header["settings"]
    if not isinstance(settings, dict):
        raise ValueError("settings is not an object")
    checked: dict[str, Any] = {}
    for key, value in settings.items():
        if key == "band":
            if not (isinstance(value, list) and len(value) == 2):
                raise ValueError(f"band {_short(value)} is not two heights")
            low, high = _number(value[0]), _number(value[1])
            if max(abs(low), abs(high)) > MAX_WORLD_COORDINATE:
                raise ValueError(f"band {_short(value)} lies past {MAX_WORLD_COORDINATE:g} m")
            checked[key] = [low, high]
        else:
            number = _number(value)
            if abs(number) > MAX_DISTANCE:
                raise ValueError(f"setting {_short(key)} = {number:g} is past {MAX_DISTANCE:g}")
            checked[key] = number
    if "band" not in checked:
        raise KeyError("band")
    return unit, half_unit, origin, checked


def _layout(listed: Any, version: int, fail: Any) -> list[tuple[str, str, tuple[int, ...]]]:
    """The header's ``arrays``: names this version writes, once each, with their dtypes and shapes."""
    schema = _schema(version)
    if not isinstance(listed, list):
        raise fail("header field missing or malformed: arrays is not a list")
    layout: list[tuple[str, str, tuple[int, ...]]] = []
    for item in listed:
        if not (isinstance(item, list) and len(item) == 3 and isinstance(item[0], str) and isinstance(item[2], list)):
            raise fail(f"header field missing or malformed: array {_short(item)} is not [name, dtype, shape]")
        array_name, dtype, shape = item
        if array_name not in schema or any(array_name == seen for seen, _, _ in layout):
            raise fail(f"array {_short(array_name)} is unknown to version {version} or listed twice")
        dtypes, trailing = schema[array_name]
        if dtype not in dtypes:
            raise fail(f"array {array_name} has dtype {_short(dtype)}, not {' or '.join(dtypes)}")
        if any(isinstance(s, bool) or not isinstance(s, int) for s in shape) or any(s < 0 for s in shape):
            raise fail(f"array {array_name} has a negative size or a shape of no whole numbers: {_short(shape)}")
        fits = (len(shape) == 2 and max(shape) <= MAX_TILES if trailing is None
                else len(shape) == 1 + len(trailing) and tuple(shape[1:]) == trailing)
        if not fits:
            raise fail(f"array {array_name} has shape {_short(shape)}")
        layout.append((array_name, dtype, tuple(shape)))
    return layout


def _ragged_offsets(arrays: dict[str, np.ndarray], vertices: np.ndarray) -> tuple[np.ndarray, ...]:
    """The region's ring, part and geometry offsets, checked against the vertices and each
    other before shapely indexes with them (it does not check: an offset past the vertices
    crashed the interpreter): each runs from 0 to the count of the level below, every ring
    has four vertices or more and closes, every polygon a ring, one geometry of them all."""
    offsets = []
    below = vertices.shape[0]
    for n, least in ((0, 4), (1, 1), (2, 1)):
        offset = arrays[f"region_offsets_{n}"].astype(np.int64)
        if offset.size < 2 or offset[0] != 0 or offset[-1] != below or (np.diff(offset) < least).any():
            raise ValueError(f"region_offsets_{n} do not run from 0 to {below} in steps of {least} or more")
        offsets.append(offset)
        below = offset.size - 1
    if below != 1:
        raise ValueError(f"{below} geometries, not one")
    rings = offsets[0]
    if (vertices[rings[:-1]] != vertices[rings[1:] - 1]).any():
        raise ValueError("a ring does not close")
    return tuple(offsets)


def decode(data: bytes | bytearray, name: str = "occmap") -> MapArrays:
    """A world map's numbers from the file's bytes; :class:`InputError` naming ``name`` if damaged.

    Every size, offset, count and number is checked against the bytes present and each
    other before anything is allocated from it or indexed with it; the header is parsed
    with depth and number lengths bounded (:func:`occtool._json.loads`)."""
    try:
        return _decode(data, name)
    except MemoryError:
        raise unreadable(name, f"not enough memory to decode its {len(data)} bytes") from None


def _decode(data: bytes | bytearray, name: str) -> MapArrays:
    import shapely

    from occtool._json import loads

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
        header = loads(bytes(data[start:start + length]).decode("utf-8"), max_depth=MAX_HEADER_DEPTH,
                       bounded_numbers=True)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise fail(f"header is not JSON: {exc.msg if hasattr(exc, 'msg') else exc}") from None
    if not isinstance(header, dict) or header.get("format") != "occtool.occmap":
        raise fail("header does not name the occmap format")
    version = header.get("version")
    if isinstance(version, bool) or version not in READS:
        raise fail(f"format version {_short(version)}, this occtool reads "
                   f"{', '.join(map(str, READS[:-1]))} and {READS[-1]}")
    try:
        unit, half_unit, origin, settings = _grid_fields(header, version)
    except KeyError as exc:
        raise fail(f"header field missing or malformed: no {exc}") from None
    except ValueError as exc:
        raise fail(f"header field missing or malformed: {exc}") from None
    offset = start + length
    arrays: dict[str, np.ndarray] = {}
    for array_name, dtype, shape in _layout(header.get("arrays"), version, fail):
        itemsize = np.dtype(dtype).itemsize
        size = math.prod(shape) * itemsize  # Python integers: no overflow
        if offset + size > len(data) - 4:
            raise fail(f"array {array_name} runs past the end of the file")
        arrays[array_name] = np.frombuffer(data, dtype=np.dtype(dtype).newbyteorder("<"), count=size // itemsize,
                                           offset=offset).reshape(shape).astype(dtype)
        offset += size
    if offset != len(data) - 4:
        raise fail(f"{len(data) - 4 - offset} bytes after the last array")
    try:
        first, last, thickness, trust, facing = _segments(arrays, version, origin, unit, half_unit)
    except (KeyError, ValueError) as exc:
        raise fail(f"segment arrays missing or misshapen: {exc}") from None
    region = shapely.MultiPolygon()
    regional = [n for n in arrays if n.startswith("region_")]
    if regional:
        try:
            if version >= 4:
                vertices = _stepped_vertices(arrays["region_steps"], arrays["region_anchors"])
            else:
                vertices = arrays["region_coords"].astype(np.int64)
            offsets = _ragged_offsets(arrays, vertices)
        except KeyError as exc:
            raise fail(f"observed region is malformed: no array {exc}") from None
        except ValueError as exc:
            raise fail(f"observed region is malformed: {exc}") from None
        coords = origin + vertices.astype(np.float64) * unit
        try:
            region = shapely.from_ragged_array(shapely.GeometryType.MULTIPOLYGON, coords, offsets)[0]
        except (ValueError, IndexError, shapely.errors.ShapelyError) as exc:
            raise fail(f"observed region is malformed: {exc}") from None
    positions = origin + arrays["positions"].astype(np.float64) * unit if "positions" in arrays else None
    band_values = settings.pop("band")
    return MapArrays(first, last, thickness, trust, region, (band_values[0], band_values[1]), positions, facing,
                     settings, unit, origin, half_unit, version)


def _segments(arrays: dict[str, np.ndarray], version: int, origin: np.ndarray, unit: float,
              half_unit: float | None) -> tuple[np.ndarray, ...]:
    """The segments' end points, thickness, trust and facing in the file's order;
    ``KeyError`` / ``ValueError`` if their arrays are missing or disagree."""
    if half_unit is None:  # version 1: both end points
        segments = arrays["segments"].astype(np.float64) * unit
        first, last = origin + segments[:, :2], origin + segments[:, 2:]
    else:
        count = arrays["middles"].shape[0]
        for other in ("directions", "half_lengths"):
            if arrays[other].shape[0] != count:
                raise ValueError(f"{arrays[other].shape[0]} {other} for {count} middles")
        middles = _tiled_middles(arrays["tile_counts"], arrays["middles"]) if version >= 4 else arrays["middles"]
        first, last = _segment_ends(middles, arrays["directions"], arrays["half_lengths"], origin, unit, half_unit)
    for other in ("thickness", "trust"):
        if arrays[other].shape[0] != first.shape[0]:
            raise ValueError(f"{arrays[other].shape[0]} {other} values for {first.shape[0]} segments")
    thickness = arrays["thickness"].astype(np.float64) / 1000.0
    trust = arrays["trust"].astype(np.float64) / 255.0
    facing = (_unpack_facing(arrays["facing"], first.shape[0]) if version >= 3
              else np.zeros(first.shape[0], dtype=np.int8))
    if version < 4:  # into the file's order, as a map quantise() made
        order, _ = _tiles(np.clip(np.round((0.5 * (first + last) - origin) / unit), 0, 65535))
        first, last, thickness, trust, facing = (a[order] for a in (first, last, thickness, trust, facing))
    return first, last, thickness, trust, facing


def read_map(path: str | os.PathLike[str]) -> MapArrays:
    """:func:`decode` of a ``.occmap`` file (``occtool map`` writes ``DIR/world.occmap``);
    a file that cannot be read or is damaged is an :class:`InputError`
    (:func:`read_map_bytes` reads it)."""
    return decode(read_map_bytes(path), str(path))


def header_version(data: bytes | bytearray) -> Any:
    """The ``version`` a ``.occmap`` file's header names (``None`` where it names none or
    cannot be read: :func:`decode` then says what is wrong), to pick the reader of a file
    that passed :func:`read_map_bytes`."""
    (length,) = struct.unpack("<I", bytes(data[len(MAGIC):len(MAGIC) + 4]))
    try:
        header = json.loads(bytes(data[len(MAGIC) + 4:len(MAGIC) + 4 + length]).decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        return None
    return header.get("version") if isinstance(header, dict) else None


def read_map_bytes(path: str | os.PathLike[str]) -> bytearray:
    """The bytes of a ``.occmap`` file of any version, or an :class:`InputError`.

    The file is checked before its body is read: a regular file (not a FIFO or a device
    such as ``/dev/zero``, which never end) of at most :data:`occtool.limits.MAX_MAP_BYTES`,
    with the signature and a header length that fits it; then exactly the bytes it had
    when it was looked at are read."""
    from occtool.limits import MAX_MAP_BYTES

    name = str(path)
    try:
        info = os.stat(path)
        if not stat.S_ISREG(info.st_mode):
            raise InputError(f"{name}: not a regular file, so not a map occtool wrote")
        if info.st_size > MAX_MAP_BYTES:
            raise unreadable(name, f"{info.st_size} bytes, more than the {MAX_MAP_BYTES >> 20} MB a map may have")
        with open(path, "rb") as stream:
            size = os.fstat(stream.fileno()).st_size
            if size != info.st_size:
                raise unreadable(name, "the file changed while it was read")
            data = bytearray(size)
            view = memoryview(data)
            prefix = stream.readinto(view[:len(MAGIC) + 4])
            if prefix < len(MAGIC) + 4 or not data.startswith(MAGIC):
                raise unreadable(name, "no occmap signature")
            (length,) = struct.unpack("<I", data[len(MAGIC):len(MAGIC) + 4])
            if length > MAX_HEADER or len(MAGIC) + 8 + length > size:
                raise unreadable(name, "header length out of range")
            got = prefix
            while got < size:
                chunk = stream.readinto(view[got:])
                if not chunk:
                    break
                got += chunk
    except OSError as exc:
        raise InputError(f"{name}: cannot read the map: {exc.strerror or exc}") from None
    except MemoryError:
        raise unreadable(name, f"not enough memory to read its {info.st_size} bytes") from None
    if got != size:
        raise unreadable(name, "the file changed while it was read")
    return data


__all__ = ["FORMAT_VERSION", "MAGIC", "UNIT", "MapArrays", "array_bytes", "decode", "encode", "framed", "header_version",
           "quantise", "read_map", "read_map_bytes", "save_map", "unreadable"]
