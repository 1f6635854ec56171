"""Whole figures: the paper's Figure 5 a, b and c, and the grid comparison."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from occtool.errors import InputError, ModelFormatError
from occtool.features import Pose, RangeLog
from occtool.plot._canvas import (
    DEFAULT_DPI,
    DEFAULT_SIZE,
    MODEL_COLOURS,
    NAVIGATION_COLOUR,
    ROBOT_COLOUR,
    FloatArray,
    new_figure,
)
from occtool.plot._drawing import (
    _colourbar,
    _finish_metric_axes,
    _finite,
    _log_in_world,
    _scatter_evidence,
    _set_square_limits,
    draw_active_pieces,
    draw_features,
    draw_heatmap,
    draw_navigation,
    draw_occupied_projection,
    draw_robot,
    draw_scaling,
    draw_truth,
    geometry_path,
)
from occtool.plot._probing import _model_summary, active_piece_function, model_piece_count
from occtool.plot._reading import report_polygons, scaling_series
from occtool.robot import Robot

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

    from occtool.navigation import NavigationMap


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
                             "pick one with position=N")
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
        raise InputError("this model does not tell which linear piece is active, so they cannot be drawn (pieces=True)")
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
            raise InputError(f"{len(maps)} robot-frame navigation maps but no pose for each: give features= "
                             "(a log with the posed positions they were extracted from), or extract with world=True")
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
    settings: Mapping[str, Any] = report["settings"] if isinstance(report.get("settings"), Mapping) else {}
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
    agreement: Mapping[str, Any] = report["agreement"] if isinstance(report.get("agreement"), Mapping) else {}
    truth: Mapping[str, Any] = report["truth"] if isinstance(report.get("truth"), Mapping) else {}
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
        scores: Mapping[str, Any] = truth[name] if isinstance(truth.get(name), Mapping) else {}
        if isinstance(scores.get("iou"), (int, float)) and isinstance(scores.get("violation"), (int, float)):
            lines.append(f"truth IoU {scores['iou']:.2f}, violation {scores['violation']:.3f} m²")
        _finish_metric_axes(ax, "\n".join(lines))
