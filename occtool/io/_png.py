"""Depth images as PNG, checked from their header before a byte is decompressed: the size
against :data:`MAX_IMAGE_PIXELS`, the chunks to IEND, the rows the header announces
(:func:`check_png`), then decoded with Pillow (:func:`decode_png`). Pillow's own limit
(``MAX_IMAGE_PIXELS``, a global) is never touched."""

from __future__ import annotations

import struct

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError

#: Largest image side accepted, pixels.
MAX_IMAGE_SIDE = 16_384


#: Most pixels of a depth image decoded: 4096 x 4096 (64 MB as 32-bit depth), far above any
#: depth camera's (a ZED's 2K is 2208 x 1242); a larger one is refused from its header,
#: before a byte is decompressed.
MAX_IMAGE_PIXELS = 4096 * 4096

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: Channels of each PNG colour type.
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
#: Adam7 interlacing passes: (first row, first column, row step, column step).
_ADAM7 = ((0, 0, 8, 8), (0, 4, 8, 8), (4, 0, 8, 4), (0, 2, 4, 4), (2, 0, 4, 2), (0, 1, 2, 2), (1, 0, 2, 1))


def check_image_size(width: int, height: int, where: str) -> None:
    """Refuse an image size that is not one of a depth camera (each side in [1, :data:`MAX_IMAGE_SIDE`],
    at most :data:`MAX_IMAGE_PIXELS` pixels), before anything is allocated for it."""
    if not (1 <= width <= MAX_IMAGE_SIDE and 1 <= height <= MAX_IMAGE_SIDE) or width * height > MAX_IMAGE_PIXELS:
        raise InputError(f"{where}: a depth image of {width}x{height} pixels; at most {MAX_IMAGE_SIDE} pixels a "
                         f"side and {MAX_IMAGE_PIXELS:,} in all are read")


def _png_row_bytes(width: int, bits: int) -> int:
    return 1 + (width * bits + 7) // 8  # a filter byte, then the packed pixels


def check_png(data: bytes, where: str) -> tuple[int, int]:
    """Check a PNG before it is decoded; return its ``(width, height)``.

    The size is read from the IHDR header and checked (:func:`check_image_size`); the chunks
    must run to IEND; the image data must inflate to exactly the rows the header announces
    (a stream that ends early would be decoded with its missing rows as zero depth, which
    is no measurement and no obstacle). The inflating is bounded by that size.

    Raises
    ------
    InputError
        Naming ``where`` and what is wrong.
    """
    import zlib

    if len(data) < 33 or data[:8] != _PNG_SIGNATURE:
        raise InputError(f"{where}: not a PNG image (no PNG signature)")
    length, kind = struct.unpack(">I4s", data[8:16])
    if kind != b"IHDR" or length != 13:
        raise InputError(f"{where}: a PNG without its IHDR header first")
    width, height, bit_depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", data[16:29])
    check_image_size(width, height, where)
    if colour not in _PNG_CHANNELS or bit_depth not in (1, 2, 4, 8, 16) or interlace not in (0, 1):
        raise InputError(f"{where}: a PNG header of colour type {colour}, bit depth {bit_depth}, "
                         f"interlace {interlace}, which PNG does not define")
    bits = bit_depth * _PNG_CHANNELS[colour]
    if interlace:
        expected = 0
        for row0, col0, row_step, col_step in _ADAM7:
            rows = (height - row0 + row_step - 1) // row_step if height > row0 else 0
            cols = (width - col0 + col_step - 1) // col_step if width > col0 else 0
            if rows and cols:
                expected += rows * _png_row_bytes(cols, bits)
    else:
        expected = height * _png_row_bytes(width, bits)
    # Walk the chunks: IDAT's pieces gathered, IEND required (a cut file has none).
    inflate = zlib.decompressobj()
    produced = 0
    offset, ended = 33, False
    try:
        while offset + 12 <= len(data):
            length, kind = struct.unpack(">I4s", data[offset:offset + 8])
            body = data[offset + 8: offset + 8 + length]
            if len(body) != length or offset + 12 + length > len(data):
                break
            if kind == b"IDAT" and not inflate.eof:
                # Bounded: never more than one byte beyond the announced rows is inflated.
                produced += len(inflate.decompress(body, expected + 1 - produced))
                if produced > expected:
                    raise InputError(f"{where}: the PNG's image data holds more than the {height} rows its "
                                     "header announces")
            offset += 12 + length
            if kind == b"IEND":
                ended = True
                break
    except zlib.error as exc:
        raise InputError(f"{where}: the PNG's image data is corrupt ({exc})") from None
    if not ended:
        raise InputError(f"{where}: the PNG is cut short (no IEND chunk): a truncated file")
    if produced < expected or not inflate.eof:
        raise InputError(f"{where}: the PNG's image data ends early ({produced:,} of {expected:,} bytes of its "
                         f"{height} rows): a truncated image")
    return width, height


def decode_png(data: bytes, where: str) -> NDArray[np.generic]:
    """A checked (:func:`check_png`) single-channel PNG as an array, through Pillow.

    Raises
    ------
    MissingDependencyError
        Without Pillow (the ``depth`` extra).
    InputError
        For a PNG that :func:`check_png` refuses or Pillow cannot decode.
    """
    check_png(data, where)
    try:
        from PIL import Image
    except ImportError:
        from occtool.errors import MissingDependencyError

        raise MissingDependencyError("Pillow", "depth", f"decoding {where}") from None
    import io

    try:
        with Image.open(io.BytesIO(data), formats=("PNG",)) as image:
            image.load()
            if image.mode not in ("I;16", "I;16B", "I;16L", "I", "F"):
                raise InputError(f"{where}: a depth image must be one 16-bit (or 32-bit) greyscale channel, "
                                 f"got Pillow mode {image.mode!r}")
            return np.asarray(image)
    except (OSError, SyntaxError, ValueError) as exc:  # InputError is a ValueError: pass it on
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{where}: Pillow cannot decode it (truncated or corrupt: {exc})") from None


__all__ = ["MAX_IMAGE_PIXELS", "MAX_IMAGE_SIDE", "check_image_size", "check_png", "decode_png"]
