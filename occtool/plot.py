"""Pictures of range data, occupancy models, navigation maps and comparison reports.

Every ``draw_*`` function draws onto a matplotlib :class:`~matplotlib.axes.Axes` the
caller owns; every ``*_figure`` function builds a complete
:class:`~matplotlib.figure.Figure` (the paper's Figure 5 a, b and c, and the grid
comparison); :func:`save_figure` writes one to PNG, SVG or PDF, chosen by the file's
extension, completely or not at all.

matplotlib is an optional extra (``pip install 'occtool[plot]'``). It is imported only
when a function here runs, and figures are built with :class:`matplotlib.figure.Figure`
and the Agg canvas directly, never through ``pyplot``, so rendering works headless and
a user's interactive backend is left alone.

Coordinates are metres in REP-103 frames (x forward, y left). Navigation maps and
features are drawn in the robot frame unless a pose places them in the world frame.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError, MissingDependencyError, ModelFormatError, OcctoolError
from occtool.features import Features, Pose, RangeLog
from occtool.io import _json as safe_json
from occtool.robot import Robot

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from occtool.navigation import NavigationMap

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


# --- matplotlib, figures and files ----------------------------------------------------------


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
    from occtool.io._atomic import atomic_write

    image_format = output_format(path)
    with atomic_write(path, "wb") as handle:
        figure.savefig(handle, format=image_format, dpi=dpi or figure.dpi)
    return Path(path)


# --- navigation maps ------------------------------------------------------------------------


def read_navigation(path: str | os.PathLike[str]) -> NavigationMap:
    """Read a navigation map GeoJSON written by ``occtool extract``.

    A thin alias of :func:`occtool.io.geojson.read_navigation`, which raises
    :class:`~occtool.errors.InputError` naming the file for malformed input.
    """
    from occtool.io.geojson import read_navigation as read

    return read(path)


def read_navigation_maps(path: str | os.PathLike[str]) -> list[tuple[int | None, NavigationMap]]:
    """Every map in a navigation GeoJSON file, with the robot position each belongs to.

    A file of one map (``occtool extract MODEL``) gives ``[(None, map)]``; a file of a
    model set (``occtool extract DIR/``, a collection or a sequence whose features carry
    ``position``) gives one ``(position, map)`` per position, in position order.

    Raises
    ------
    InputError
        If the file is not a navigation map (the message names the file).
    """
    from occtool.io.geojson import read_navigation as read

    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{os.fspath(path)}: not a text (UTF-8) file") from None
    positions = _tagged_positions(text)
    if not positions:
        return [(None, read(path))]
    return [(position, read(path, position=position)) for position in positions]


def _tagged_positions(text: str) -> list[int]:
    """The ``position`` numbers a navigation GeoJSON's features carry (collection or sequence)."""
    try:
        documents = [safe_json.loads(text)]
    except json.JSONDecodeError:
        documents = []
        for line in text.splitlines():
            line = line.strip().lstrip("\x1e").strip()
            try:
                documents.append(safe_json.loads(line)) if line else None
            except json.JSONDecodeError:
                return []  # not ours to diagnose: the reader names the file and line
    features: list[Any] = []
    for document in documents:
        if isinstance(document, Mapping) and document.get("type") == "FeatureCollection":
            features.extend(document.get("features") or [])
        else:
            features.append(document)
    tags = {feature["properties"].get("position") for feature in features
            if isinstance(feature, Mapping) and isinstance(feature.get("properties"), Mapping)}
    return sorted(t for t in tags if isinstance(t, int) and not isinstance(t, bool))


def _finite(value: float | None) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def map_in_frame(nav: NavigationMap, pose: Pose | None) -> NavigationMap:
    """The map in the world frame at ``pose``; unchanged when ``pose`` is None or it is there already.

    Raises
    ------
    InputError
        If a world-frame map is asked to move to a different pose.
    """
    if pose is None:
        return nav
    if nav.frame_id == "base_link":
        return nav.in_world(pose)
    if nav.pose is not None and (nav.pose.x, nav.pose.y, nav.pose.yaw) == (pose.x, pose.y, pose.yaw):
        return nav
    raise InputError(f"the navigation map is in the {nav.frame_id!r} frame already and cannot be moved again")


# --- geometry helpers -----------------------------------------------------------------------


def _to_frame(xy: ArrayLike, pose: Pose | None) -> FloatArray:
    points = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return points if pose is None else pose.to_world(points)


def _polygons(geometry: Any) -> list[Any]:
    """The polygons of a Polygon, MultiPolygon or GeometryCollection (empty ones dropped)."""
    if geometry is None or geometry.is_empty:
        return []
    kind = geometry.geom_type
    if kind == "Polygon":
        return [geometry]
    if kind in ("MultiPolygon", "GeometryCollection"):
        return [p for part in geometry.geoms for p in _polygons(part)]
    return []


def geometry_path(geometry: Any, pose: Pose | None = None) -> Any:
    """A matplotlib Path of a shapely (Multi)Polygon, holes included, optionally moved by a pose.

    Parameters
    ----------
    geometry
        A shapely Polygon or MultiPolygon in the robot frame.
    pose
        When given, the path is placed in the world frame at this pose.

    Returns
    -------
    matplotlib.path.Path
    """
    require_matplotlib()
    from matplotlib.path import Path as MplPath

    from shapely.geometry.polygon import orient

    vertices: list[FloatArray] = []
    codes: list[NDArray[np.uint8]] = []
    for polygon in _polygons(geometry):
        # matplotlib fills by the nonzero winding rule: a hole shows only if it runs
        # against its shell, so rings are oriented shell counter-clockwise, holes clockwise.
        polygon = orient(polygon, sign=1.0)
        for ring in (polygon.exterior, *polygon.interiors):
            xy = _to_frame(np.asarray(ring.coords)[:, :2], pose)
            if len(xy) < 3:
                continue
            ring_codes = np.full(len(xy), MplPath.LINETO, dtype=np.uint8)
            ring_codes[0] = MplPath.MOVETO
            ring_codes[-1] = MplPath.CLOSEPOLY
            vertices.append(xy)
            codes.append(ring_codes)
    if not vertices:
        return MplPath(np.empty((0, 2)))
    return MplPath(np.concatenate(vertices), np.concatenate(codes))


def _finish_metric_axes(ax: Axes, title: str | None = None, *, frame: str = "base_link") -> None:
    ax.set_aspect("equal", adjustable="box")
    # Named in SVG output, so the axes' frame can be found to map drawn paths back to metres.
    ax.patch.set_gid("axes-frame")
    if frame == "base_link":
        ax.set_xlabel("x (m, forward)")
        ax.set_ylabel("y (m, left)")
    else:
        ax.set_xlabel(f"x (m, {frame} frame)")
        ax.set_ylabel(f"y (m, {frame} frame)")
    if title:
        ax.set_title(title, fontsize="medium")


def _set_square_limits(ax: Axes, half_width: float, centre: tuple[float, float] = (0.0, 0.0)) -> None:
    cx, cy = centre
    ax.set_xlim(cx - half_width, cx + half_width)
    ax.set_ylim(cy - half_width, cy + half_width)


# --- drawing onto axes ----------------------------------------------------------------------


def draw_robot(ax: Axes, radius: float, pose: Pose | None = None, *, label: str | None = "robot") -> Any:
    """Draw the robot's footprint disc with a tick along its heading.

    Parameters
    ----------
    ax
        Axes to draw on.
    radius
        Footprint radius, metres.
    pose
        World pose; the robot frame origin (heading +x) when omitted.
    label
        Legend label, or None for no legend entry.

    Returns
    -------
    matplotlib.patches.Circle
    """
    from matplotlib.patches import Circle

    pose = pose or Pose()
    disc = Circle((pose.x, pose.y), radius, facecolor=ROBOT_COLOUR, edgecolor="black", linewidth=0.8,
                  alpha=0.85, zorder=5, label=label, gid="robot")
    ax.add_patch(disc)
    tip = pose.to_world([[radius, 0.0]])[0]
    ax.plot([pose.x, tip[0]], [pose.y, tip[1]], color="black", linewidth=1.0, zorder=6)
    return disc


def draw_features(
    ax: Axes,
    features: Features,
    *,
    pose: Pose | None = None,
    marker_size: float = 4.0,
    colormap: str = "gray",
) -> Any:
    """Draw features projected on the floor (Oxy), brighter where the evidence is higher.

    Points are drawn in order of increasing evidence so the most certain ones stay on
    top; the axes get a dark background so that bright means certain, as in the
    paper's Figure 5a.

    Parameters
    ----------
    ax
        Axes to draw on.
    features
        Features in the robot frame.
    pose
        When given, features are placed in the world frame at this pose.
    marker_size
        Marker area in points squared.
    colormap
        Name of a matplotlib colormap running from dark to bright.

    Returns
    -------
    matplotlib.collections.PathCollection
        The scatter, for a colour bar.
    """
    return _scatter_evidence(ax, _to_frame(features.points[:, :2], pose), features.evidence,
                             marker_size=marker_size, colormap=colormap)


def _scatter_evidence(ax: Axes, xy: FloatArray, evidence: FloatArray, *, marker_size: float = 4.0,
                      colormap: str = "gray") -> Any:
    order = np.argsort(evidence, kind="stable")
    ax.set_facecolor("black")
    # vmin below zero keeps zero-evidence features a dim grey instead of invisible black.
    # Large clouds are rasterised so that SVG and PDF stay small.
    return ax.scatter(xy[order, 0], xy[order, 1], c=evidence[order], cmap=colormap, vmin=-0.3, vmax=1.0,
                      s=marker_size, linewidths=0, gid="features", rasterized=len(order) > 20000)


def _log_in_world(log: RangeLog) -> tuple[FloatArray, FloatArray, FloatArray]:
    """All features of a posed log in the world frame: ``(xy, evidence, path)``."""
    xy = np.concatenate([p.pose.to_world(p.features.points[:, :2]) for p in log.positions])  # type: ignore[union-attr]
    evidence = np.concatenate([p.features.evidence for p in log.positions])
    path = np.array([[p.pose.x, p.pose.y] for p in log.positions])  # type: ignore[union-attr]
    return xy, evidence, path


def draw_navigation(
    ax: Axes,
    nav: NavigationMap,
    *,
    pose: Pose | None = None,
    slices: bool = True,
    points: bool = True,
    circle: bool = True,
    robot: bool = True,
    labels: bool = True,
    explain_empty: bool = True,
    colormap: str = "viridis",
) -> dict[str, Any]:
    """Draw a navigation map: polygon, per-height slices, points, range circle and robot.

    Parameters
    ----------
    ax
        Axes to draw on.
    nav
        The navigation map (:class:`occtool.navigation.NavigationMap`), in the robot
        frame or already in a world frame.
    pose
        Place a robot-frame map in the world frame at this pose. A world-frame map is
        drawn where it is, around its own pose.
    slices, points, circle, robot
        Whether to draw the slices, the obstacle and exploration points, the max-range
        circle and the robot disc.
    labels
        Whether the artists get legend labels (switch off for all but one of several
        maps on the same axes).
    explain_empty
        Whether an empty polygon is explained in a note beside the robot (it is always
        ringed in red).
    colormap
        Colormap the slices' outlines are coloured from, lowest height first.

    Returns
    -------
    dict
        The artists by role: ``"navigation"`` (PathPatch), ``"slices"`` (list),
        ``"obstacles"``, ``"exploration"``, ``"range"``, ``"robot"``, and ``"empty"``
        (with ``"empty_note"``) for an empty polygon, when drawn.
    """
    from matplotlib import colormaps
    from matplotlib.patches import Circle, PathPatch

    def label(text: str) -> str | None:
        return text if labels else None

    nav = map_in_frame(nav, pose)
    origin = nav.pose if nav.frame_id != "base_link" and nav.pose is not None else Pose()
    artists: dict[str, Any] = {}
    if slices and nav.slices:
        colours = colormaps[colormap](np.linspace(0.0, 0.9, len(nav.slices)))
        drawn = []
        for item, colour in zip(nav.slices, colours):
            patch = PathPatch(geometry_path(item.polygon), facecolor="none", edgecolor=colour, linewidth=0.9,
                              linestyle="--", zorder=2, label=label(f"slice h = {item.height:+.2f} m"),
                              gid=f"slice{item.height:+.3f}")
            ax.add_patch(patch)
            drawn.append(patch)
        artists["slices"] = drawn
    threshold = _finite(nav.threshold)
    area = PathPatch(geometry_path(nav.polygon), facecolor=NAVIGATION_COLOUR, alpha=0.45,
                     edgecolor=NAVIGATION_COLOUR, linewidth=1.6, zorder=3, gid="navigation",
                     label=label("navigation area" + (f" (F < {threshold:g})" if threshold is not None else "")))
    ax.add_patch(area)
    artists["navigation"] = area
    if nav.polygon.is_empty:
        # An empty map is a result worth seeing (the robot is in collision where it
        # stands), not a blank to puzzle over: a red ring marks the position, and a
        # lone map says so in words.
        radius = _finite(nav.robot_radius) or Robot().radius
        artists["empty"] = Circle((origin.x, origin.y), radius * 1.5, facecolor="none", edgecolor=OBSTACLE_COLOUR,
                                  linewidth=2.0, zorder=6, gid="empty", label=label("empty navigation polygon"))
        ax.add_patch(artists["empty"])
        if explain_empty:
            artists["empty_note"] = ax.annotate(
                "navigation polygon is empty:\nno collision-free area at this position", (origin.x, origin.y),
                xytext=(0, -40), textcoords="offset points", ha="center", va="top", fontsize="small",
                color=OBSTACLE_COLOUR, zorder=9, bbox={"boxstyle": "round", "facecolor": "white", "alpha": 0.85})
    max_range = _finite(nav.max_range)
    if circle and max_range:
        ring = Circle((origin.x, origin.y), max_range, facecolor="none", edgecolor="0.4", linestyle=":",
                      linewidth=1.0, zorder=1, gid="max-range", label=label(f"max range {max_range:g} m"))
        ax.add_patch(ring)
        artists["range"] = ring
    if points:
        obstacles, exploration = nav.obstacle_points, nav.exploration_points
        artists["obstacles"] = ax.scatter(obstacles[:, 0], obstacles[:, 1], marker="x", s=28, linewidths=1.4,
                                          color=OBSTACLE_COLOUR, zorder=7, gid="obstacles",
                                          label=label(f"obstacle points ({len(obstacles)}, reinforcement -1)"))
        artists["exploration"] = ax.scatter(exploration[:, 0], exploration[:, 1], marker="^", s=26,
                                            facecolor="none", edgecolor=EXPLORATION_COLOUR, linewidths=1.2,
                                            zorder=7, gid="exploration",
                                            label=label(f"exploration points ({len(exploration)}, reinforcement +1)"))
    if robot:
        radius = _finite(nav.robot_radius) or Robot().radius
        artists["robot"] = draw_robot(ax, radius, origin, label=label(f"robot (radius {radius:g} m)"))
    return artists


def draw_truth(ax: Axes, scene: Any, *, pose: Pose | None = None, labels: bool = True) -> list[Any]:
    """Draw a synthetic scene's true obstacle footprints.

    Obstacles that reach into the robot's body band (above the ground clearance and
    below the top of the body) are hatched: the navigation polygon must avoid them.
    The others (a pallet under the clearance, a shelf over the robot) are outlined
    dotted, since driving under or over them is allowed.

    Parameters
    ----------
    ax
        Axes to draw on.
    scene
        A :class:`occtool.simulate.Scene` (from :func:`occtool.simulate.load_truth`):
        footprints in x, y metres, robot frame; heights above the floor.
    pose
        When given, footprints are moved into the world frame at this pose.
    labels
        Whether the first footprint of each kind gets a legend label.

    Returns
    -------
    list
        The PathPatches drawn.
    """
    from matplotlib.patches import PathPatch
    from shapely.geometry import Polygon

    robot = getattr(scene, "robot", None) or Robot()
    patches = []
    labelled: set[bool] = set()
    for obstacle in scene.obstacles:
        blocking = obstacle.z_min < robot.body_height and obstacle.z_max > robot.ground_clearance
        text = "true obstacles" if blocking else "true obstacles the robot passes under or over"
        patch = PathPatch(geometry_path(Polygon(obstacle.footprint), pose), facecolor="none",
                          edgecolor=TRUTH_COLOUR, hatch="///" if blocking else None,
                          linestyle="-" if blocking else ":", linewidth=1.0, zorder=4,
                          label=text if labels and blocking not in labelled else None,
                          gid="truth" if blocking else "truth-passable")
        labelled.add(blocking)
        ax.add_patch(patch)
        patches.append(patch)
    return patches


# --- occupancy models -----------------------------------------------------------------------


def evaluate_on_floor_grid(model: Any, height: float, extent: float, resolution: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Evaluate ``F`` on a square x, y grid around the robot at one sensor-frame height.

    Parameters
    ----------
    model
        A fitted model with ``predict(alpha, h, r)``.
    height
        Sensor-frame height ``h`` (negative below the sensor), metres.
    extent
        Half-width of the square, metres.
    resolution
        Cells along each side.

    Returns
    -------
    x, y, F
        Cell-centre coordinates (``(resolution,)`` each) and ``(resolution, resolution)``
        occupancy values, rows along y.
    """
    axis, alpha, h, r = _floor_grid(height, extent, resolution)
    values = np.asarray(model.predict(alpha, h, r), dtype=np.float64).reshape(resolution, resolution)
    return axis, axis.copy(), values


def _floor_grid(height: float, extent: float, resolution: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Cell centres of a square x, y grid at one height, and their (alpha, h, r), flattened row by row."""
    if resolution < 2:
        raise InputError(f"resolution must be at least 2 cells, got {resolution}")
    step = 2.0 * extent / resolution
    axis = -extent + step * (np.arange(resolution) + 0.5)
    gx, gy = np.meshgrid(axis, axis)
    alpha = np.arctan2(gy, gx).ravel()
    h = np.full(alpha.shape, float(height))
    r = np.sqrt(gx.ravel() ** 2 + gy.ravel() ** 2 + height**2)
    return axis, alpha, h, r


def occupied_projection(
    model: Any,
    level: float,
    heights: Sequence[float],
    max_range: float,
    *,
    angles: int = 180,
    ranges: int = 60,
) -> tuple[FloatArray, FloatArray]:
    """Points of a uniform (alpha, h, r) grid where ``F`` exceeds a level, projected on the floor.

    Sampling is uniform in the model's own coordinates, which gives the picture the
    circular look of the paper's Figure 5b.

    Parameters
    ----------
    model
        A fitted model with ``predict(alpha, h, r)``.
    level
        Occupancy level; points with ``F > level`` are returned.
    heights
        Sensor-frame heights to sample, metres.
    max_range
        Largest horizontal distance sampled, metres.
    angles, ranges
        Samples in pan angle and in horizontal distance.

    Returns
    -------
    xy, values
        ``(K, 2)`` floor coordinates and the ``(K,)`` occupancy values there.
    """
    heights_array = np.asarray(heights, dtype=np.float64).reshape(-1)
    if heights_array.size == 0:
        raise InputError("at least one height is needed for the projection")
    alpha = np.linspace(-np.pi, np.pi, angles, endpoint=False)
    horizontal = np.linspace(max_range / ranges, max_range, ranges)
    a, h, d = np.meshgrid(alpha, heights_array, horizontal, indexing="ij")
    r = np.sqrt(d**2 + h**2)
    values = np.asarray(model.predict(a.ravel(), h.ravel(), r.ravel()), dtype=np.float64)
    keep = values > level
    x = (d.ravel() * np.cos(a.ravel()))[keep]
    y = (d.ravel() * np.sin(a.ravel()))[keep]
    return np.column_stack([x, y]), values[keep]


def active_piece_function(model: Any) -> Callable[[FloatArray, FloatArray, FloatArray], NDArray[np.intp]] | None:
    """The model's "which linear piece is active" function, if it has one.

    Looks for ``active_piece(alpha, h, r)`` on the fitted estimator's ``tree_`` and on
    the object itself (a :class:`occtool.tree.MinMaxTree` has it).

    Returns
    -------
    callable or None
        ``f(alpha, h, r) -> piece index`` per point, or None when there is none.
    """
    for owner in (getattr(model, "tree_", None), model):
        function = getattr(owner, "active_piece", None)
        if callable(function):
            return function
    return None


def model_piece_count(model: Any) -> int | None:
    """Number of linear pieces in a model's tree, when it says."""
    for owner in (getattr(model, "tree_", None), model):
        value = getattr(owner, "n_pieces", None)
        if isinstance(value, (int, np.integer)):
            return int(value)
    return None


def model_robot(model: Any) -> Robot:
    """The robot a model was fitted for (``robot_``, else ``robot``), or the default robot."""
    for name in ("robot_", "robot"):
        robot = getattr(model, name, None)
        if isinstance(robot, Robot):
            return robot
    return Robot()


def model_extent(model: Any, level: float, robot: Robot | None = None, *, default: float = 5.0) -> float:
    """Half-width of the area worth drawing around a model, metres.

    Twice the horizontal distance at which ``F`` reaches ``level``,
    taken at the median over pan angles and heights of the robot's body band,
    between 1 and 30 m; ``default`` for a model without ``inverse_range``.
    """
    inverse = getattr(model, "inverse_range", None)
    if not callable(inverse):
        return default
    robot = robot or model_robot(model)
    heights = np.linspace(*robot.body_band, 3)[:, None]
    alpha = np.linspace(-np.pi, np.pi, 180, endpoint=False)[None, :]
    r = np.asarray(inverse(alpha, heights, level), dtype=np.float64)
    horizontal = np.sqrt(np.clip(r**2 - heights**2, 0.0, None))
    finite = horizontal[np.isfinite(horizontal)]
    if finite.size == 0 or finite.max() <= 0:
        return default
    # The median, not the maximum or a high percentile: where the model saw no features
    # (or only far ones) F rises slowly and the level is crossed far away, which would
    # shrink the surroundings of the robot to a dot.
    return float(np.clip(2.0 * np.median(finite), 1.0, 30.0))


def _model_summary(model: Any) -> str:
    summary = getattr(model, "training_summary", None)
    if not callable(summary):
        return ""
    try:
        values = summary()
    except OcctoolError:  # an unfitted model has no summary to show
        return ""
    parts = []
    if isinstance(values.get("n_features"), int):
        parts.append(f"{values['n_features']} features")
    if isinstance(values.get("rmse"), float):
        parts.append(f"RMSE {values['rmse']:.3f}")
    return ", ".join(parts)


def draw_occupied_projection(
    ax: Axes,
    model: Any,
    level: float,
    heights: Sequence[float],
    max_range: float,
    *,
    marker_size: float = 3.0,
) -> Any:
    """Draw where ``F`` exceeds ``level`` projected on the floor (the paper's Figure 5b).

    Returns
    -------
    matplotlib.collections.PathCollection
    """
    xy, values = occupied_projection(model, level, heights, max_range)
    order = np.argsort(values, kind="stable")
    ax.set_facecolor("black")
    return ax.scatter(xy[order, 0], xy[order, 1], c=values[order], cmap="gray", vmin=level - 0.3, vmax=1.0,
                      s=marker_size, linewidths=0, gid="occupied")


def draw_heatmap(
    ax: Axes,
    model: Any,
    height: float,
    extent: float,
    *,
    level: float | None = None,
    resolution: int = 160,
    colormap: str = "viridis",
) -> Any:
    """Draw a heat map of ``F`` over (x, y) at one sensor-frame height, with the level's contour.

    Returns
    -------
    matplotlib.image.AxesImage
    """
    x, y, values = evaluate_on_floor_grid(model, height, extent, resolution)
    image = ax.imshow(values, origin="lower", extent=(-extent, extent, -extent, extent), cmap=colormap,
                      vmin=0.0, vmax=1.0, interpolation="nearest", gid="occupancy-heatmap")
    if level is not None and values.min() < level < values.max():
        ax.contour(x, y, values, levels=[level], colors="white", linewidths=1.0)
    return image


def draw_active_pieces(ax: Axes, model: Any, height: float, extent: float, *, resolution: int = 160) -> Any | None:
    """Colour the (x, y) plane at one height by which linear piece of the tree is active.

    Returns
    -------
    matplotlib.image.AxesImage or None
        None when the model does not expose its active piece.
    """
    function = active_piece_function(model)
    if function is None:
        return None
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib import colormaps

    _, alpha, h, r = _floor_grid(height, extent, resolution)
    pieces = np.asarray(function(alpha, h, r)).astype(np.intp).reshape(resolution, resolution)
    count = max(int(model_piece_count(model) or 0), int(pieces.max()) + 1)
    palette = colormaps["tab20"](np.arange(count) % 20)
    return ax.imshow(pieces, origin="lower", extent=(-extent, extent, -extent, extent),
                     cmap=ListedColormap(palette), norm=BoundaryNorm(np.arange(count + 1) - 0.5, count),
                     interpolation="nearest", gid="active-pieces")


def expand_navigation_paths(paths: Iterable[str | os.PathLike[str]]) -> list[Path]:
    """Navigation map files from files and folders (a folder gives its ``*.geojson``, sorted).

    Raises
    ------
    InputError
        If a folder holds no GeoJSON file.
    """
    found: list[Path] = []
    for item in map(Path, paths):
        if item.is_dir():
            inside = sorted(p for p in item.iterdir() if p.suffix.lower() == ".geojson" and p.is_file())
            if not inside:
                raise InputError(f"{item} holds no .geojson navigation map")
            found.extend(inside)
        else:
            found.append(item)
    return found


# --- reports and scaling curves -------------------------------------------------------------


def read_json(path: str | os.PathLike[str], what: str) -> Any:
    """Read a JSON document, with a one-line error naming the file when it is malformed."""
    text = Path(path).read_text(encoding="utf-8")
    try:
        return safe_json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelFormatError(f"{os.fspath(path)} is not a valid {what} (line {exc.lineno}: {exc.msg})") from None


def report_polygons(report: Mapping[str, Any]) -> dict[str, Any]:
    """The navigation polygons per model in a comparison report, as shapely geometries.

    Looks in ``report["polygons"][model]`` and in ``report["models"][model]["polygon"]``;
    a value may be a GeoJSON geometry, a Feature or a FeatureCollection (whose
    ``kind: navigation`` feature is used).
    """
    from shapely.errors import ShapelyError
    from shapely.geometry import shape

    found: dict[str, Any] = {}
    candidates: dict[str, Any] = {}
    models = report.get("models")
    if isinstance(models, Mapping):
        for name, entry in models.items():
            if isinstance(entry, Mapping) and "polygon" in entry:
                candidates[name] = entry["polygon"]
    polygons = report.get("polygons")
    if isinstance(polygons, Mapping):
        candidates.update(polygons)
    for name, value in candidates.items():
        if isinstance(value, Mapping) and value.get("type") == "FeatureCollection":
            value = next((f for f in value.get("features") or [] if isinstance(f, Mapping)
                          and (f.get("properties") or {}).get("kind") == "navigation"), None)
        if isinstance(value, Mapping) and value.get("type") == "Feature":
            value = value.get("geometry")
        try:
            found[str(name)] = shape(value)
        except (TypeError, ValueError, KeyError, IndexError, AttributeError, ShapelyError):
            continue  # a section we cannot read is skipped, not fatal: the rest still draws
    return found


@dataclass(frozen=True)
class ScalingSeries:
    """One model's cost against one size variable, from the benchmark's sweep."""

    model: str
    variable: str
    x: FloatArray
    seconds: FloatArray
    memory_bytes: FloatArray


_TIME_KEYS = ("total_s", "build_s", "fit_s", "seconds", "time_s")
_MEMORY_KEYS = ("memory_bytes", "peak_memory_bytes", "bytes")
_SIZE_KEYS = ("scale", "features", "n_features", "scene_scale")


def scaling_series(bench: Any) -> list[ScalingSeries]:
    """Scaling curves from the benchmark's results: time and memory against size per model.

    Accepts a list of rows (or ``{"scaling": [...]}`` / ``{"sweep": [...]}``, as
    ``bench/results.json`` has it) where a row has a size (``scale`` and/or
    ``features``; ``"sweep"`` names the one it varies) and either per-model entries
    under ``"models"`` or a ``"model"`` name with ``build_s`` (plus ``extract_s``) and
    ``memory_bytes``. Rows missing a number are skipped.

    Returns
    -------
    list of ScalingSeries
        One per (model, size variable) with at least two points, sorted by size.
    """
    rows: Any = bench
    if isinstance(bench, Mapping):
        for key in ("scaling", "sweep", "rows", "results"):
            if isinstance(bench.get(key), list):
                rows = bench[key]
                break
        else:
            rows = []
    if not isinstance(rows, list):
        return []
    collected: dict[tuple[str, str], list[tuple[float, float, float]]] = {}

    def number(entry: Mapping[str, Any], keys: Iterable[str]) -> float | None:
        for key in keys:
            value = entry.get(key)
            if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
                return float(value)
        return None

    def seconds_of(entry: Mapping[str, Any]) -> float | None:
        if "build_s" in entry and "extract_s" in entry:
            build, extract = number(entry, ["build_s"]), number(entry, ["extract_s"])
            if build is not None and extract is not None:
                return build + extract
        return number(entry, _TIME_KEYS)

    for row in rows:
        if not isinstance(row, Mapping):
            continue
        entries: list[tuple[str, Mapping[str, Any]]] = []
        if isinstance(row.get("models"), Mapping):
            entries = [(str(n), e) for n, e in row["models"].items() if isinstance(e, Mapping)]
        elif isinstance(row.get("model"), str):
            entries = [(row["model"], row)]
        # A row of one sweep varies one size; the other is held fixed and not a curve.
        swept = (row["sweep"],) if row.get("sweep") in ("scale", "features") else ("scale", "features")
        for name, entry in entries:
            seconds, memory = seconds_of(entry), number(entry, _MEMORY_KEYS)
            if seconds is None and memory is None:
                continue
            for variable in swept:
                size = number(row, [variable] if variable == "scale" else ["features", "n_features"])
                if size is None:
                    continue
                collected.setdefault((name, variable), []).append(
                    (size, np.nan if seconds is None else seconds, np.nan if memory is None else memory))
    series = []
    known = list(MODEL_COLOURS)  # the parametric model first, then the baselines
    for (name, variable), values in sorted(collected.items(), key=lambda item: (
            known.index(item[0][0]) if item[0][0] in known else len(known), item[0])):
        if len(values) < 2:
            continue
        array = np.asarray(sorted(values), dtype=np.float64)
        series.append(ScalingSeries(name, variable, array[:, 0], array[:, 1], array[:, 2]))
    return series


def draw_scaling(ax_time: Axes, ax_memory: Axes, series: Sequence[ScalingSeries], variable: str) -> None:
    """Draw time and memory against one size variable, one line per model, log axes.

    Parameters
    ----------
    ax_time, ax_memory
        Axes for time (seconds, build plus extraction) and memory (MiB).
    series
        From :func:`scaling_series`; those of other variables are ignored.
    variable
        ``"scale"`` (scene scale) or ``"features"`` (feature count).
    """
    label = "scene scale" if variable == "scale" else "features"
    for item in (s for s in series if s.variable == variable):
        colour = MODEL_COLOURS.get(item.model)
        ax_time.plot(item.x, item.seconds, marker="o", color=colour, label=item.model,
                     gid=f"time-{item.model}-{variable}")
        ax_memory.plot(item.x, item.memory_bytes / 2**20, marker="o", color=colour, label=item.model,
                       gid=f"memory-{item.model}-{variable}")
    for ax, what in ((ax_time, "time (s), build + extract"), (ax_memory, "memory (MiB)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel(what)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize="x-small")
        ax.set_title(f"{what.split(' ')[0]} against {label}", fontsize="medium")


# --- whole figures --------------------------------------------------------------------------


def _colourbar(figure: Figure, mappable: Any, ax: Axes, label: str) -> None:
    bar = figure.colorbar(mappable, ax=ax, shrink=0.8)
    bar.set_label(label)


def _features_extent(xy: FloatArray, minimum: float = 1.0) -> tuple[tuple[float, float], float]:
    if len(xy) == 0:
        return (0.0, 0.0), minimum
    low, high = xy.min(axis=0), xy.max(axis=0)
    centre = (low + high) / 2.0
    half = max(float((high - low).max()) / 2.0 * 1.05, minimum)
    return (float(centre[0]), float(centre[1])), half


def features_figure(
    log: RangeLog,
    *,
    position: int | None = None,
    robot: Robot | None = None,
    size: tuple[float, float] = DEFAULT_SIZE,
    dpi: float = DEFAULT_DPI,
    title: str | None = None,
) -> Figure:
    """The range data projected on the floor with the robot at the centre (Figure 5a).

    A single position is drawn in the robot frame. A log of several positions with
    poses, and no ``position`` chosen, is drawn in the world frame with the robot at
    each pose and the path joining them.

    Parameters
    ----------
    log
        The range log.
    position
        Index of the position to draw; all positions when omitted.
    robot
        The robot, for its disc; defaults to :class:`Robot`'s defaults.
    size, dpi, title
        Figure size in inches, resolution, and a title replacing the automatic one.

    Returns
    -------
    matplotlib.figure.Figure
    """
    robot = robot or Robot()
    figure = new_figure(size, dpi)
    ax = figure.add_subplot()
    source = Path(log.source).name if log.source else "range log"
    world_frame: str | None = None
    if position is not None or len(log.positions) <= 1:
        chosen = log.single(position)
        scatter = draw_features(ax, chosen.features)
        draw_robot(ax, robot.radius)
        centre, half = _features_extent(chosen.features.points[:, :2], robot.radius * 4)
        where = f"position {chosen.index}, " if len(log.positions) > 1 else ""
        automatic = (f"Range features projected on the floor (Oxy), robot frame\n"
                     f"{source}: {where}{len(chosen.features)} features; brighter = higher evidence")
    else:
        if not all(p.pose is not None for p in log.positions):
            raise InputError(f"{source} holds {len(log.positions)} positions without poses for all of them: "
                             "pick one with --position N")
        xy, evidence, path = _log_in_world(log)
        world_frame = "world"
        scatter = _scatter_evidence(ax, xy, evidence)
        ax.plot(path[:, 0], path[:, 1], color=ROBOT_COLOUR, linewidth=0.8, marker=".", markersize=3, zorder=6,
                gid="path", label="robot path")
        # A disc per position would bury a long path; show where the robot started and ended.
        for item in (log.positions[0], log.positions[-1]):
            draw_robot(ax, robot.radius, item.pose, label=None)
        centre, half = _features_extent(np.concatenate([xy, path]), robot.radius * 4)
        automatic = (f"Range features projected on the floor (Oxy), world frame\n"
                     f"{source}: {len(log.positions)} positions, {len(evidence)} features; brighter = higher evidence")
    _set_square_limits(ax, half, centre)
    _finish_metric_axes(ax, title or automatic, frame="base_link" if world_frame is None else world_frame)
    if scatter is not None:
        _colourbar(figure, scatter, ax, "evidence m")
    return figure


def model_figure(
    model: Any,
    *,
    level: float = 0.4,
    height: float | None = None,
    heights: Sequence[float] | None = None,
    extent: float = 5.0,
    robot: Robot | None = None,
    pieces: bool = False,
    resolution: int = 160,
    source: str = "",
    size: tuple[float, float] | None = None,
    dpi: float = DEFAULT_DPI,
    title: str | None = None,
) -> Figure:
    """The occupancy model: where ``F > level`` on the floor, and ``F`` at one height.

    Panels, left to right: the (alpha, h, r) samples with ``F > level`` projected on
    the floor (the paper's Figure 5b); a heat map of ``F`` over (x, y) at ``height``
    with the level's contour; and, with ``pieces``, the same plane coloured by the
    active linear piece.

    Parameters
    ----------
    model
        A fitted model with ``predict(alpha, h, r)``.
    level
        Occupancy level of the projection and the contour.
    height
        Sensor-frame height of the heat map, metres; the middle of the robot's body band
        when omitted.
    heights
        Sensor-frame heights of the projection; six across the body band when omitted.
    extent
        Half-width of the area drawn, metres.
    robot
        The robot, for the body band and its disc.
    pieces
        Add the active-piece panel (an :class:`InputError` if the model cannot say).
    resolution
        Heat-map cells along each side.
    source
        Model file name for the title.
    size, dpi, title
        Figure size in inches (wide enough for the panels when omitted), resolution,
        and a title replacing the automatic one.

    Returns
    -------
    matplotlib.figure.Figure
    """
    robot = robot or Robot()
    if not 0.0 <= level <= 1.0:
        raise InputError(f"level must lie in [0, 1], got {level}")
    if extent <= 0 or not math.isfinite(extent):
        raise InputError(f"extent must be a positive number of metres, got {extent}")
    low, high = robot.body_band
    if height is None:
        height = (low + high) / 2.0
    if heights is None:
        heights = tuple(np.linspace(low, high, 6))
    if pieces and active_piece_function(model) is None:
        raise InputError("this model does not tell which linear piece is active, so --pieces cannot be drawn")
    panels = 3 if pieces else 2
    figure = new_figure(size or (4.6 * panels, 4.6), dpi)
    axes = figure.subplots(1, panels, squeeze=False)[0]

    projection = draw_occupied_projection(axes[0], model, level, heights, extent)
    draw_robot(axes[0], robot.radius)
    _set_square_limits(axes[0], extent)
    _finish_metric_axes(axes[0], f"F > {level:g} projected on the floor\n"
                                 f"h in [{min(heights):+.2f}, {max(heights):+.2f}] m")
    _colourbar(figure, projection, axes[0], "occupancy F")

    image = draw_heatmap(axes[1], model, height, extent, level=level, resolution=resolution)
    draw_robot(axes[1], robot.radius, label=None)
    _finish_metric_axes(axes[1], f"F over (x, y) at h = {height:+.2f} m\n"
                                 f"({height + robot.sensor_height:.2f} m above the floor)")
    _colourbar(figure, image, axes[1], "occupancy F")

    if pieces:
        regions = draw_active_pieces(axes[2], model, height, extent, resolution=resolution)
        if regions is not None and regions.norm.Ncmap <= 20:
            bar = figure.colorbar(regions, ax=axes[2], shrink=0.8, ticks=np.arange(regions.norm.Ncmap))
            bar.set_label("linear piece")
        draw_robot(axes[2], robot.radius, label=None)
        _finish_metric_axes(axes[2], f"active linear piece at h = {height:+.2f} m")

    count = model_piece_count(model)
    name = Path(source).name if source else "model"
    details = [f"{count} linear pieces"] if count else []
    details += [d for d in (_model_summary(model), f"level {level:g}") if d]
    figure.suptitle(title or f"Occupancy model {name}: " + ", ".join(details), fontsize="large")
    return figure


def navigation_figure(
    maps: Sequence[NavigationMap],
    *,
    positions: Sequence[int | None] | None = None,
    log: RangeLog | None = None,
    position: int | None = None,
    truth: Any = None,
    slices: bool = True,
    source: str = "",
    size: tuple[float, float] = DEFAULT_SIZE,
    dpi: float = DEFAULT_DPI,
    title: str | None = None,
) -> Figure:
    """The navigation polygon, slices, obstacle and exploration points (Figure 5c).

    One robot-frame map is drawn in the robot frame. Several maps, one per position of
    a multi-position log, are drawn in the world frame along the robot's path: maps
    written in a world frame (``occtool extract --world``) stay where they are, and
    robot-frame maps are placed at the poses of ``log``'s positions (matched by
    position number when ``positions`` is given, else in order).

    Parameters
    ----------
    maps
        Navigation maps (:class:`occtool.navigation.NavigationMap`).
    positions
        The log position each map belongs to (as :func:`read_navigation_maps` gives),
        None where unknown.
    log
        Range log whose features are drawn underneath: the chosen position under a
        single map, every position under several.
    position
        The log position under a single map (needed when the log has several and the
        map's own position number is not known).
    truth
        A scene (:func:`occtool.simulate.load_truth`) whose obstacles are drawn on top;
        it is placed at the first map's pose in a world-frame picture.
    slices
        Whether to draw the per-height slices (one map only: along a path they crowd).
    source
        Where the map(s) came from, for the title.
    size, dpi, title
        Figure size in inches, resolution, and a title replacing the automatic one.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if not maps:
        raise InputError("no navigation map to draw")
    single = len(maps) == 1
    if positions is not None and len(positions) != len(maps):
        raise InputError(f"{len(maps)} navigation maps but {len(positions)} position numbers")
    poses_by_index = {p.index: p.pose for p in log.positions} if log is not None else {}
    poses_in_order = [p.pose for p in log.positions] if log is not None else []
    placed: list[NavigationMap] = []
    for index, nav in enumerate(maps):
        number = positions[index] if positions is not None else None
        if nav.frame_id != "base_link" or single:
            placed.append(nav)
        elif number is not None and poses_by_index.get(number) is not None:
            placed.append(nav.in_world(poses_by_index[number]))  # type: ignore[arg-type]
        elif number is None and len(poses_in_order) == len(maps) and poses_in_order[index] is not None:
            placed.append(nav.in_world(poses_in_order[index]))  # type: ignore[arg-type]
        else:
            raise InputError(f"{len(maps)} robot-frame navigation maps but no pose for each: give a --features "
                             "log with the posed positions they were extracted from, or extract with --world")
    world = any(nav.frame_id != "base_link" for nav in placed)
    poses = [nav.pose if nav.frame_id != "base_link" and nav.pose is not None else Pose() for nav in placed]

    figure = new_figure(size, dpi)
    ax = figure.add_subplot()
    scatter = None
    corners: list[FloatArray] = []
    if log is not None:
        if single:
            tagged = positions[0] if positions is not None else None
            if position is None and tagged is not None and len(log.positions) > 1:
                # A map read from a model set knows its position: draw that one's features.
                matching = [i for i, item in enumerate(log.positions) if item.index == tagged]
                position = matching[0] if matching else None
            chosen = log.single(position)
            scatter = draw_features(ax, chosen.features, pose=poses[0] if world else None)
        else:
            if not all(p.pose is not None for p in log.positions):
                raise InputError("the features log has positions without poses: they cannot be drawn along the path")
            xy, evidence, _ = _log_in_world(log)
            scatter = _scatter_evidence(ax, xy, evidence)
    if truth is not None:
        draw_truth(ax, truth, pose=poses[0] if world else None)
    drawn = [draw_navigation(ax, nav, slices=slices and single, labels=index == 0, explain_empty=single)
             for index, nav in enumerate(placed)]
    if not single:
        # The legend speaks for every map on the path, not just the first.
        obstacles = sum(len(nav.obstacle_points) for nav in placed)
        exploration = sum(len(nav.exploration_points) for nav in placed)
        drawn[0]["obstacles"].set_label(f"obstacle points ({obstacles} in all, reinforcement -1)")
        drawn[0]["exploration"].set_label(f"exploration points ({exploration} in all, reinforcement +1)")
        empty = [artists["empty"] for artists in drawn if "empty" in artists]
        if empty:
            empty[0].set_label(f"empty navigation polygon ({len(empty)} of {len(placed)})")
    for index, nav in enumerate(placed):
        reach = _finite(nav.max_range) or 0.0
        if not nav.polygon.is_empty:
            minx, miny, maxx, maxy = nav.polygon.bounds
            corners.append(np.array([[minx, miny], [maxx, maxy]]))
        reach = max(reach, _finite(nav.robot_radius) or 0.0, 0.5)
        corners.append(np.array([[poses[index].x - reach, poses[index].y - reach],
                                 [poses[index].x + reach, poses[index].y + reach]]))
    if not single:
        path = np.array([[p.x, p.y] for p in poses])
        ax.plot(path[:, 0], path[:, 1], color=ROBOT_COLOUR, linewidth=1.2, zorder=8, label="robot path", gid="path")
    centre, half = _features_extent(np.concatenate(corners), minimum=0.5)
    _set_square_limits(ax, half * 1.08, centre)
    # Below the axes, so the legend never hides the map it explains.
    figure.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncols=3, fontsize="x-small",
                  frameon=False)
    first = maps[0]
    parameters = []
    if _finite(first.threshold) is not None:
        parameters.append(f"threshold {first.threshold:g}")
    if first.heights:
        parameters.append("heights " + ", ".join(f"{h:+.2f}" for h in first.heights) + " m")
    if _finite(first.robot_radius) is not None:
        parameters.append(f"robot radius {first.robot_radius:g} m")
    frame = f"{placed[0].frame_id} frame" if world else "robot frame"
    where = f" {Path(source).name}" if source else ""
    if single:
        what = f"Navigation map{where}, {frame}"
    else:
        what = f"Navigation maps{where} of {len(maps)} positions, {frame}"
    _finish_metric_axes(ax, title or (what + ("\n" + "; ".join(parameters) if parameters else "")),
                        frame=placed[0].frame_id if world else "base_link")
    if scatter is not None:
        _colourbar(figure, scatter, ax, "evidence m")
    return figure


def compare_figure(
    report: Mapping[str, Any],
    *,
    bench: Any = None,
    source: str = "",
    size: tuple[float, float] | None = None,
    dpi: float = DEFAULT_DPI,
    title: str | None = None,
) -> Figure:
    """The comparison report: navigation polygons side by side and the scaling curves.

    The top row draws each model's navigation polygon (those the report carries), the
    bottom row time and memory against scene scale and feature count on log axes
    (from ``bench``, or the report's own ``"scaling"`` section). A report without
    sweeps shows bars of each model's build time, extraction time and memory instead.
    ``bench/results.json`` itself may be given as the report: its
    ``"headline_report"`` is drawn with its sweeps.

    Parameters
    ----------
    report
        The ``occtool compare-grid --json`` document.
    bench
        The benchmark's results (``bench/results.json``), optional.
    source
        Report file name for the title.
    size, dpi, title
        Figure size in inches (from the panel count when omitted), resolution, title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if not isinstance(report, Mapping):
        raise ModelFormatError(f"{source or 'the report'} is not a JSON object")
    if "models" not in report and isinstance(report.get("headline_report"), Mapping):
        # bench/results.json: its headline comparison and its own sweeps.
        bench = report if bench is None else bench
        report = report["headline_report"]
    polygons = report_polygons(report)
    series = scaling_series(bench if bench is not None else report)
    variables = [v for v in ("scale", "features") if any(s.variable == v for s in series)]
    models = {str(k): v for k, v in (report.get("models") or {}).items() if isinstance(v, Mapping)} \
        if isinstance(report.get("models"), Mapping) else {}
    if not (polygons or variables or models):
        raise ModelFormatError(f"{source or 'the report'} has no models, polygons or scaling results to draw")
    settings = report.get("settings") if isinstance(report.get("settings"), Mapping) else {}
    cost_panels = 2 * len(variables) if variables else (3 if models else 0)
    columns = max(len(polygons), cost_panels, 1)
    rows = int(bool(polygons)) + int(bool(cost_panels))
    figure = new_figure(size or (3.6 * columns, 3.6 * rows + 0.6), dpi)
    grid = figure.add_gridspec(rows, 1)
    row = 0
    if polygons:
        _draw_report_polygons(figure, grid[row, 0].subgridspec(1, len(polygons)), report, polygons, settings)
        row += 1
    if variables:
        cells = grid[row, 0].subgridspec(1, 2 * len(variables))
        for index, variable in enumerate(variables):
            draw_scaling(figure.add_subplot(cells[0, 2 * index]), figure.add_subplot(cells[0, 2 * index + 1]),
                         series, variable)
    elif models:
        cells = grid[row, 0].subgridspec(1, 3)
        names = list(models)
        for index, (key, label, scale) in enumerate((("build_s", "build time (s)", 1.0),
                                                     ("extract_s", "extraction time (s)", 1.0),
                                                     ("memory_bytes", "memory (MiB)", 2.0**-20))):
            ax = figure.add_subplot(cells[0, index])
            values = [_report_number(models[n], key) * scale for n in names]
            bars = ax.bar(names, values, color=[MODEL_COLOURS.get(n, "tab:gray") for n in names])
            ax.set_gid(f"bars-{key}")
            ax.bar_label(bars, labels=[f"{v:.3g}" for v in values], fontsize="small")
            positive = [v for v in values if v > 0 and math.isfinite(v)]
            if positive:
                # Log axis from a decade under the smallest bar, so bar heights compare by ratio.
                ax.set_yscale("log")
                ax.set_ylim(min(positive) / 10.0, max(positive) * 3.0)
            ax.set_title(label, fontsize="medium")
    name = Path(source).name if source else "comparison report"
    details = [f"{report['features']} features"] if isinstance(report.get("features"), int) else []
    for key, text in (("threshold", "threshold {:g}"), ("pieces", "{:d} pieces"),
                      ("resolution", "grid cell {:g} m")):
        value = settings.get(key)
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            details.append(text.format(value))
    figure.suptitle(title or f"Parametric model against grids: {name}" + (", " + ", ".join(details) if details else ""),
                    fontsize="large")
    return figure


def _report_number(section: Mapping[str, Any], key: str) -> float:
    value = section.get(key)
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else np.nan


def _draw_report_polygons(figure: Figure, cells: Any, report: Mapping[str, Any], polygons: Mapping[str, Any],
                          settings: Mapping[str, Any]) -> None:
    """One panel per model: its navigation polygon, the parametric one outlined for reference."""
    from matplotlib.patches import Circle, PathPatch

    radius = _report_number(settings, "robot_radius")
    radius = radius if math.isfinite(radius) else Robot().radius
    max_range = _report_number(settings, "max_range")
    extents = [max(abs(v) for v in g.bounds) for g in polygons.values() if not g.is_empty]
    half = 1.1 * max(extents + ([max_range] if math.isfinite(max_range) else []) + [radius * 2])
    reference = polygons.get("parametric")
    agreement = report.get("agreement") if isinstance(report.get("agreement"), Mapping) else {}
    truth = report.get("truth") if isinstance(report.get("truth"), Mapping) else {}
    shared = None
    for index, (name, geometry) in enumerate(polygons.items()):
        ax = figure.add_subplot(cells[0, index], sharex=shared, sharey=shared)
        shared = shared or ax
        colour = MODEL_COLOURS.get(name, NAVIGATION_COLOUR)
        ax.add_patch(PathPatch(geometry_path(geometry), facecolor=colour, alpha=0.35, edgecolor=colour,
                               linewidth=1.5, gid=f"polygon-{name}", label=f"{name} polygon"))
        if reference is not None and name != "parametric":
            ax.add_patch(PathPatch(geometry_path(reference), facecolor="none", edgecolor=MODEL_COLOURS["parametric"],
                                   linestyle="--", linewidth=1.0, label="parametric polygon"))
        if math.isfinite(max_range):
            ax.add_patch(Circle((0.0, 0.0), max_range, facecolor="none", edgecolor="0.4", linestyle=":",
                                linewidth=1.0))
        draw_robot(ax, radius, label=None)
        _set_square_limits(ax, half)
        lines = [f"{name}: area {geometry.area:.2f} m²"]
        iou = agreement.get(name, {}).get("iou") if isinstance(agreement.get(name), Mapping) else None
        if isinstance(iou, (int, float)):
            lines.append(f"IoU with parametric {iou:.2f}")
        scores = truth.get(name) if isinstance(truth.get(name), Mapping) else {}
        if isinstance(scores.get("iou"), (int, float)) and isinstance(scores.get("violation"), (int, float)):
            lines.append(f"truth IoU {scores['iou']:.2f}, violation {scores['violation']:.3f} m²")
        _finish_metric_axes(ax, "\n".join(lines))
