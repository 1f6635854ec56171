"""Issue 23: damaged or hostile depth input (truncated or flipped PNGs, odd intrinsics and
pose files, depth messages with wrong sizes) is an InputError, and one line on the command
line, never a traceback."""

from __future__ import annotations

import shutil
import traceback
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.io import read_log
from occtool.io.depth import PinholeCamera, back_project

FIXTURE = Path(__file__).resolve().parent.parent / "fixtures" / "depth-office"
FUZZ = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def two_frames(tmp_path_factory) -> Path:
    """The fixture's first two frames as a 3DMatch folder, small enough to read many times."""
    from PIL import Image

    folder = tmp_path_factory.mktemp("frames")
    sequence = folder / "seq-01"
    sequence.mkdir()
    listed = [line.split()[1] for line in (FIXTURE / "depth.txt").read_text().splitlines()
              if line and not line.startswith("#")][:2]
    for i, name in enumerate(listed):
        tum = np.asarray(Image.open(FIXTURE / name)).astype(np.float64) / 5.0  # TUM's x5000 to millimetres
        Image.fromarray(tum.astype(np.uint16)).save(sequence / f"frame-{i:06d}.depth.png")
        np.savetxt(sequence / f"frame-{i:06d}.pose.txt", np.eye(4))
    shutil.copy(FIXTURE / "camera-intrinsics.txt", folder / "camera-intrinsics.txt")
    return folder


def _copy(folder: Path, tmp_path_factory) -> Path:
    target = tmp_path_factory.mktemp("copy") / "frames"
    shutil.copytree(folder, target)
    return target


def _read_or_refuse(path: Path) -> None:
    try:
        read_log(path, depth_features=200)
    except InputError as exc:
        assert "\n" not in str(exc)


@FUZZ
@given(cut=st.floats(0.0, 1.0, exclude_max=True), flip=st.booleans(), where=st.floats(0.0, 1.0, exclude_max=True),
       bit=st.integers(0, 7))
def test_a_damaged_depth_png_is_read_or_refused_as_input(tmp_path_factory, two_frames, cut, flip, where, bit):
    folder = _copy(two_frames, tmp_path_factory)
    png = folder / "seq-01" / "frame-000001.depth.png"
    data = bytearray(png.read_bytes())
    if flip:
        data[int(where * len(data))] ^= 1 << bit
    else:
        data = data[: int(cut * len(data))]
    png.write_bytes(bytes(data))
    _read_or_refuse(folder)


@FUZZ
@given(text=st.text(st.sampled_from("0123456789 .-e\nnaif"), max_size=80))
def test_any_intrinsics_or_pose_text_is_read_or_refused_as_input(tmp_path_factory, two_frames, text):
    folder = _copy(two_frames, tmp_path_factory)
    (folder / "camera-intrinsics.txt").write_text(text)
    _read_or_refuse(folder)
    folder = _copy(two_frames, tmp_path_factory)
    (folder / "seq-01" / "frame-000000.pose.txt").write_text(text)
    _read_or_refuse(folder)


@settings(max_examples=40, deadline=None)
@given(shape=st.tuples(st.integers(1, 30), st.integers(1, 30)),
       values=st.sampled_from([0.0, 1.0, np.nan, np.inf, -np.inf, 1e30, -3.0]),
       fx=st.floats(allow_nan=True, allow_infinity=True), no_return=st.sampled_from([None, 2.0]))
def test_back_projection_takes_any_frame_or_refuses_it(shape, values, fx, no_return):
    try:
        camera = PinholeCamera(20, 10, fx, 50.0, 10.0, 5.0)
    except InputError:
        return
    image = np.full(shape, values)
    try:
        points, evidence = back_project(image, camera, no_return_range=no_return)
    except InputError as exc:
        assert "does not match" in str(exc)
        return
    assert np.isfinite(points).all() and ((evidence >= 0) & (evidence <= 1)).all()


def test_the_command_line_says_so_in_one_line(tmp_path, two_frames):
    folder = tmp_path / "frames"
    shutil.copytree(two_frames, folder)
    png = folder / "seq-01" / "frame-000001.depth.png"
    png.write_bytes(png.read_bytes()[:100])
    result = CliRunner().invoke(cli, ["fit", str(folder / "camera-intrinsics.txt"), "-o", str(tmp_path / "m.json")])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError("".join(traceback.format_exception(*result.exc_info)))
    assert result.exit_code != 0
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and "not a readable depth image" in errors[0], result.output
    assert "--skip-invalid" in errors[0]


def test_a_32fc1_compressed_depth_image_decodes_image_transports_inverse_depth() -> None:
    import io
    import struct
    from types import SimpleNamespace

    from PIL import Image

    from occtool.io.mcap._depth import _compressed_depth

    z0, depth_max = 100.0, 10.0  # compressed_depth_image_transport's defaults
    quant_a = z0 * (z0 + 1.0)
    quant_b = 1.0 - quant_a / depth_max
    depth = np.linspace(0.5, 6.0, 48 * 64).reshape(48, 64)
    depth[0, :5] = np.nan
    inverse = np.where(np.isfinite(depth), quant_a / depth + quant_b, 0.0).round().astype(np.uint16)
    buffer = io.BytesIO()
    Image.fromarray(inverse).save(buffer, format="PNG")
    message = SimpleNamespace(format="32FC1; compressedDepth png",
                              data=struct.pack("<iff", 0, quant_a, quant_b) + buffer.getvalue())
    decoded, scale = _compressed_depth(message, "test")
    assert scale == 1.0 and np.isnan(decoded[0, :5]).all()
    np.testing.assert_allclose(decoded[1:], depth[1:], rtol=0.02)
    with pytest.raises(InputError, match="not compressedDepth"):
        _compressed_depth(SimpleNamespace(format="jpeg", data=b""), "test")
    with pytest.raises(InputError, match="cannot be decoded"):
        _compressed_depth(SimpleNamespace(format="16UC1; compressedDepth png", data=b"\0" * 40), "test")


@settings(max_examples=60, deadline=None)
@given(width=st.integers(-2, 40), height=st.integers(-2, 40), step=st.integers(0, 100),
       size=st.integers(0, 4000), encoding=st.sampled_from(["16UC1", "mono16", "32FC1", "rgb8", "", "8UC1"]),
       big=st.booleans())
def test_any_image_message_layout_is_read_or_refused_as_input(width, height, step, size, encoding, big):
    from types import SimpleNamespace

    from occtool.io.mcap._channels import DEPTH_IMAGE
    from occtool.io.mcap._depth import DepthSettings, decode_depth

    settings_ = DepthSettings()
    settings_.cameras["cam"] = PinholeCamera(8, 6, 10.0, 10.0, 4.0, 3.0)
    message = SimpleNamespace(header=SimpleNamespace(frame_id="cam", stamp=None), width=width, height=height,
                              step=step, encoding=encoding, is_bigendian=big,
                              data=bytes(np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8)))
    try:
        points, evidence, frame, _ = decode_depth(DEPTH_IMAGE, message, settings_, None, "test")
    except InputError as exc:
        assert "\n" not in str(exc)
        return
    assert frame == "cam" and np.isfinite(points).all() and ((evidence > 0) & (evidence <= 1)).all()


def test_without_pillow_the_error_names_the_extra(monkeypatch, two_frames) -> None:
    import sys

    from occtool.errors import MissingDependencyError

    monkeypatch.setitem(sys.modules, "PIL", None)
    with pytest.raises(MissingDependencyError, match=r"occtool\[depth\]"):
        read_log(two_frames)
