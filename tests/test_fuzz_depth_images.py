"""Issue 37, item 4: depth images are checked before they are decoded.

Crafted PNGs (every chunk's CRC valid, so only the checks can refuse them): a header that
claims 20000x20000 or 13000x13000 pixels is refused from its IHDR, before Pillow sees a
byte; a PNG whose image data holds 10 of its 120 rows, or whose IEND is missing, is
refused, not read with zero depth; raw image data must be exactly height x step bytes; a
``camera-intrinsics.txt`` must be a pinhole K and is no log on its own. Every refusal is
an :class:`InputError` (one line on the command line), never a traceback.
"""

from __future__ import annotations

import io
import shutil
import struct
import traceback
import zlib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.io import read_log
from occtool.io.depth import MAX_IMAGE_PIXELS, check_png, decode_png
from occtool.io.depth_folders import read_depth_png
from occtool.io.mcap._depth import _compressed_depth, _raw_array

pytest.importorskip("PIL")

FIXTURE = Path(__file__).resolve().parent.parent / "fixtures" / "depth-office"
FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)


def png(width: int, height: int, rows: bytes | None = None, *, bit_depth: int = 16, colour: int = 0,
        end: bool = True, extra: bytes = b"") -> bytes:
    """A CRC-valid PNG whose header says ``width`` x ``height`` and whose IDAT inflates to ``rows``
    (default: all rows of zeros, each with filter byte 0)."""
    if rows is None:
        rows = bytes((1 + width * bit_depth // 8) * height)
    header = struct.pack(">IIBBBBB", width, height, bit_depth, colour, 0, 0, 0)
    out = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows + extra))
    return out + (chunk(b"IEND", b"") if end else b"")


def real_png(width: int = 16, height: int = 120) -> tuple[bytes, np.ndarray]:
    from PIL import Image

    values = (np.arange(width * height, dtype=np.uint16) + 1).reshape(height, width)
    buffer = io.BytesIO()
    Image.fromarray(values).save(buffer, format="PNG")
    return buffer.getvalue(), values


def compressed(data: bytes) -> SimpleNamespace:
    return SimpleNamespace(format="16UC1; compressedDepth png", data=struct.pack("<iff", 0, 0.0, 0.0) + data)


@pytest.fixture
def pillow_never_opens(monkeypatch):
    """Fail the test if Pillow is asked to open anything: the refusal must come first."""
    from PIL import Image

    def refuse(*args, **kwargs):
        raise AssertionError("Pillow was asked to decode an image the header check should have refused")

    monkeypatch.setattr(Image, "open", refuse)


@pytest.mark.parametrize("side", [20_000, 13_000, 4097 * 2])
def test_a_huge_header_is_refused_before_decoding(side, pillow_never_opens, tmp_path):
    data = png(side, side, rows=b"\x00")  # the header alone claims the size
    with pytest.raises(InputError, match=f"{side}x{side} pixels"):
        _compressed_depth(compressed(data), "/camera/depth, message 3")
    path = tmp_path / "huge.png"
    path.write_bytes(data)
    with pytest.raises(InputError, match=f"{path} is not a readable depth image: a depth image of {side}x{side}"):
        read_depth_png(path)


def test_pillows_global_limit_is_left_alone():
    from PIL import Image

    before = Image.MAX_IMAGE_PIXELS
    with pytest.raises(InputError):
        check_png(png(20_000, 20_000, rows=b"\x00"), "x")
    assert Image.MAX_IMAGE_PIXELS == before and MAX_IMAGE_PIXELS < before


def test_a_png_with_10_of_its_120_rows_is_refused_not_read_as_zero_depth(tmp_path):
    whole, values = real_png(16, 120)
    np.testing.assert_array_equal(decode_png(whole, "whole"), values)
    row = 1 + 16 * 2
    short = png(16, 120, rows=bytes(row * 10))
    with pytest.raises(InputError, match="ends early .* 120 rows"):
        _compressed_depth(compressed(short), "/camera/depth, message 7")
    path = tmp_path / "short.png"
    path.write_bytes(short)
    with pytest.raises(InputError, match="short.png is not a readable depth image: .*ends early"):
        read_depth_png(path)


@pytest.mark.parametrize("damage", ["no IEND", "cut", "extra rows", "not a PNG", "no IHDR"])
def test_damaged_pngs_are_refused(damage):
    whole, _ = real_png()
    data = {
        "no IEND": whole[:-12],
        "cut": whole[: len(whole) // 2],
        "extra rows": png(16, 120, extra=bytes(33 * 5)),
        "not a PNG": b"GIF89a" + whole[6:],
        "no IHDR": whole[:8] + chunk(b"tEXt", b"a\x00b") + whole[8:],
    }[damage]
    with pytest.raises(InputError):
        check_png(data, "frame")


def test_an_interlaced_png_is_checked_by_its_seven_passes():
    values = (np.arange(37 * 23, dtype=np.uint16) * 7).reshape(23, 37)
    # Pillow writes no interlaced PNG: build one from the 16-bit rows of each Adam7 pass.
    passes = ((0, 0, 8, 8), (0, 4, 8, 8), (4, 0, 8, 4), (0, 2, 4, 4), (2, 0, 4, 2), (0, 1, 2, 2), (1, 0, 2, 1))
    raw = b""
    for r0, c0, dr, dc in passes:
        sub = values[r0::dr, c0::dc]
        if sub.size:
            raw += b"".join(b"\x00" + row.astype(">u2").tobytes() for row in sub)
    header = struct.pack(">IIBBBBB", 37, 23, 16, 0, 0, 0, 1)
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
    assert check_png(data, "x") == (37, 23)
    np.testing.assert_array_equal(decode_png(data, "x"), values)
    with pytest.raises(InputError, match="ends early"):
        check_png(data.replace(chunk(b"IDAT", zlib.compress(raw)), chunk(b"IDAT", zlib.compress(raw[:-10]))), "x")


@FUZZ
@given(cut=st.integers(min_value=0, max_value=2000), flip=st.integers(min_value=0, max_value=2000),
       bit=st.integers(min_value=0, max_value=7), fix_crc=st.booleans())
def test_truncated_or_flipped_pngs_are_read_whole_or_refused(cut, flip, bit, fix_crc):
    whole, values = real_png()
    data = bytearray(whole)
    if flip < len(data):
        data[flip] ^= 1 << bit
    if fix_crc:  # recompute every chunk's CRC: only the structural checks stand in the way
        offset = 8
        while offset + 12 <= len(data):
            length = struct.unpack(">I", data[offset:offset + 4])[0]
            if offset + 12 + length > len(data):
                break
            body = bytes(data[offset + 4: offset + 8 + length])
            data[offset + 8 + length: offset + 12 + length] = struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
            offset += 12 + length
    data = bytes(data[: len(data) - cut]) if cut else bytes(data)
    try:
        decoded, scale = _compressed_depth(compressed(data), "msg")
    except InputError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("msg: ")
        return
    # Read: then all of it, the header's size, never rows made up.
    assert decoded.shape[0] * decoded.shape[1] <= MAX_IMAGE_PIXELS
    if data == whole:
        np.testing.assert_array_equal(decoded, values)


@pytest.mark.parametrize("extra", [-1, 1, 480])
def test_raw_image_data_must_be_exactly_height_times_step(extra):
    height, width, step = 4, 3, 8
    good = bytes(height * step)
    image, _ = _raw_array(good, "16UC1", height, width, step, False, "msg 1")
    assert image.shape == (4, 3)
    with pytest.raises(InputError, match=f"msg 1: {height * step + extra} data bytes where 4 rows of step 8"):
        _raw_array(bytes(height * step + extra), "16UC1", height, width, step, False, "msg 1")


@FUZZ
@given(height=st.integers(-2, 70_000), width=st.integers(-2, 70_000), step=st.integers(0, 2**31),
       size=st.integers(0, 4096))
def test_raw_image_headers_are_checked_before_any_allocation(height, width, step, size):
    try:
        image, _ = _raw_array(bytes(size), "16UC1", height, width, step, False, "msg")
    except InputError as exc:
        assert "\n" not in str(exc)
        return
    assert image.shape == (height, width) and size == height * (step or 2 * width)


def _tum(tmp_path: Path) -> Path:
    folder = tmp_path / "rgbd_dataset_freiburg3_test"
    shutil.copytree(FIXTURE, folder)
    return folder


@pytest.mark.parametrize("k", [
    "1 0 0\n0 1 0\n0 0 1\n1 1 1\n",          # not 3x3
    "525 0 319.5\n0 525 239.5\n1 0 1\n",    # last row
    "525 3 319.5\n0 525 239.5\n0 0 1\n",    # skew
    "-525 0 319.5\n0 525 239.5\n0 0 1\n",   # fx < 0
    "525 0 319.5\n0 0 239.5\n0 0 1\n",      # fy = 0
    "525 0 nan\n0 525 239.5\n0 0 1\n",      # NaN
])
def test_a_tum_camera_intrinsics_that_is_no_pinhole_is_refused(tmp_path, k):
    folder = _tum(tmp_path)
    (folder / "camera-intrinsics.txt").write_text(k)
    with pytest.raises(InputError, match="camera-intrinsics.txt"):
        read_log(folder)


def test_camera_intrinsics_alone_is_no_log(tmp_path):
    lone = tmp_path / "camera-intrinsics.txt"
    lone.write_text("525 0 319.5\n0 525 239.5\n0 0 1\n")
    with pytest.raises(InputError, match="give the folder of depth frames, or a TUM folder's depth.txt"):
        read_log(lone)
    result = CliRunner().invoke(cli, ["map", str(lone), "-o", str(tmp_path / "out")])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError("".join(traceback.format_exception(*result.exc_info)))
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert result.exit_code != 0 and len(errors) == 1 and "depth.txt" in errors[0], result.output
    assert not (tmp_path / "out").exists()


def test_a_tum_folders_camera_intrinsics_reads_the_folder(tmp_path):
    folder = _tum(tmp_path)
    if not (folder / "camera-intrinsics.txt").is_file():
        pytest.skip("the fixture has no camera-intrinsics.txt")
    assert len(read_log(folder / "camera-intrinsics.txt").positions) == len(read_log(folder).positions)
