"""Loading matplotlib, making headless figures, and writing them to PNG, SVG or PDF; the shared style."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError, MissingDependencyError

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure



FloatArray = NDArray[np.float64]


#: Output formats :func:`save_figure` writes, keyed by file extension.
SUPPORTED_FORMATS: dict[str, str] = {".png": "png", ".svg": "svg", ".pdf": "pdf"}


#: Default figure size in inches (width, height) and resolution.
DEFAULT_SIZE: tuple[float, float] = (7.0, 6.0)


DEFAULT_DPI: float = 100.0


# Colours kept consistent across every picture so a reader learns them once.
NAVIGATION_COLOUR = "tab:green"


OBSTACLE_COLOUR = "tab:red"


EXPLORATION_COLOUR = "tab:blue"


ROBOT_COLOUR = "tab:orange"


TRUTH_COLOUR = "0.6"  # visible on the dark feature background and on white


MODEL_COLOURS = {"parametric": "tab:green", "grid": "tab:purple", "octomap": "tab:brown"}


def require_matplotlib() -> Any:
    """Import matplotlib, or explain how to install it.

    Returns
    -------
    module
        The :mod:`matplotlib` module.

    Raises
    ------
    MissingDependencyError
        If matplotlib is not installed.
    """
    try:
        import matplotlib
        import matplotlib.figure  # noqa: F401
        from matplotlib.backends import backend_agg  # noqa: F401
    except ImportError:
        raise MissingDependencyError("matplotlib", "plot", "Plotting") from None
    return matplotlib


def output_format(path: str | os.PathLike[str]) -> str:
    """The image format a file name asks for.

    Parameters
    ----------
    path
        Output file name; its extension (case-insensitive) picks the format.

    Returns
    -------
    str
        ``"png"``, ``"svg"`` or ``"pdf"``.

    Raises
    ------
    InputError
        If the extension is missing or not one of PNG, SVG, PDF.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in SUPPORTED_FORMATS:
        shown = f"'{Path(path).suffix}'" if suffix else "no extension"
        raise InputError(
            f"cannot tell the image format of {os.fspath(path)} ({shown}): "
            "name the output .png, .svg or .pdf (PNG, SVG, PDF)"
        )
    return SUPPORTED_FORMATS[suffix]


def parse_size(text: str, dpi: float = DEFAULT_DPI) -> tuple[float, float]:
    """Parse a figure size ``"W,H"`` in inches, or ``"W,Hpx"`` / ``"WxHpx"`` in pixels.

    Parameters
    ----------
    text
        ``"7,6"`` (inches), ``"800,600px"`` or ``"800x600px"`` (pixels at ``dpi``).
    dpi
        Resolution that converts pixels to inches.

    Returns
    -------
    tuple of float
        Width and height in inches.

    Raises
    ------
    InputError
        If the text is not two positive numbers.
    """
    raw = str(text).strip().lower()
    pixels = raw.endswith("px")
    body = raw[:-2] if pixels else raw.removesuffix("in")
    parts = [p for p in body.replace("x", ",").replace(" ", "").split(",") if p]
    try:
        width, height = (float(p) for p in parts)
    except ValueError:
        raise InputError(
            f"size {text!r} is not W,H: give inches ('7,6') or pixels ('800,600px')"
        ) from None
    if not (math.isfinite(width) and math.isfinite(height) and width > 0 and height > 0):
        raise InputError(f"size {text!r} must be two positive numbers")
    if pixels:
        if dpi <= 0:
            raise InputError(f"dpi must be positive, got {dpi}")
        width, height = width / dpi, height / dpi
    return width, height


def new_figure(size: tuple[float, float] = DEFAULT_SIZE, dpi: float = DEFAULT_DPI) -> Figure:
    """A Figure on the headless Agg canvas, laid out with the constrained engine.

    Parameters
    ----------
    size
        Width and height in inches.
    dpi
        Resolution of raster output, dots per inch.

    Returns
    -------
    matplotlib.figure.Figure
    """
    require_matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if dpi <= 0 or not math.isfinite(dpi):
        raise InputError(f"dpi must be a positive number, got {dpi}")
    figure = Figure(figsize=size, dpi=dpi, layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def save_figure(figure: Figure, path: str | os.PathLike[str], *, dpi: float | None = None) -> Path:
    """Write a figure to PNG, SVG or PDF, chosen by the extension, completely or not at all.

    The image is rendered into a temporary file beside ``path`` and renamed into place,
    so a failure leaves no partial picture. The page keeps the figure's size exactly
    (no tight bounding box), so ``size * dpi`` is the PNG's pixel size.

    Parameters
    ----------
    figure
        The figure to write.
    path
        Output file ending in ``.png``, ``.svg`` or ``.pdf``.
    dpi
        Resolution for PNG; the figure's own when omitted.

    Returns
    -------
    pathlib.Path
        The path written.
    """
    from occtool._files import atomic_write

    image_format = output_format(path)
    with atomic_write(path, "wb") as handle:
        figure.savefig(handle, format=image_format, dpi=dpi or figure.dpi)
    return Path(path)
