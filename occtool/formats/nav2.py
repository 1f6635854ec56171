"""Nav2 occupancy maps: ``map.yaml`` + its image as ``nav2_map_server`` reads them.

The YAML names the image, its ``resolution`` (metres per pixel), the ``origin``
``[x, y, yaw]`` of the image's *lower-left* pixel in the map frame, ``negate``,
``occupied_thresh``, ``free_thresh`` and ``mode``. The image is a binary PGM (P5), its
first row the *top* of the map. With ``negate: 0`` map_server reads a pixel ``v`` as the
occupancy ``p = (255 - v) / 255``; in ``trinary`` mode ``p > occupied_thresh`` is occupied
(100), ``p < free_thresh`` free (0) and anything else unknown (-1). occtool writes 254
for free, 0 for occupied and 205 for unknown, the values map_saver writes.

``free_thresh`` is 0.196, not map_saver's old default 0.25: the unknown pixel 205 reads
as ``p = 50 / 255 = 0.1961``, which a threshold of 0.25 loads as *free* (unknown space
handed to the planner as drivable). Nav2 fixed its own trinary maps the same way
(ros-navigation/navigation2 pull request 5278: trinary YAMLs get 0.65 and 0.196, as
ROS 1's map_saver wrote).

A ``scale`` map (:func:`write_nav2_scale`) keeps the map's graded occupancy: an RGBA PNG,
as Nav2's map_saver writes one, grey ``255 (1 - p)``, transparent where unknown (-1);
map_server loads ``p > occupied_thresh`` as 100, ``p < free_thresh`` as 0 and anything
between as ``rint(100 (p - free_thresh) / (occupied_thresh - free_thresh))``. PNG images
need Pillow (the ``png`` extra).
"""

from __future__ import annotations

import math
import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool._files import atomic_write
from occtool.errors import InputError
from occtool.limits import DEFAULT_MEMORY_LIMIT, MAX_DISTANCE, memory_bytes
from occtool.raster import SpilledCells

OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196
#: Bytes of image rows written at a time.
_STRIP_BYTES = 1 << 20
#: Bytes a cell of a map read back holds (:func:`read_nav2`): its map_server cell (int8) ...
CELL_BYTES = 1
#: ... and, for a PNG image, what decoding it whole takes a cell (Pillow's RGBA image and its
#: RGB copy, the channels' sums, the alpha and the lookup keys). A PGM is read a strip of
#: rows at a time, so its pixels are never held whole.
PNG_DECODE_BYTES = 15
#: Image cells read and classified at a time from a PGM (a whole number of rows, at least one).
_READ_STRIP_CELLS = 1 << 22
#: A scale map's free threshold, map_saver's default (its unknown is transparency, not a grey).
SCALE_FREE_THRESH = 0.25
#: map_server's cell values (nav_msgs/OccupancyGrid).
CELL_FREE, CELL_OCCUPIED, CELL_UNKNOWN = 0, 100, -1


@dataclass
class Nav2Map:
    """A map as map_server loads it: ``cells`` ``(rows, cols)`` int8 of 0 free / 100 occupied /
    -1 unknown (``scale`` maps also 1-99 between), row 0 at the bottom (y = origin y), plus the
    YAML's settings. Read with ``decimate=k`` (:func:`read_nav2`), each cell is a ``k`` x ``k``
    block of the image's (``decimation``; ``resolution`` stays the image's own), its largest value."""

    cells: NDArray[np.int8]
    resolution: float
    origin: tuple[float, float, float]
    image: str
    negate: int
    occupied_thresh: float
    free_thresh: float
    mode: str
    decimation: int = 1


def write_nav2(pixels: NDArray[np.uint8] | SpilledCells, resolution: float, origin: tuple[float, float], yaml_path: str | os.PathLike[str],
               *, image_name: str | None = None, overwrite: bool = True) -> tuple[Path, Path]:
    """Write ``pixels`` (``(rows, cols)`` uint8, row 0 at the bottom, y = ``origin[1]``; an
    array or a raster's :class:`~occtool.raster.SpilledCells`) as a Nav2 map.

    Writes the PGM next to the YAML (``image_name``, default the YAML's stem + ``.pgm``),
    each file atomically. Returns the two paths.
    """
    if not isinstance(pixels, SpilledCells):  # read back a strip at a time below, never whole
        pixels = np.asarray(pixels)
    if pixels.ndim != 2 or pixels.size == 0 or pixels.dtype != np.uint8:
        raise InputError(f"a Nav2 map needs a non-empty 2D uint8 image, got {pixels.dtype} {pixels.shape}")
    if not (np.isfinite(resolution) and resolution > 0):
        raise InputError(f"map resolution must be a positive number of metres, got {resolution}")
    yaml_path = Path(yaml_path)
    image_path = yaml_path.with_name(image_name or yaml_path.stem + ".pgm")
    rows, cols = pixels.shape
    header = f"P5\n# occtool fused map\n{cols} {rows}\n255\n".encode("ascii")
    with atomic_write(image_path, "wb", overwrite=overwrite) as handle:
        handle.write(header)
        # PGM's first row is the top of the picture: the map's highest y. Written in strips
        # of rows, so that a large map is never copied whole.
        step = max(1, _STRIP_BYTES // cols)
        for top in range(rows, 0, -step):
            handle.write(np.ascontiguousarray(pixels[max(0, top - step):top][::-1]).tobytes())
    _write_yaml(yaml_path, image_path.name, "trinary", resolution, origin, FREE_THRESH, overwrite)
    return yaml_path, image_path


def _pillow(purpose: str) -> Any:
    try:
        from PIL import Image
    except ImportError:
        raise InputError(f"{purpose} needs Pillow: pip install 'occtool[png]'") from None
    return Image


def write_nav2_scale(occupancy: NDArray[np.floating], resolution: float, origin: tuple[float, float],
                     yaml_path: str | os.PathLike[str], *, image_name: str | None = None,
                     overwrite: bool = True) -> tuple[Path, Path]:
    """Write a graded map (``(rows, cols)`` occupancy in [0, 1], NaN unknown, row 0 at the
    bottom) as a ``scale`` Nav2 map: ``map.yaml`` + an RGBA PNG (``image_name``, default the
    YAML's stem + ``.png``), each file atomically. Returns the two paths."""
    occupancy = np.asarray(occupancy)
    if occupancy.ndim != 2 or occupancy.size == 0 or occupancy.dtype.kind != "f":
        raise InputError(f"a scale Nav2 map needs a non-empty 2D float array, got {occupancy.dtype} {occupancy.shape}")
    rows, cols = occupancy.shape
    # Strips of rows: the temporaries are a strip's, the RGBA image the only whole copy.
    step = max(1, _STRIP_BYTES // cols)
    for low in range(0, rows, step):
        part = occupancy[low:low + step]
        known = np.isfinite(part)
        if ((part[known] < 0) | (part[known] > 1)).any():
            raise InputError("a scale Nav2 map's occupancy must lie in [0, 1] (NaN: unknown)")
    if not (np.isfinite(resolution) and resolution > 0):
        raise InputError(f"map resolution must be a positive number of metres, got {resolution}")
    image_module = _pillow("a scale Nav2 map (PNG)")
    yaml_path = Path(yaml_path)
    image_path = yaml_path.with_name(image_name or yaml_path.stem + ".png")
    rgba = np.empty((rows, cols, 4), dtype=np.uint8)
    for low in range(0, rows, step):
        part = occupancy[low:low + step]
        known = np.isfinite(part)
        # The image's first row is the map's top: this strip's rows land flipped at the bottom end.
        out = rgba[rows - low - part.shape[0]:rows - low][::-1]
        out[..., :3] = np.rint(255.0 * (1.0 - np.where(known, part, 0.5))).astype(np.uint8)[..., None]
        # map_server reads transparency as unknown only in scale mode; map_saver writes 50 % grey there.
        out[..., 3] = np.where(known, 255, 0)
    with atomic_write(image_path, "wb", overwrite=overwrite) as handle:
        image_module.fromarray(rgba, mode="RGBA").save(handle, format="PNG")
    _write_yaml(yaml_path, image_path.name, "scale", resolution, origin, SCALE_FREE_THRESH, overwrite)
    return yaml_path, image_path


def _write_yaml(yaml_path: Path, image: str, mode: str, resolution: float, origin: tuple[float, float],
                free_thresh: float, overwrite: bool) -> None:
    text = (
        f"image: {image}\n"
        f"mode: {mode}\n"
        f"resolution: {float(resolution)!r}\n"
        f"origin: [{float(origin[0])!r}, {float(origin[1])!r}, 0.0]\n"
        f"negate: 0\n"
        f"occupied_thresh: {OCCUPIED_THRESH}\n"
        f"free_thresh: {free_thresh}\n"
    )
    with atomic_write(yaml_path, "w", overwrite=overwrite) as handle:
        handle.write(text)


# --- reading ------------------------------------------------------------------------------
# A map folder is user input: every size and value is checked against the file and its
# range before anything is allocated, and every refusal is one InputError line naming the
# file, the setting and what it must be.

#: Longest map.yaml read: map_server's are a few hundred bytes.
MAX_YAML_BYTES = 64 * 1024
#: Longest PGM header (magic, comments, width, height, maxval).
MAX_PGM_HEADER_BYTES = 64 * 1024
#: Cell sizes read, metres: a micrometre to MAX_DISTANCE (10 km); outside this no map is a robot's.
MIN_RESOLUTION = 1e-6
#: Farthest map coordinate read (origin and far corner), metres: beyond any frame on Earth
#: (UTM northings reach 1e7), far below where a figure's arithmetic loses its digits.
MAX_MAP_COORDINATE = 1e8
#: Cells looked up per step when pixels become cells: bounds the temporary index arrays.
_LOOKUP_CHUNK = 1 << 22
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: The last 12 bytes of every PNG: the empty IEND chunk and its CRC.
_PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"
_NUMBER = re.compile(rb"[0-9]{1,12}")


def _shown(text: str) -> str:
    """A value from the file as a message shows it: quoted, one line, at most 40 characters."""
    return repr(text if len(text) <= 40 else text[:37] + "...")


def _png_size(path: Path) -> tuple[int, int]:
    """A PNG's ``(height, width)`` from its IHDR chunk (bytes 16-24), once its signature is
    checked: a small file can inflate to any size, so the size is judged (:func:`read_nav2`)
    before Pillow sees the file."""
    with open(path, "rb") as handle:
        head = handle.read(24)
    if len(head) < 24 or not head.startswith(_PNG_SIGNATURE) or head[12:16] != b"IHDR":
        raise InputError(f"{path}: not a PNG image (no PNG signature and IHDR header)")
    width, height = struct.unpack(">II", head[16:24])
    if width < 1 or height < 1:
        raise InputError(f"{path}: a {width}x{height} PNG image has no pixels")
    return height, width


def _read_png(path: Path) -> tuple[NDArray[np.uint16], NDArray[np.uint8] | None]:
    """The sum of each pixel's colour channels (0-765; map_server's brightness is their mean)
    and its alpha (``None``: the image has none), of a PNG whose size :func:`read_nav2` has
    judged from its header (:func:`_png_size`)."""
    image_module = _pillow(f"{path}: reading a PNG map image")
    from PIL import PngImagePlugin

    # Pillow decodes a file cut after its last pixel row without complaint: a PNG ends with IEND.
    with open(path, "rb") as handle:
        handle.seek(max(0, path.stat().st_size - len(_PNG_END)))
        if handle.read() != _PNG_END:
            raise InputError(f"{path}: truncated PNG image (it does not end with an IEND chunk)")
    try:
        # The PNG plugin's own class, not Image.open: the image's size was judged against the
        # caller's memory limit already, and Pillow's process-wide bomb limit (a setting
        # occtool leaves alone) would refuse a map occtool writes (the 237 M cells of ten
        # Freiburg campuses).
        with open(path, "rb") as handle, PngImagePlugin.PngImageFile(handle) as image:
            image.load()  # a truncated file fails here (OSError), not half-decoded
            alpha = np.asarray(image.getchannel("A")) if "A" in image.getbands() else None
            colour = np.asarray(image.convert("RGB"))
    except (OSError, ValueError, SyntaxError, image_module.DecompressionBombError) as exc:
        detail = str(exc).splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{path}: not a readable PNG image ({detail})") from None
    return colour.sum(axis=-1, dtype=np.uint16), alpha


def _pgm_header(path: Path) -> tuple[int, int, int, int]:
    """A binary PGM's width, height, maxval and the offset of its first pixel, once its
    header is checked and agrees with the file's length to the byte (a PGM holds every
    pixel it claims, so its size needs no other bound)."""
    size = path.stat().st_size
    with open(path, "rb") as handle:
        head = handle.read(MAX_PGM_HEADER_BYTES)
    tokens: list[bytes] = []
    position = 0
    # Header: magic, width, height, maxval, separated by whitespace, '#' comments to end of line.
    while len(tokens) < 4:
        while position < len(head) and head[position:position + 1].isspace():
            position += 1
        if head[position:position + 1] == b"#":
            end = head.find(b"\n", position)
            if end < 0:
                break
            position = end + 1
            continue
        start = position
        while position < len(head) and not head[position:position + 1].isspace():
            position += 1
        if start == position or position == len(head):
            break  # no token, or one that runs into the end of what was read
        tokens.append(head[start:position])
    if tokens[:1] and tokens[0] != b"P5":
        raise InputError(f"{path}: not a binary PGM (P5) image")
    if len(tokens) < 4:
        raise InputError(f"{path}: truncated PGM header" if len(head) < MAX_PGM_HEADER_BYTES
                         else f"{path}: no PGM header in its first {MAX_PGM_HEADER_BYTES:,} bytes")
    if not all(_NUMBER.fullmatch(token) for token in tokens[1:]):
        raise InputError(f"{path}: malformed PGM header (width, height and maxval must be whole numbers)")
    width, height, maxval = (int(token) for token in tokens[1:])
    if width < 1 or height < 1:
        raise InputError(f"{path}: a {width}x{height} PGM image has no pixels")
    if not 1 <= maxval <= 65535:
        raise InputError(f"{path}: PGM maxval {maxval} is not in [1, 65535]")
    position += 1  # the single whitespace byte after maxval
    sample = 1 if maxval < 256 else 2
    if size - position != width * height * sample:
        raise InputError(f"{path}: the PGM header says {width}x{height} pixels ({width * height * sample:,} bytes) "
                         f"but {size - position:,} bytes follow it (a short or padded file)")
    return width, height, maxval, position


def _pgm_cells(path: Path, width: int, height: int, maxval: int, position: int, table: NDArray[np.int8],
               factor: int) -> NDArray[np.int8]:
    """``table[pixel]`` of every pixel of a PGM (:func:`_pgm_header`'s figures), row 0 at the
    bottom (the image's last row), reduced in ``factor`` x ``factor`` blocks (:func:`decimate_cells`),
    read a strip of rows at a time from the file's end: only the result is held whole."""
    dtype = np.dtype(np.uint8) if maxval < 256 else np.dtype(">u2")
    cells = np.empty((-(-height // factor), -(-width // factor)), dtype=np.int8)
    step = max(1, _READ_STRIP_CELLS // (width * factor)) * factor  # map rows a step, whole blocks
    for low in range(0, height, step):  # map rows, from the bottom: the image's last rows first
        high = min(low + step, height)
        count = (high - low) * width
        pixels = np.fromfile(path, dtype=dtype, count=count, offset=position + (height - high) * width * dtype.itemsize)
        if pixels.size != count:
            raise InputError(f"{path}: the PGM image changed while it was read")
        if maxval not in (255, 65535) and int(pixels.max()) > maxval:
            raise InputError(f"{path}: a pixel value {int(pixels.max())} is above the PGM maxval {maxval}")
        block = decimate_cells(table[pixels.reshape(high - low, width)][::-1], factor)
        cells[low // factor:low // factor + block.shape[0]] = block
    return cells


def _classify(p: NDArray[np.floating], mode: str, occupied: float, free: float) -> NDArray[np.int8]:
    """map_server's cell of each occupancy ``p``: its thresholds, and in ``scale`` mode the grade between."""
    cells = np.full(p.shape, CELL_UNKNOWN, dtype=np.int8)
    cells[p > occupied] = CELL_OCCUPIED
    cells[p < free] = CELL_FREE
    if mode == "scale":
        between = (p >= free) & (p <= occupied)
        cells[between] = np.rint(100.0 * (p[between] - free) / (occupied - free)).astype(np.int8)
    return cells


def _lookup_flipped(table: NDArray[np.int8], keys: NDArray[Any], unknown: NDArray[np.bool_] | None,
                    factor: int = 1) -> NDArray[np.int8]:
    """``table[keys]`` with row 0 at the bottom (``keys``' last row), ``unknown`` cells -1,
    reduced in ``factor`` x ``factor`` blocks (:func:`decimate_cells`).

    A cell depends on its pixel's value only, so a table of every value replaces float
    arrays the image's size; rows go in chunks so that numpy's index arrays stay small."""
    rows, cols = keys.shape
    cells = np.empty((-(-rows // factor), -(-cols // factor)), dtype=np.int8)
    step = max(1, _LOOKUP_CHUNK // (cols * factor)) * factor  # map rows a step, whole blocks
    for low in range(0, rows, step):  # map rows, from the bottom: the image's last rows first
        high = min(low + step, rows)
        block = table[keys[rows - high:rows - low]]
        if unknown is not None:
            block[unknown[rows - high:rows - low]] = CELL_UNKNOWN
        reduced = decimate_cells(block[::-1], factor)
        cells[low // factor:low // factor + reduced.shape[0]] = reduced
    return cells


#: Cells reduced per step by :func:`decimate_cells`: bounds the padded copy of a strip of rows.
_DECIMATE_STRIP_CELLS = 1 << 23


def decimate_cells(cells: NDArray[np.int8], factor: int) -> NDArray[np.int8]:
    """Each ``factor`` x ``factor`` block of map_server ``cells`` (row 0 at the bottom, blocks
    from it) as its largest value.

    In a map's cells (-1 unknown, 0 free, 1-99 graded, 100 occupied) the largest is the
    darkest known cell: a block with one occupied cell is occupied, one with no known cell
    unknown. Edge blocks are padded with unknown, which never wins. The strips of rows
    reduced at once are bounded, so memory stays that of the result.

    Examples
    --------
    >>> cells = np.zeros((4, 5), dtype=np.int8)
    >>> cells[2, 3] = 100
    >>> cells[:, 4] = -1
    >>> decimate_cells(cells, 2).tolist()
    [[0, 0, -1], [0, 100, -1]]
    """
    if factor < 1:
        raise InputError(f"decimation factor must be >= 1, got {factor}")
    if factor == 1:
        return cells
    rows, cols = cells.shape
    out_rows, out_cols = -(-rows // factor), -(-cols // factor)
    reduced = np.empty((out_rows, out_cols), dtype=np.int8)
    strip = max(1, _DECIMATE_STRIP_CELLS // (out_cols * factor * factor))  # output rows per step
    for first in range(0, out_rows, strip):
        block = cells[first * factor:(first + strip) * factor]
        count = -(-len(block) // factor)
        padded = np.full((count * factor, out_cols * factor), CELL_UNKNOWN, dtype=np.int8)
        padded[:len(block), :cols] = block
        reduced[first:first + count] = padded.reshape(count, factor, out_cols, factor).max(axis=(1, 3))
    return reduced


def _read_yaml(path: Path) -> dict[str, str]:
    # map_server's YAML is flat key: value lines; a full YAML parser is not needed for it.
    with open(path, "rb") as handle:
        data = handle.read(MAX_YAML_BYTES + 1)
    if len(data) > MAX_YAML_BYTES:
        raise InputError(f"{path}: longer than {MAX_YAML_BYTES:,} bytes, not a Nav2 map.yaml")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {exc.start}), not a Nav2 map.yaml") from None
    settings: dict[str, str] = {}
    for number, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        key, sep, value = line.partition(":")
        key = key.strip()
        if not sep or not key:
            raise InputError(f"{path}: line {number} {_shown(line)} is not 'key: value'")
        if key in settings:
            raise InputError(f"{path}: line {number}: {key} is set twice")
        settings[key] = value.strip()
    return settings


#: The numbers of map.yaml: (lowest, highest, what they are).
_RANGES = {
    "resolution": (MIN_RESOLUTION, MAX_DISTANCE, "metres per cell"),
    "occupied_thresh": (0.0, 1.0, "occupancy probability"),
    "free_thresh": (0.0, 1.0, "occupancy probability"),
}


def _number(path: Path, settings: dict[str, str], key: str) -> float:
    low, high, unit = _RANGES[key]
    if key not in settings:
        raise InputError(f"{path}: no {key} (map_server needs it)")
    text = settings[key]
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not low <= value <= high:  # NaN fails too
        raise InputError(f"{path}: {key} must be a number in [{low:g}, {high:g}] ({unit}), got {_shown(text)}")
    return value


def _origin(path: Path, settings: dict[str, str]) -> tuple[float, float, float]:
    if "origin" not in settings:
        raise InputError(f"{path}: no origin (map_server needs it: [x, y, yaw])")
    text = settings["origin"]
    parts = text[1:-1].split(",") if text.startswith("[") and text.endswith("]") else []
    try:
        values = tuple(float(part) for part in parts)
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values) \
            or max(abs(values[0]), abs(values[1])) > MAX_MAP_COORDINATE:
        raise InputError(f"{path}: origin must be [x, y, yaw], finite, x and y within "
                         f"{MAX_MAP_COORDINATE:g} m, got {_shown(text)}")
    return values[0], values[1], values[2]


def _settings(path: Path) -> tuple[str, str, float, tuple[float, float, float], int, float, float]:
    """map.yaml's image, mode, resolution, origin, negate and thresholds, each checked."""
    settings = _read_yaml(path)
    image = settings.get("image", "")
    if not image:
        raise InputError(f"{path}: no image (map_server needs the image file's name)")
    mode = settings.get("mode", "trinary")
    if mode not in ("trinary", "scale"):
        raise InputError(f"{path}: mode {_shown(mode)} is not read (trinary or scale)")
    resolution = _number(path, settings, "resolution")
    origin = _origin(path, settings)
    negate_text = settings.get("negate", "0")
    if negate_text not in ("0", "1"):
        raise InputError(f"{path}: negate must be 0 or 1, got {_shown(negate_text)}")
    occupied = _number(path, settings, "occupied_thresh")
    free = _number(path, settings, "free_thresh")
    if not free < occupied:
        raise InputError(f"{path}: free_thresh {free:g} must be below occupied_thresh {occupied:g}")
    return image, mode, resolution, origin, int(negate_text), occupied, free


def _image(yaml_path: Path, image: str) -> tuple[Path, int, int, tuple[int, int, int, int] | None]:
    """The image map.yaml names, its height and width (from its header, checked:
    :func:`_pgm_header`, :func:`_png_size`) and the PGM header's figures (``None`` for a PNG)."""
    image_path = yaml_path.parent / image
    if not image_path.is_file():
        raise InputError(f"{yaml_path}: image {_shown(image)} is not a file ({image_path})")
    if image_path.suffix.lower() == ".png":
        rows, cols = _png_size(image_path)
        return image_path, rows, cols, None
    header = _pgm_header(image_path)
    return image_path, header[1], header[0], header


def read_memory(rows: int, cols: int, *, png: bool = False, decimate: int = 1) -> int:
    """Bytes :func:`read_nav2` holds at most reading a ``rows`` x ``cols`` image (``png``:
    decoded whole; a PGM a strip of rows at a time) into cells reduced ``decimate`` times
    each way: :data:`CELL_BYTES` a cell kept, :data:`PNG_DECODE_BYTES` a PNG's pixel, and
    the strips' temporaries (a few bytes a cell of a strip)."""
    kept = -(-rows // decimate) * -(-cols // decimate) * CELL_BYTES
    strip = min(rows * cols, max(_READ_STRIP_CELLS, cols * decimate)) * 4
    return kept + strip + (rows * cols * PNG_DECODE_BYTES if png else 0)


def nav2_shape(yaml_path: str | os.PathLike[str]) -> tuple[int, int]:
    """The ``(rows, cols)`` of a Nav2 map's image, from map.yaml and the image's header (each
    checked as :func:`read_nav2` checks them), without reading its pixels: how finely to
    read it (``decimate=``) is chosen from it."""
    yaml_path = Path(yaml_path)
    _, rows, cols, _ = _image(yaml_path, _settings(yaml_path)[0])
    return rows, cols


def _size(size: int) -> str:
    return f"{size / 1e9:.1f} GB" if size >= 10**8 else f"{size / 1e6:.0f} MB" if size >= 10**6 else "under 1 MB"


def read_nav2(yaml_path: str | os.PathLike[str], *, decimate: int = 1,
              memory_limit: int | float | str | None = DEFAULT_MEMORY_LIMIT) -> Nav2Map:
    """Load a Nav2 map by map_server's rules (``negate``, thresholds, ``trinary`` or ``scale``;
    a binary PGM of any maxval up to 65535, its samples fractions of maxval, or a PNG with
    Pillow). ``raw`` maps are refused.

    Returns cells with row 0 at the bottom, so cell ``(j, i)`` covers
    ``origin + (i, j) * resolution``; with ``decimate`` k > 1, cell ``(j, i)`` is the block of
    k x k cells from ``origin + k (i, j) * resolution``, its largest value (the darkest known
    cell: :func:`decimate_cells`), and :attr:`Nav2Map.decimation` is k. A PGM is read a strip
    of rows at a time, so a map read decimated holds little more than its blocks.

    The memory the read needs (:func:`read_memory`: a byte a cell kept, a PNG's decoding)
    is judged from the image's header before any pixel is read: over ``memory_limit``
    (bytes, or a size such as ``"8G"``; ``None``: no limit) the map is refused in one line.

    Raises
    ------
    InputError
        One line naming the file and what is wrong: a setting missing or out of map_server's
        range (``resolution`` > 0, ``origin`` ``[x, y, yaw]`` finite, ``negate`` 0 or 1,
        ``0 <= free_thresh < occupied_thresh <= 1``), an image that needs more than
        ``memory_limit`` to read, or a PGM whose header and length disagree.
    """
    if isinstance(decimate, bool) or not isinstance(decimate, (int, np.integer)) or decimate < 1:
        raise InputError(f"decimate must be a whole number >= 1, got {decimate!r}")
    decimate = int(decimate)
    limit = memory_bytes(memory_limit)
    yaml_path = Path(yaml_path)
    image, mode, resolution, origin, negate, occupied, free = _settings(yaml_path)
    image_path, rows, cols, pgm = _image(yaml_path, image)
    need = read_memory(rows, cols, png=pgm is None, decimate=decimate)
    if limit is not None and need > limit:
        wanted = max(1, -(-need // 10**9))  # whole gigabytes, rounded up
        raise InputError(f"{image_path}: a {cols}x{rows} map image needs about {_size(need)} of memory to read, "
                         f"over the limit of {_size(limit)}: raise it with memory_limit='{wanted}G'")
    corner = (origin[0] + cols * resolution, origin[1] + rows * resolution)
    if max(abs(corner[0]), abs(corner[1])) > MAX_MAP_COORDINATE:
        raise InputError(f"{yaml_path}: the map's far corner ({corner[0]:g}, {corner[1]:g}) lies beyond "
                         f"{MAX_MAP_COORDINATE:g} m (check resolution and origin)")
    if pgm is None:
        brightness, alpha = _read_png(image_path)
        # Every (channel sum, alpha) pair through the arithmetic map_server's rules take.
        shade = np.arange(766, dtype=np.uint16).astype(np.float32) / np.float32(3.0)
        keys: NDArray[Any] = brightness
        unknown = None
        if mode == "trinary" and alpha is not None:
            # map_server averages the alpha in with the colours in trinary mode.
            shade = (3.0 * shade[:, None] + np.arange(256, dtype=np.uint8)[None, :]) / np.float32(4.0)
            keys = brightness.astype(np.uint32) * np.uint32(256) + alpha
        elif mode == "scale" and alpha is not None:
            unknown = alpha < 255
        shade = shade.ravel()
        p = shade / 255.0 if negate else (255.0 - shade) / 255.0
        cells = _lookup_flipped(_classify(p, mode, occupied, free), keys, unknown, decimate)
    else:
        width, height, maxval, position = pgm
        shade = np.arange(256 if maxval < 256 else 65536, dtype=np.float64)
        if maxval != 255:
            shade *= 255.0 / maxval  # PGM samples are fractions of maxval
        p = shade / 255.0 if negate else (255.0 - shade) / 255.0
        cells = _pgm_cells(image_path, width, height, maxval, position, _classify(p, mode, occupied, free), decimate)
    return Nav2Map(cells, resolution, origin, image, negate, occupied, free, mode, decimate)


__all__ = ["FREE_THRESH", "OCCUPIED_THRESH", "SCALE_FREE_THRESH", "Nav2Map", "decimate_cells", "nav2_shape",
           "read_memory", "read_nav2", "write_nav2", "write_nav2_scale"]
