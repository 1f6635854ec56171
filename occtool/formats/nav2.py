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

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool._files import atomic_write
from occtool.errors import InputError

OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196
#: Map images larger than this many cells are refused before they are decoded.
MAX_IMAGE_CELLS = 50_000_000
#: A scale map's free threshold, map_saver's default (its unknown is transparency, not a grey).
SCALE_FREE_THRESH = 0.25
#: map_server's cell values (nav_msgs/OccupancyGrid).
CELL_FREE, CELL_OCCUPIED, CELL_UNKNOWN = 0, 100, -1


@dataclass
class Nav2Map:
    """A map as map_server loads it: ``cells`` ``(rows, cols)`` int8 of 0 free / 100 occupied /
    -1 unknown (``scale`` maps also 1-99 between), row 0 at the bottom (y = origin y), plus the
    YAML's settings."""

    cells: NDArray[np.int8]
    resolution: float
    origin: tuple[float, float, float]
    image: str
    negate: int
    occupied_thresh: float
    free_thresh: float
    mode: str


def write_nav2(pixels: NDArray[np.uint8], resolution: float, origin: tuple[float, float], yaml_path: str | os.PathLike[str],
               *, image_name: str | None = None, overwrite: bool = True) -> tuple[Path, Path]:
    """Write ``pixels`` (``(rows, cols)`` uint8, row 0 at the bottom, y = ``origin[1]``) as a Nav2 map.

    Writes the PGM next to the YAML (``image_name``, default the YAML's stem + ``.pgm``),
    each file atomically. Returns the two paths.
    """
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
        # PGM's first row is the top of the picture: the map's highest y.
        handle.write(np.ascontiguousarray(pixels[::-1]).tobytes())
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
    known = np.isfinite(occupancy)
    if ((occupancy[known] < 0) | (occupancy[known] > 1)).any():
        raise InputError("a scale Nav2 map's occupancy must lie in [0, 1] (NaN: unknown)")
    if not (np.isfinite(resolution) and resolution > 0):
        raise InputError(f"map resolution must be a positive number of metres, got {resolution}")
    image_module = _pillow("a scale Nav2 map (PNG)")
    yaml_path = Path(yaml_path)
    image_path = yaml_path.with_name(image_name or yaml_path.stem + ".png")
    grey = np.rint(255.0 * (1.0 - np.where(known, occupancy, 0.5))).astype(np.uint8)
    # map_server reads transparency as unknown only in scale mode; map_saver writes 50 % grey there.
    rgba = np.stack([grey, grey, grey, np.where(known, 255, 0).astype(np.uint8)], axis=-1)[::-1]
    with atomic_write(image_path, "wb", overwrite=overwrite) as handle:
        image_module.fromarray(np.ascontiguousarray(rgba), mode="RGBA").save(handle, format="PNG")
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


def _read_png(path: Path) -> tuple[NDArray[np.float32], NDArray[np.uint8] | None]:
    """map_server's brightness of each pixel (the mean of its colour channels, 0-255) and
    its alpha (``None``: the image has none)."""
    image_module = _pillow(f"{path}: reading a PNG map image")
    try:
        with image_module.open(path) as image:
            # A PNG's size is in its header and a small file can inflate to any size: refuse first.
            if image.width * image.height > MAX_IMAGE_CELLS:
                raise InputError(f"{path}: a {image.width}x{image.height} map image is over "
                                 f"{MAX_IMAGE_CELLS:,} cells")
            image.load()
            alpha = np.asarray(image.getchannel("A")) if "A" in image.getbands() else None
            colour = np.asarray(image.convert("RGB"))
    except (OSError, ValueError, SyntaxError, image_module.DecompressionBombError) as exc:
        raise InputError(f"{path}: not a readable PNG image ({exc})") from None
    return colour.sum(axis=-1, dtype=np.uint16).astype(np.float32) / np.float32(3.0), alpha


def _read_pgm(path: Path) -> NDArray[np.uint8]:
    data = path.read_bytes()
    tokens: list[bytes] = []
    position = 0
    # Header: magic, width, height, maxval, separated by whitespace, '#' comments to end of line.
    while len(tokens) < 4:
        while position < len(data) and data[position:position + 1].isspace():
            position += 1
        if data[position:position + 1] == b"#":
            end = data.find(b"\n", position)
            if end < 0:
                raise InputError(f"{path}: truncated PGM header")
            position = end + 1
            continue
        start = position
        while position < len(data) and not data[position:position + 1].isspace():
            position += 1
        if start == position:
            raise InputError(f"{path}: truncated PGM header")
        tokens.append(data[start:position])
    position += 1
    if tokens[0] != b"P5":
        raise InputError(f"{path}: not a binary PGM (P5) image")
    try:
        width, height, maxval = (int(t) for t in tokens[1:])
    except ValueError:
        raise InputError(f"{path}: malformed PGM header") from None
    if maxval != 255 or width <= 0 or height <= 0:
        raise InputError(f"{path}: only 8-bit PGM images are read, got maxval {maxval}")
    body = np.frombuffer(data, dtype=np.uint8, count=width * height, offset=position) \
        if len(data) - position >= width * height else None
    if body is None:
        raise InputError(f"{path}: the PGM image is shorter than {width}x{height}")
    return body.reshape(height, width)


def _parse_yaml(path: Path) -> dict[str, str]:
    # map_server's YAML is flat key: value lines; a full YAML parser is not needed for it.
    settings: dict[str, str] = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        key, sep, value = line.partition(":")
        if not sep:
            raise InputError(f"{path}: line {line!r} is not 'key: value'")
        settings[key.strip()] = value.strip()
    return settings


def read_nav2(yaml_path: str | os.PathLike[str]) -> Nav2Map:
    """Load a Nav2 map by map_server's rules (``negate``, thresholds, ``trinary`` or ``scale``;
    a PGM, or a PNG with Pillow).

    Returns cells with row 0 at the bottom, so cell ``(j, i)`` covers
    ``origin + (i, j) * resolution``.
    """
    yaml_path = Path(yaml_path)
    settings = _parse_yaml(yaml_path)
    try:
        image = settings["image"]
        resolution = float(settings["resolution"])
        origin = tuple(float(v) for v in settings["origin"].strip("[]").split(","))
        negate = int(settings.get("negate", "0"))
        occupied = float(settings["occupied_thresh"])
        free = float(settings["free_thresh"])
    except (KeyError, ValueError) as exc:
        raise InputError(f"{yaml_path}: missing or malformed map setting ({exc})") from None
    mode = settings.get("mode", "trinary")
    if len(origin) != 3:
        raise InputError(f"{yaml_path}: origin must be [x, y, yaw]")
    if mode not in ("trinary", "scale"):
        raise InputError(f"{yaml_path}: mode {mode!r} is not read (trinary or scale)")
    image_path = yaml_path.with_name(image) if not os.path.isabs(image) else Path(image)
    alpha = None
    if image_path.suffix.lower() == ".png":
        shade, alpha = _read_png(image_path)
        if mode == "trinary" and alpha is not None:
            # map_server averages the alpha in with the colours in trinary mode.
            shade = (3.0 * shade + alpha) / np.float32(4.0)
    else:
        shade = _read_pgm(image_path).astype(np.float64)
    p = shade / 255.0 if negate else (255.0 - shade) / 255.0
    cells = np.full(shade.shape, CELL_UNKNOWN, dtype=np.int8)
    cells[p > occupied] = CELL_OCCUPIED
    cells[p < free] = CELL_FREE
    if mode == "scale":
        between = (p >= free) & (p <= occupied)
        cells[between] = np.rint(100.0 * (p[between] - free) / (occupied - free)).astype(np.int8)
        if alpha is not None:
            cells[alpha < 255] = CELL_UNKNOWN
    return Nav2Map(cells[::-1].copy(), resolution, origin, image, negate, occupied, free, mode)


__all__ = ["FREE_THRESH", "OCCUPIED_THRESH", "SCALE_FREE_THRESH", "Nav2Map", "read_nav2", "write_nav2",
           "write_nav2_scale"]
