"""The ``.occmap`` file: one :class:`~occtool.fuse._world.WorldMap` on disk, versioned and checked.

Layout (little-endian)::

    8 bytes   magic  b"\\x89OCCMAP\\n"
    4 bytes   uint32 header length H
    H bytes   UTF-8 JSON header: format version, unit, origin, the map's settings,
              and each array's name, dtype and shape in the order they follow
    ...       the arrays' bytes, back to back
    4 bytes   uint32 CRC-32 of everything before it

Arrays (version 3): ``middles`` uint16 ``(S, 2)``, each segment's middle in units from
``origin``; ``directions`` uint8 ``(S,)``, its direction in [0, pi) in steps of pi/256;
``half_lengths`` uint8 ``(S,)`` in the header's ``half_unit`` (2 mm unless a segment is
longer than 1.02 m); ``thickness`` and ``trust`` uint8 ``(S,)`` (millimetres,
1/255ths): 8 bytes a segment, where its two end points took 10 in version 1 (``segments``
uint16 ``(S, 4)``, still read); ``facing`` uint8 ``(ceil(S / 4),)``, the side each segment
was seen from in two bits (0 both, 1 the left of its direction, 2 the right; segment ``i``
in bits ``2 (i mod 4)`` of byte ``i // 4``; absent in versions 1 and 2: every segment
faces both); ``positions`` uint16 ``(P, 2)`` in units, the run's
positions (the free level rises away from them; absent in version 1). The observed region
as shapely's ragged arrays: ``region_coords`` uint16 ``(V, 2)`` in units and its
``region_offsets_*`` uint32. A map is quantised to this precision when it is built
(:func:`quantise`), so a map read back answers exactly as the one written.
:func:`load_map` checks the magic, the version, the sizes, the checksum and every value:
a damaged or foreign file is one :class:`~occtool.errors.InputError`.
"""

from __future__ import annotations

import json
import math
import os
import struct
import zlib
from typing import Any

import numpy as np

from occtool.errors import InputError

MAGIC = b"\x89OCCMAP\n"
FORMAT_VERSION = 3
#: Versions :func:`decode` reads.
READS = (1, 2, 3)
#: A segment's half-length in this unit (metres) unless one is longer than 255 of them.
HALF_UNIT = 0.002
#: Direction steps over [0, pi).
DIRECTION_STEPS = 256
#: A header longer than this is not an occmap header (bytes).
MAX_HEADER = 1 << 20
_DTYPES = {"uint8": np.uint8, "uint16": np.uint16, "uint32": np.uint32}


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


def quantise(world: Any, unit: float | None = None) -> Any:
    """``world`` with its numbers rounded to what the file stores (a new map; same settings)."""
    import shapely

    from occtool.fuse._world import UNIT, WorldMap

    unit = UNIT if unit is None else float(unit)
    lower, upper = world.bounds
    origin, unit = _grid(lower, upper, unit)

    def snap(xy: np.ndarray) -> np.ndarray:
        return origin + np.clip(np.round((xy - origin) / unit), 0, 65535) * unit

    half_unit = _half_unit(0.5 * np.hypot(*(world.end - world.start).T))
    start, end = _segment_ends(*_segment_codes(world, origin, unit, half_unit), origin, unit, half_unit)
    # The stored direction lies in [0, pi): a segment turned round faces the other way.
    turned = ((world.end - world.start) * (end - start)).sum(axis=1)
    facing = np.where(np.hypot(*(end - start).T) > 1e-12, np.sign(turned), 0).astype(np.int8) * world.facing
    thickness = np.clip(np.round(world.thickness * 1000.0), 0, 255) / 1000.0
    trust = np.clip(np.round(world.trust * 255.0), 0, 255) / 255.0
    region = world.region
    if not region.is_empty:
        # On the file's grid and valid there (origin is a whole number of units), then
        # through the loader's own arithmetic, so that a map read back is this one.
        region = _areal(shapely.transform(_areal(shapely.set_precision(region, unit)), snap))
    params = world.params()
    band = params.pop("band")
    quantised = WorldMap(start, end, thickness, trust, region, band=band, positions=snap(world.positions),
                         facing=facing, **params)
    quantised.unit, quantised.origin, quantised.half_unit = unit, origin, half_unit
    return quantised


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
    arrays = [("middles", middles.reshape(-1, 2)), ("directions", steps), ("half_lengths", half),
              ("thickness", np.clip(np.round(world.thickness * 1000.0), 0, 255).astype(np.uint8)),
              ("trust", np.clip(np.round(world.trust * 255.0), 0, 255).astype(np.uint8)),
              ("facing", _pack_facing(world.facing))]
    arrays.append(("positions", units(world.positions).reshape(-1, 2)))
    region = _areal(world.region) if not world.region.is_empty else shapely.MultiPolygon()
    if not region.is_empty:
        _, coords, offsets = shapely.to_ragged_array([region])
        arrays.append(("region_coords", units(coords)))
        for n, offset in enumerate(offsets):
            arrays.append((f"region_offsets_{n}", np.asarray(offset, dtype="<u4")))
    header = {"format": "occtool.occmap", "version": FORMAT_VERSION, "unit": unit, "half_unit": half_unit,
              "origin": [float(origin[0]), float(origin[1])], "settings": world.params(),
              "arrays": [[name, str(a.dtype.name), list(a.shape)] for name, a in arrays]}
    return header, arrays


def encode(world: Any) -> bytes:
    """The file's bytes for ``world``."""
    header, arrays = _arrays(world)
    text = json.dumps(header, sort_keys=True, separators=(",", ":")).encode("utf-8")
    body = MAGIC + struct.pack("<I", len(text)) + text + b"".join(a.astype(a.dtype.newbyteorder("<")).tobytes()
                                                                   for _, a in arrays)
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def save_map(world: Any, path: str | os.PathLike[str], *, overwrite: bool = True) -> int:
    """Write ``world`` to ``path`` through a temporary file; returns the bytes written."""
    from occtool.io._atomic import atomic_write

    data = encode(world)
    with atomic_write(path, "wb", overwrite=overwrite) as stream:
        stream.write(data)
    return len(data)


def decode(data: bytes, name: str = "occmap") -> Any:
    """A :class:`WorldMap` from the file's bytes; :class:`InputError` naming ``name`` if damaged."""
    import shapely

    from occtool.fuse._world import WorldMap

    def fail(why: str) -> InputError:
        return InputError(f"{name}: not a readable occtool map ({why})")

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
            first, last = _segment_ends(arrays["middles"].reshape(-1, 2), arrays["directions"].reshape(-1),
                                        arrays["half_lengths"].reshape(-1), origin, unit, half_unit)
        thickness = arrays["thickness"].astype(np.float64) / 1000.0
        trust = arrays["trust"].astype(np.float64) / 255.0
        facing = (_unpack_facing(arrays["facing"].reshape(-1), first.shape[0]) if version >= 3
                  else np.zeros(first.shape[0], dtype=np.int8))
    except (KeyError, ValueError) as exc:
        raise fail(f"segment arrays missing or misshapen: {exc}") from None
    region = shapely.MultiPolygon()
    if "region_coords" in arrays:
        coords = origin + arrays["region_coords"].reshape(-1, 2).astype(np.float64) * unit
        offsets = [arrays[f"region_offsets_{n}"].astype(np.int64) for n in range(3) if f"region_offsets_{n}" in arrays]
        try:
            region = shapely.from_ragged_array(shapely.GeometryType.MULTIPOLYGON, coords, tuple(offsets))[0]
        except (ValueError, IndexError, shapely.errors.ShapelyError) as exc:
            raise fail(f"observed region is malformed: {exc}") from None
    try:
        band = settings.pop("band")
        positions = (origin + arrays["positions"].reshape(-1, 2).astype(np.float64) * unit
                     if "positions" in arrays else None)
        world = WorldMap(first, last, thickness, trust, region, positions=positions, facing=facing,
                         band=(float(band[0]), float(band[1])), **{k: float(v) for k, v in settings.items()})
    except (InputError, TypeError, KeyError, IndexError, ValueError) as exc:
        raise fail(str(exc)) from None
    world.unit, world.origin, world.half_unit = unit, origin, half_unit
    return world


def load_map(path: str | os.PathLike[str]) -> Any:
    """Read a ``.occmap`` file written by :meth:`WorldMap.save` (``occtool map`` writes
    ``DIR/world.occmap``); a damaged file is an :class:`InputError`."""
    try:
        with open(path, "rb") as stream:
            data = stream.read()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the map: {exc.strerror or exc}") from None
    return decode(data, str(path))


__all__ = ["FORMAT_VERSION", "MAGIC", "decode", "encode", "load_map", "quantise", "save_map"]
