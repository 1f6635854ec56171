"""Versions 5 and 6 of the ``.occmap`` file: a 3D world map (:class:`occtool.fuse._world3d.WorldMap3D`).

Version 6 is written; version 5 is still read (the notes at the end say what changed).

Layout (little-endian), the header conventions of :mod:`occtool.formats.occmap`::

    8 bytes   magic  b"\\x89OCCMAP\\n"
    4 bytes   uint32 header length H
    H bytes   UTF-8 JSON header: format "occtool.occmap", version 6, kind "world3d", unit, frame (left
              out for the default, the frame of the log's poses), resolution, box (``lo`` cell
              indices and ``shape``), falloffs, free level, ``levels`` (the patches of each
              level), ``planes`` (how many of them hold their own plane), ``surface_bytes``,
              ``free_shift``, ``free_saturation``, ``free_classes``, ``extent``, ``packed``
              (the length of the zlib stream) and, where the map's frame is not the poses',
              ``to_map``: 12 numbers, a row-major 3x4 rigid transform from the poses' frame
              to the map's, applied to every query
    ...       one zlib stream of the arrays' bytes, back to back (a deflate block each)
    4 bytes   uint32 CRC-32 of everything before it

Arrays of version 6: ``free`` uint8 ``(F,)``, one byte for each cell of the free space's box
(its cells ``2 ** free_shift`` times the resolution, the box :func:`level_box` of that level;
x slowest, z fastest): 0 where no training ray passed, else 1 + the cell's class (how often
rays crossed it), whose occupancy :func:`free_table` gives; ``surface0``, ``surface1``, ...
the cells of each level holding a patch (level ``l``'s cells ``2 ** l`` times the
resolution, keys into its box), as the varint gaps between them (:func:`varint_gaps`,
``surface_bytes`` long); then the patches, level by level in the order of their cells,
column by column (each column compresses on its own terms): ``refs`` ``(S,)``, ``normals``
and ``offsets`` ``(P,)`` (the ``P`` patches with their own plane), ``thickness`` and
``trust`` ``(S,)``, all uint8 (:class:`PatchCodes`): at most 5 bytes a patch before
compression. A patch is a plane through its cell: its normal and its distance from the
cell's centre, or its neighbour's plane; its extent along the plane is the header's
``extent`` times its cell. :func:`decode` checks the magic, version, sizes (before
allocating), checksum and values: a damaged file is one :class:`~occtool.errors.InputError`.

Version 5 (read, no longer written): ``free`` a bitset of the crossed cells at the map's
resolution, every one at the header's ``free_level``; the patches in the columns
``offsets`` ``(S, 3)``, ``normals`` ``(S, 2)``, ``axes``, ``extents`` ``(S, 2)``,
``thickness``, ``trust`` (:class:`PatchCodesV5`), 10 bytes a patch.
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
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.formats.occmap import MAGIC, MAX_HEADER, framed, write_file
from occtool.limits import MAX_DISTANCE, MAX_WORLD_COORDINATE, MIN_DISTANCE

FloatArray = NDArray[np.float64]

#: The header's ``format`` and ``version``, as :mod:`occtool.formats.occmap` writes them
#: (versions 1-4 are the 2D map's).
FORMAT = "occtool.occmap"
FORMAT_VERSION = 6
#: The versions this module reads.
VERSIONS = (5, 6)
KIND = "world3d"
#: Most cells a box may hold (a bitset of 256 MB at most, checked before inflating).
MAX_CELLS = 1 << 31
#: Most levels of patches a file may hold.
MAX_LEVELS = 8
#: The patch columns of each version: name, bytes a patch.
COLUMNS = (("refs", 1), ("normals", 1), ("offsets", 1), ("thickness", 1), ("trust", 1))
#: The version-6 columns held only for the patches with their own plane.
PLANE_COLUMNS = ("normals", "offsets")
COLUMNS_V5 = (("offsets", 3), ("normals", 2), ("axes", 1), ("extents", 2), ("thickness", 1), ("trust", 1))
#: Normal codes of version 6: :data:`POLAR_STEPS` polar angles by :data:`AZIMUTH_STEPS` azimuths.
POLAR_STEPS = 9
AZIMUTH_STEPS = 16
NORMAL_CODES = POLAR_STEPS * AZIMUTH_STEPS
#: The frame a map answers in unless its header names another.
DEFAULT_FRAME = "the frame of the log's poses"
#: Most classes of crossed cells a file may hold.
MAX_FREE_CLASSES = 64


@dataclass
class PatchCodes:
    """The patches at the file's precision (version 6), in the order of their cells' keys.

    ``keys`` int64 ``(S,)`` each patch's cell as a linear index into its level's box (x
    slowest, z fastest), sorted; ``normals`` uint8 ``(S,)`` the normal's direction code
    (:func:`occtool.fuse._patches.normal_of`); ``offsets`` uint8 ``(S,)`` the plane's signed
    distance from the cell's centre along the normal, in 1/64ths of the cell, plus 128;
    ``thickness`` uint8 ``(S,)`` the half-thickness in mm; ``trust`` uint8 ``(S,)`` in
    1/255ths (never 0).
    """

    keys: NDArray[np.int64]
    refs: NDArray[np.uint8]
    normals: NDArray[np.uint8]
    offsets: NDArray[np.uint8]
    thickness: NDArray[np.uint8]
    trust: NDArray[np.uint8]

    def __len__(self) -> int:
        return int(self.keys.size)


@dataclass
class PatchCodesV5:
    """The patches of a version-5 file, in the order of their cells' keys.

    ``keys`` int64 ``(S,)`` each patch's cell as a linear index into the map's box (x slowest,
    z fastest), sorted; ``offsets`` uint8 ``(S, 3)`` the centre within its cell in 1/256ths;
    ``normals`` uint8 ``(S, 2)`` polar and azimuth codes; ``axes`` uint8 ``(S,)`` the in-plane
    direction of the largest extent; ``extents`` uint8 ``(S, 2)`` half-extents along it and
    across it in 1/255ths of the cell; ``thickness`` uint8 ``(S,)`` the half-thickness in mm;
    ``trust`` uint8 ``(S,)`` in 1/255ths (never 0).
    """

    keys: NDArray[np.int64]
    offsets: NDArray[np.uint8]
    normals: NDArray[np.uint8]
    axes: NDArray[np.uint8]
    extents: NDArray[np.uint8]
    thickness: NDArray[np.uint8]
    trust: NDArray[np.uint8]

    def __len__(self) -> int:
        return int(self.keys.size)


def free_table(resolution: float, free_level: float, saturation: float, classes: int) -> FloatArray:
    """The occupancy of each class of crossed cells (version 6): class ``c`` holds the cells
    that ``2 ** c`` to ``2 ** (c + 1) - 1`` points of a walk in steps of half a cell fell in
    (the last every cell above); its occupancy falls from 0.5 towards ``free_level`` as
    ``1 - exp(-n / s)`` of the class's typical count ``n`` (its geometric middle), ``s`` the
    ``saturation`` times the cell's face (``resolution`` its edge)."""
    typical = 2.0 ** (np.arange(classes) + 0.5)
    scale = saturation * resolution * resolution
    with np.errstate(divide="ignore", over="ignore"):  # a tiny saturation: every class at the free level
        return np.asarray(0.5 - (0.5 - free_level) * (1.0 - np.exp(-typical / scale)), dtype=np.float64)


def level_box(lo: NDArray[np.int64], shape: tuple[int, int, int], level: int) -> tuple[NDArray[np.int64],
                                                                                         tuple[int, int, int]]:
    """The box of cells ``2 ** level`` times coarser that covers the box ``lo``, ``shape``."""
    low = np.floor_divide(lo, 1 << level)
    high = np.floor_divide(lo + np.asarray(shape) - 1, 1 << level)
    size = high - low + 1
    return low.astype(np.int64), (int(size[0]), int(size[1]), int(size[2]))


def rigid(matrix: ArrayLike) -> FloatArray:
    """``matrix`` as a 4x4 rigid transform (a rotation and a translation), or an InputError."""
    out = np.asarray(matrix, dtype=np.float64)
    if out.shape != (4, 4) or not np.isfinite(out).all() or not np.allclose(out[3], [0.0, 0.0, 0.0, 1.0]) or not (
            np.allclose(out[:3, :3] @ out[:3, :3].T, np.eye(3), atol=1e-6) and np.linalg.det(out[:3, :3]) > 0.0):
        raise InputError("a map's frame transform must be a 4x4 rotation and translation")
    return out


@dataclass
class Map3DArrays:
    """A 3D world map's numbers as the file holds them: the keywords of
    :class:`occtool.fuse.WorldMap3D` (which :func:`occtool.fuse.load_map_3d` makes of them)."""

    resolution: float
    lo: np.ndarray
    shape: tuple[int, int, int]
    free_keys: np.ndarray
    patches: list[Any]
    falloff: float
    edge_falloff: float
    free_level: float
    frame: str
    to_map: np.ndarray | None
    free_codes: np.ndarray | None = None
    free_table: np.ndarray | None = None
    free_shift: int = 0
    extent: float = 1.0
    free_saturation: float = 0.0


def varint_gaps(keys: np.ndarray) -> np.ndarray:
    """Sorted distinct keys as the gaps between them (the first: the key itself), each an
    unsigned LEB128 varint (7 bits a byte, the high bit set on all but a number's last byte)."""
    gaps = np.diff(np.r_[-1, np.asarray(keys, dtype=np.int64)]) - 1
    if not gaps.size:
        return np.zeros(0, dtype=np.uint8)
    width = np.maximum(1, (np.floor(np.log2(np.maximum(gaps, 1))).astype(np.int64) // 7) + 1)
    owner = np.repeat(np.arange(gaps.size), width)
    index = np.arange(owner.size) - np.repeat(np.cumsum(width) - width, width)
    byte = (gaps[owner] >> (7 * index)) & 0x7F
    return (byte | np.where(index < width[owner] - 1, 0x80, 0)).astype(np.uint8)


def keys_of_varints(data: np.ndarray, count: int, cells: int) -> np.ndarray | None:
    """The keys :func:`varint_gaps` coded, or None unless ``data`` holds exactly ``count`` of
    them below ``cells``."""
    if data.size == 0:
        return np.zeros(0, dtype=np.int64) if count == 0 else None
    last = np.flatnonzero(data < 0x80)
    if last.size != count or last[-1] != data.size - 1:
        return None
    width = np.diff(np.r_[-1, last])
    if int(width.max()) > 5:
        return None
    owner = np.repeat(np.arange(count), width)
    index = np.arange(data.size) - np.repeat(np.cumsum(width) - width, width)
    gaps = np.zeros(count, dtype=np.int64)
    np.add.at(gaps, owner, (data.astype(np.int64) & 0x7F) << (7 * index))
    keys = np.cumsum(gaps + 1) - 1
    return keys if int(keys[-1]) < cells else None


def _bitset(keys: np.ndarray, cells: int) -> np.ndarray:
    bits = np.zeros(cells, dtype=bool)
    bits[keys] = True
    return np.packbits(bits)


def _header(world: Any, version: int) -> dict[str, Any]:
    header = {"format": FORMAT, "version": version, "kind": KIND, "unit": "m", "frame": world.frame,
              "resolution": world.resolution, "lo": [int(v) for v in world.lo], "shape": list(world.shape),
              "falloff": world.falloff, "edge_falloff": world.edge_falloff, "free_level": world.free_level,
              "levels": [len(codes) for codes in world.patches]}
    if world.to_map is not None:
        header["to_map"] = [float(v) for v in np.asarray(world.to_map)[:3].reshape(-1)]
    return header


def encode(world: Any) -> bytes:
    """The file's bytes for a :class:`~occtool.fuse._world3d.WorldMap3D`: version 6, or
    version 5 for a map read from a version-5 file (its patches are coded as that version's)."""
    if any(isinstance(codes, PatchCodesV5) for codes in world.patches):
        return _encode_v5(world)
    free = np.zeros(int(np.prod(level_box(world.lo, world.shape, world.free_shift)[1])), dtype=np.uint8)
    # A map made without classes: every crossed cell at the free level (one class, saturated).
    graded = world.free_codes is not None and world.free_table is not None
    free[world.free_keys] = np.asarray(world.free_codes, dtype=np.uint8) + 1 if graded else 1
    saturation, classes = (float(world.free_saturation), int(world.free_table.size)) if graded else (1e-9, 1)
    arrays = [free]
    surfaces = [varint_gaps(codes.keys) for codes in world.patches]
    arrays += surfaces
    for name, _ in COLUMNS:
        arrays.append(np.concatenate([np.asarray(getattr(codes, name), dtype=np.uint8).reshape(-1)[
            codes.refs == 0 if name in PLANE_COLUMNS else slice(None)] for codes in world.patches]))
    # One zlib stream, a deflate block an array: each array's own code tables (about a
    # tenth fewer bytes than one block over them all on the TUM cabinet).
    deflate = zlib.compressobj(9)
    payload = b"".join(deflate.compress(a.tobytes()) + deflate.flush(zlib.Z_BLOCK) for a in arrays) + deflate.flush()
    header = _header(world, FORMAT_VERSION)
    header["surface_bytes"] = [int(a.size) for a in surfaces]
    if header["frame"] == DEFAULT_FRAME:
        del header["frame"]
    header.update(free_shift=int(world.free_shift), extent=float(world.extent),
                  planes=[int(np.sum(codes.refs == 0)) for codes in world.patches],
                  free_saturation=saturation, free_classes=classes,
                  packed=len(payload))
    return framed(json.dumps(header, separators=(",", ":")).encode("utf-8"), payload)


def _encode_v5(world: Any) -> bytes:
    cells = int(np.prod(world.shape))
    arrays = [("free", _bitset(world.free_keys, cells))]
    for level, codes in enumerate(world.patches):
        arrays.append((f"surface{level}", _bitset(codes.keys, int(np.prod(level_box(world.lo, world.shape, level)[1])))))
    for name, width in COLUMNS_V5:
        rows = np.concatenate([np.asarray(getattr(codes, name), dtype=np.uint8).reshape(len(codes), width)
                               for codes in world.patches])
        arrays.append((name, np.ascontiguousarray(rows.T).reshape(-1)))
    payload = zlib.compress(b"".join(a.tobytes() for _, a in arrays), 9)
    header = _header(world, 5)
    header.update(arrays=[[name, "uint8", list(a.shape)] for name, a in arrays], packed=len(payload))
    return framed(json.dumps(header, separators=(",", ":")).encode("utf-8"), payload)


def save_map3d(world: Any, path: str | os.PathLike[str], *, overwrite: bool = True) -> int:
    """Write ``world`` to ``path`` atomically; returns the bytes written."""
    return write_file(encode(world), path, overwrite=overwrite)


def decode(data: bytes, name: str = "occmap") -> Map3DArrays:
    """A version-5 file's numbers (:class:`Map3DArrays`), checked; :func:`occtool.fuse.load_map_3d`
    makes the map of them."""

    def fail(why: str) -> InputError:
        return InputError(f"{name}: not a readable 3D world map ({why})")

    if len(data) < len(MAGIC) + 8 or not data.startswith(MAGIC):
        raise fail("no occmap magic")
    (stored,) = struct.unpack("<I", data[-4:])
    if zlib.crc32(data[:-4]) & 0xFFFFFFFF != stored:
        raise fail("checksum mismatch: the file is damaged or truncated")
    (length,) = struct.unpack("<I", data[len(MAGIC):len(MAGIC) + 4])
    start = len(MAGIC) + 4
    if length > MAX_HEADER or start + length > len(data) - 4:
        raise fail("header length beyond the file")
    try:
        header = json.loads(data[start:start + length].decode("utf-8"))
        version, kind = header["version"], header["kind"]
        if header["format"] != FORMAT:
            raise fail("not an occtool.occmap header")
        resolution, falloff, edge_falloff, free_level = (float(header[k]) for k in (
            "resolution", "falloff", "edge_falloff", "free_level"))
        lo = np.array([int(v) for v in header["lo"]], dtype=np.int64)
        shape = tuple(int(v) for v in header["shape"])
        counts = [int(v) for v in header["levels"]]
        packed = int(header["packed"])
        frame = str(header.get("frame", DEFAULT_FRAME))
        to_map = header.get("to_map")
        if version == 6:
            free_shift, extent = int(header["free_shift"]), float(header["extent"])
            saturation, classes = float(header["free_saturation"]), int(header["free_classes"])
            planes = [int(v) for v in header["planes"]]
            surface_bytes = [int(v) for v in header["surface_bytes"]]
            if not (math.isfinite(saturation) and saturation > 0.0 and 1 <= classes <= MAX_FREE_CLASSES
                    and 0.0 <= free_level <= 1.0):
                raise fail("bad free space")
            table = free_table(resolution * (1 << min(max(free_shift, 0), MAX_LEVELS)), free_level, saturation,
                               classes)
        else:
            free_shift, extent, table, saturation, planes = 0, 1.0, np.zeros(0), 0.0, list(counts)
            surface_bytes = []
        if to_map is not None:
            to_map = np.vstack([np.array([float(v) for v in to_map], dtype=np.float64).reshape(3, 4),
                                [0.0, 0.0, 0.0, 1.0]])
    except (ValueError, KeyError, TypeError, OverflowError, UnicodeDecodeError):
        raise fail("unreadable header") from None
    if version not in VERSIONS or kind != KIND:
        raise fail(f"version {version!r} {kind!r}, this reads {' and '.join(map(str, VERSIONS))} {KIND!r}")
    if not (0 <= free_shift < MAX_LEVELS and 0.0 < extent <= 4.0 and table.size <= MAX_FREE_CLASSES
            and (version == 5 or table.size >= 1) and np.all((table >= 0.0) & (table <= 1.0))):
        raise fail("bad free space or patch extent")
    if lo.shape != (3,) or len(shape) != 3 or min(shape) < 1 or not all(
            MIN_DISTANCE <= v <= MAX_DISTANCE for v in (resolution, falloff, edge_falloff)):
        raise fail("bad box, resolution or falloff")
    # Lengths a map can hold: finite is not enough (a resolution of 1e153 m passes that, and
    # its queries' reach overflows to infinity).
    if not (np.abs(lo * resolution) <= MAX_WORLD_COORDINATE).all() or not (
            np.abs((lo + np.asarray(shape)) * resolution) <= MAX_WORLD_COORDINATE).all():
        raise fail(f"a box beyond {MAX_WORLD_COORDINATE:g} m")
    if not 0.0 <= free_level <= 1.0:
        raise fail("free level outside [0, 1]")
    if to_map is not None:
        try:
            to_map = rigid(to_map)
        except InputError:
            raise fail("the frame transform is not a rotation and translation") from None
    cells = shape[0] * shape[1] * shape[2]
    count = sum(counts)
    if cells > MAX_CELLS or not 1 <= len(counts) <= MAX_LEVELS or min(counts) < 0 or count > cells:
        raise fail(f"{cells} cells and patches {counts} is not a map this reads")
    box = (shape[0], shape[1], shape[2])
    level_cells = [int(np.prod(level_box(lo, box, level)[1])) for level in range(len(counts))]
    free_cells = int(np.prod(level_box(lo, box, free_shift)[1]))
    if version == 6 and free_cells > MAX_CELLS // 8:
        raise fail(f"a free space of {free_cells} cells is not a map this reads")
    columns_of = COLUMNS if version == 6 else COLUMNS_V5
    if version == 6 and (len(surface_bytes) != len(counts) or not all(
            n <= b <= 5 * n for n, b in zip(counts, surface_bytes))):
        raise fail("bad surface sizes")
    sizes = [free_cells if version == 6 else (cells + 7) // 8] + (
        surface_bytes if version == 6 else [(c + 7) // 8 for c in level_cells])
    if len(planes) != len(counts) or not all(0 <= p <= c for p, c in zip(planes, counts)):
        raise fail("bad plane counts")
    widths = {name: (sum(planes) if version == 6 and name in PLANE_COLUMNS else count) * width
              for name, width in columns_of}
    expected = sum(sizes) + sum(widths.values())
    if packed != len(data) - 4 - start - length:
        raise fail("array bytes do not match the header")
    inflater = zlib.decompressobj()
    try:
        raw = inflater.decompress(data[start + length:-4], expected + 1)
    except zlib.error:
        raise fail("corrupt array stream") from None
    if len(raw) != expected or inflater.unconsumed_tail or not inflater.eof:
        raise fail("array bytes do not match the header")
    buffer = np.frombuffer(raw, dtype=np.uint8)

    def keys(at: int, size: int, n: int) -> np.ndarray:
        return np.flatnonzero(np.unpackbits(buffer[at:at + size], count=n)).astype(np.int64)

    free_codes: np.ndarray | None = None
    if version == 6:
        free = np.flatnonzero(buffer[:sizes[0]]).astype(np.int64)
        free_codes = buffer[free] - np.uint8(1)
        if free.size and int(free_codes.max()) >= table.size:
            raise fail("a free cell's class beyond the free table")
    else:
        free = keys(0, sizes[0], cells)
    at = sizes[0]
    surfaces = []
    for level, n in enumerate(level_cells):
        found = keys_of_varints(buffer[at:at + sizes[level + 1]], counts[level], n) if version == 6 else (
            keys(at, sizes[level + 1], n))
        if found is None or found.size != counts[level]:
            raise fail(f"the surface cells of level {level} do not match its patch count")
        surfaces.append(found)
        at += sizes[level + 1]
    columns: dict[str, np.ndarray] = {}
    for column, width in columns_of:
        columns[column] = buffer[at:at + widths[column]].reshape(width, -1).T.copy()
        at += widths[column]
    if version == 6:
        _check_refs(columns, counts, planes, surfaces, lo, box, fail)
    if count and (columns["trust"].min() == 0 or columns["thickness"].min() == 0 or (
            version == 5 and columns["extents"].min() == 0)):
        raise fail("patch values out of range")
    patches: list[Any] = []
    first = 0
    for level, n in enumerate(counts):
        part = {name: value[first:first + n] for name, value in columns.items()}
        first += n
        if version == 6:
            patches.append(PatchCodes(surfaces[level], part["refs"][:, 0], part["normals"][:, 0],
                                      part["offsets"][:, 0], part["thickness"][:, 0], part["trust"][:, 0]))
        else:
            patches.append(PatchCodesV5(surfaces[level], part["offsets"], part["normals"], part["axes"][:, 0],
                                        part["extents"], part["thickness"][:, 0], part["trust"][:, 0]))
    return Map3DArrays(resolution, lo, box, free, patches, falloff, edge_falloff, free_level, frame, to_map,
                       free_codes, table if version == 6 else None, free_shift, extent,
                       saturation if version == 6 else 0.0)


def _check_refs(columns: dict[str, np.ndarray], counts: list[int], planes: list[int], surfaces: list[np.ndarray],
                lo: np.ndarray, box: tuple[int, int, int], fail: Any) -> None:
    """Version 6's merged planes, checked: each level's reference codes 0-3, as many 0s as
    its plane count, each reference to a patch of the same level in the cell before it (not
    wrapping round the box); the explicit planes' codes spread over every patch (0 where it
    refers)."""
    refs = columns["refs"][:, 0]
    if refs.size and int(refs.max()) > 3:
        raise fail("patch references out of range")
    normals, offsets = columns["normals"][:, 0], columns["offsets"][:, 0]
    if normals.size and (int(normals.max()) >= NORMAL_CODES or int(offsets.min()) == 0):
        raise fail("patch values out of range")
    full_normals, full_offsets = np.zeros(refs.size, dtype=np.uint8), np.zeros(refs.size, dtype=np.uint8)
    first = 0
    for level, (n, p) in enumerate(zip(counts, planes)):
        part = refs[first:first + n]
        if int(np.sum(part == 0)) != p:
            raise fail(f"level {level}'s references do not match its plane count")
        shape = level_box(lo, box, level)[1]
        keys = surfaces[level]
        steps = np.array([0, 1, shape[2], shape[1] * shape[2]], dtype=np.int64)[part]
        wrap = np.select([part == 1, part == 2, part == 3], [keys % shape[2] == 0, (keys // shape[2]) % shape[1] == 0,
                                                             keys // (shape[1] * shape[2]) == 0], False)
        at = np.clip(np.searchsorted(keys, keys - steps), 0, max(n - 1, 0))
        if n and ((part > 0) & (wrap | (keys[at] != keys - steps))).any():
            raise fail(f"a patch of level {level} refers to a cell without one")
        first += n
    explicit = refs == 0
    full_normals[explicit], full_offsets[explicit] = normals, offsets
    columns["normals"], columns["offsets"] = full_normals[:, None], full_offsets[:, None]


def read_map3d(path: str | os.PathLike[str]) -> Map3DArrays:
    """Read a 3D ``.occmap`` file (version 5 or 6): a regular file of at most
    :data:`occtool.limits.MAX_MAP_BYTES`, checked before it is read whole."""
    from occtool.limits import MAX_MAP_BYTES

    try:
        with open(path, "rb") as handle:
            info = os.fstat(handle.fileno())
            if not stat.S_ISREG(info.st_mode):
                raise InputError(f"{path}: not a readable 3D world map (not a regular file)")
            if info.st_size > MAX_MAP_BYTES:
                raise InputError(f"{path}: not a readable 3D world map ({info.st_size} bytes, more than the "
                                 f"{MAX_MAP_BYTES >> 20} MB a map may have)")
            data = handle.read(MAX_MAP_BYTES + 1)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    return decode(data, str(path))


__all__ = ["FORMAT", "FORMAT_VERSION", "KIND", "Map3DArrays", "PatchCodes", "PatchCodesV5", "VERSIONS", "decode", "encode", "level_box",
           "read_map3d", "rigid", "save_map3d"]
