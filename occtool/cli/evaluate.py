"""``occtool evaluate``: score a navigation polygon against a scene's truth."""

from __future__ import annotations

import click

from occtool.cli.options import config_option, json_option, write_json_report
from occtool.limits import MAX_DISTANCE, MAX_RAYS, MAX_ROBOT_SIZE


@click.command("evaluate")
@click.argument("navigation", type=click.Path(exists=True, dir_okay=False), metavar="NAV.geojson")
@click.argument("truth", type=click.Path(exists=True, dir_okay=False), metavar="TRUTH.json")
@click.option("--robot-radius", type=click.FloatRange(min=0.0, max=MAX_ROBOT_SIZE), default=None,
              help="Robot radius for the truth, metres (default: the GeoJSON's, else the truth's).")
@click.option("--max-range", type=click.FloatRange(min=0.0, max=MAX_DISTANCE, min_open=True), default=None,
              help="Max range of the navigation map, metres (default: the GeoJSON's).")
@click.option("--rays", type=click.IntRange(min=8, max=MAX_RAYS), default=7200, show_default=True,
              help="Rays of the angular sweep tracing the reachable region.")
@click.option("--point-tolerance", type=click.FloatRange(min=0.0), default=0.05, show_default=True,
              help="Metres short of the max range that still count as open, judging the map's points.")
@json_option("the scores")
@config_option
def evaluate(navigation: str, truth: str, robot_radius: float | None, max_range: float | None, rays: int,
             point_tolerance: float, json_path: str | None) -> None:
    """Compare the navigation polygon in NAV.geojson with the region reachable in TRUTH.json.

    IoU is area(nav & truth) / area(nav | truth); violation is the share of the
    polygon's area where the robot's body would touch an obstacle.
    """
    import json
    import logging
    import math

    from occtool.errors import InputError
    from occtool.formats.geojson import read_navigation
    from occtool.scoring import evaluate_navigation, robot_frame_points, robot_frame_polygon
    from occtool.simulate import load_truth

    nav = read_navigation(navigation)
    scene = load_truth(truth)
    polygon, obstacle_points, exploration_points = nav.polygon, nav.obstacle_points, nav.exploration_points
    if nav.frame_id != "base_link":
        if nav.pose is None:
            raise InputError(f"{navigation} is in the {nav.frame_id!r} frame without the robot's pose: "
                             "extract it in base_link to evaluate it")
        polygon = robot_frame_polygon(polygon, nav.pose)
        obstacle_points = robot_frame_points(obstacle_points, nav.pose)
        exploration_points = robot_frame_points(exploration_points, nav.pose)
    radius = robot_radius if robot_radius is not None else _known(nav.robot_radius)
    limit = max_range if max_range is not None else _known(nav.max_range)
    if limit is None:
        raise InputError(f"{navigation} does not state its max_range: pass --max-range")
    logger = logging.getLogger("occtool.evaluate")
    for key in ("sensor_height", "body_height"):
        stated, truth_value = getattr(nav, key), getattr(scene.robot, key)
        if math.isfinite(stated) and not math.isclose(stated, truth_value, abs_tol=1e-6):
            logger.warning("%s: %s is %g m, the truth's robot has %g m", navigation, key, stated, truth_value)
    result = evaluate_navigation(polygon, scene, robot_radius=radius, max_range=limit, n_rays=rays,
                                 obstacle_points=obstacle_points, exploration_points=exploration_points,
                                 point_tolerance=point_tolerance)
    if write_json_report(json_path, json.dumps(
            {"navigation": navigation, "truth": truth, "scene": scene.name, **result.to_dict()}, indent=1)):
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"{navigation} against {truth} ({scene.name or 'scene'})")
    table.add_column("measure")
    table.add_column("value", justify="right")
    table.add_column("meaning")
    table.add_row("IoU", f"{result.iou:.4f}", "area(nav & truth) / area(nav | truth)")
    table.add_row("violation", f"{result.violation:.4f}", "share of nav where the body hits an obstacle")
    table.add_row("coverage", f"{result.coverage:.4f}", "share of the truth inside nav")
    table.add_row("excess", f"{result.excess:.4f}", "share of nav outside the truth")
    if result.obstacle_accuracy is not None:
        table.add_row("obstacle points", f"{result.obstacle_accuracy:.4f}", "share facing a true obstacle in range")
    if result.exploration_accuracy is not None:
        table.add_row(
            "exploration points", f"{result.exploration_accuracy:.4f}", "share facing open space to max range"
        )
    table.add_row("area", f"{result.area:.3f} m²", "navigation polygon")
    table.add_row("truth area", f"{result.truth_area:.3f} m²", "reachable in a straight line")
    table.add_row("robot radius", f"{result.robot_radius:g} m", "")
    table.add_row("max range", f"{result.max_range:g} m", "")
    Console().print(table)


def _known(value: float) -> float | None:
    """A parameter the file records, or ``None`` where it records none (NaN)."""
    return None if value != value else float(value)
