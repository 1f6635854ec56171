"""Drawing onto a caller's matplotlib Axes: features, robot, navigation maps, truth, models, sweeps."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.features import Features, Pose, RangeLog
from occtool.plot._canvas import (
    EXPLORATION_COLOUR,
    MODEL_COLOURS,
    NAVIGATION_COLOUR,
    OBSTACLE_COLOUR,
    ROBOT_COLOUR,
    TRUTH_COLOUR,
    FloatArray,
    require_matplotlib,
)
from occtool.plot._probing import (
    _floor_grid,
    active_piece_function,
    evaluate_on_floor_grid,
    model_piece_count,
    occupied_projection,
)
from occtool.plot._reading import ScalingSeries
from occtool.robot import Robot

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from occtool.navigation import NavigationMap


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
    from matplotlib import colormaps
    from matplotlib.colors import BoundaryNorm, ListedColormap

    _, alpha, h, r = _floor_grid(height, extent, resolution)
    pieces = np.asarray(function(alpha, h, r)).astype(np.intp).reshape(resolution, resolution)
    count = max(int(model_piece_count(model) or 0), int(pieces.max()) + 1)
    palette = colormaps["tab20"](np.arange(count) % 20)
    return ax.imshow(pieces, origin="lower", extent=(-extent, extent, -extent, extent),
                     cmap=ListedColormap(palette), norm=BoundaryNorm(np.arange(count + 1) - 0.5, count),
                     interpolation="nearest", gid="active-pieces")


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


def _colourbar(figure: Figure, mappable: Any, ax: Axes, label: str) -> None:
    bar = figure.colorbar(mappable, ax=ax, shrink=0.8)
    bar.set_label(label)
