"""``occtool extract``: the navigation polygon, obstacle and exploration points as GeoJSON."""

from __future__ import annotations

from typing import Any

import click

from occtool.cli.options import (
    config_option, extract_from_kwargs, extract_options, geojson_options, output_option, overwrite_option,
    refuse_existing,
)


def _is_model_set(path: str) -> bool:
    from pathlib import Path

    return Path(path).is_dir() or Path(path).name == "index.json"


def _robot_given(ctx: click.Context) -> set[str]:
    """The robot options set on the command line or in a --config file (not defaults)."""
    from click.core import ParameterSource

    names = ("robot_radius", "sensor_height", "body_height", "ground_clearance")
    return {
        name for name in names
        if ctx.get_parameter_source(name) not in (ParameterSource.DEFAULT, None)
    }


@click.command(short_help="Extract the navigation polygon and points as GeoJSON.")
@click.argument("model", type=click.Path(exists=True, dir_okay=True))
@output_option
@extract_options
@geojson_options
@click.option("--ignore-bounds", is_flag=True, default=False,
              help="Cut at the given heights only, with no bounds between them (the paper's plain "
                   "extraction: an obstacle between two heights may be missed); the return guard still holds.")
@click.option("--straight-line/--no-straight-line", default=True, show_default=True,
              help="Keep only what the robot reaches in a straight line with its body clear (the paper's "
                   "promise), or every point where the body fits.")
@click.option("--world", is_flag=True, default=False,
              help="Model set: move each position's map into the world (map) frame by its pose.")
@overwrite_option
@config_option
def extract(
    model: str, output: str | None, ignore_bounds: bool, straight_line: bool, world: bool, overwrite: bool,
    **kwargs: Any,
) -> None:
    """Extract the navigation map of MODEL (a model file from `occtool fit`, or an inverse).

    At --threshold and each height of --heights the inverted model is swept over the pan
    angle; the polygons are shrunk by --robot-radius, intersected and clipped to the
    --max-range circle. Obstacle points lie on the polygon's boundary inside the circle,
    exploration points on the circle where the polygon reaches it. The map holds between
    the heights and rays too: the model's pieces bound the free distance over every box of
    pan angle x height exactly, and it keeps the robot's radius from every return the
    model's guard holds (docs/navigation.md).

    MODEL may be a model set (a folder from `occtool fit -o DIR/`, or its index.json): one
    map per position, all in one file with each feature's "position" (or, with -o DIR/,
    one DIR/nav_NNNN.geojson per position). --world moves each map into the world frame
    by its position's pose.

    The robot's geometry defaults to the one the model was fitted for; the --robot-radius,
    --sensor-height, --body-height and --ground-clearance given override it.

    Coordinates are x, y metres in the robot frame (base_link), not longitude/latitude;
    the collection's properties say so. Written to standard output without -o.
    """
    import logging
    import os
    import warnings
    from dataclasses import replace
    from pathlib import Path

    from occtool.errors import InputError
    from occtool.features import Pose
    from occtool.io.geojson import write_navigation, write_navigation_set
    from occtool.io.model import read_model_set, read_navigable
    from occtool.navigation import NavigationWarning, navigation_map

    logger = logging.getLogger("occtool.extract")
    given = _robot_given(click.get_current_context())
    options = extract_from_kwargs(kwargs)
    written = {
        "sequence": kwargs["sequence"], "indent": kwargs["indent"], "precision": kwargs["precision"],
        "include_slices": kwargs["include_slices"], "overwrite": overwrite,
    }

    def one_map(path: Any) -> Any:
        navigable = read_navigable(path)
        model_robot = navigable.robot
        settings = dict(options)
        if model_robot is not None:
            # The model was fitted for a robot (its floor, its body): keep what the user did not override.
            fields = {"robot_radius": "radius", "sensor_height": "sensor_height", "body_height": "body_height",
                      "ground_clearance": "ground_clearance"}
            settings["robot"] = replace(
                model_robot,
                **{field: getattr(options["robot"], field) for name, field in fields.items() if name in given},
            )
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", NavigationWarning)
            nav = navigation_map(navigable.inverse_range, straight_line=straight_line,
                                 **navigable.navigation_options(bounds=not ignore_bounds), **settings)
        for warning in caught:
            logger.warning("%s: %s", path, warning.message)
        if nav.margin > 0:
            logger.info(
                "%s: cut at %d heights, threshold %.3g lowered by %.3g to %.3g so the map holds between them",
                path, len(nav.slice_heights), nav.threshold, nav.margin, nav.effective_threshold,
            )
        logger.info(
            "%s: navigation polygon %.3g m2, %d obstacle and %d exploration points",
            path, nav.polygon.area, len(nav.obstacle_points), len(nav.exploration_points),
        )
        return nav

    if not _is_model_set(model):
        if world:
            raise click.UsageError("--world needs a model set (a folder from `occtool fit -o DIR/`) with poses")
        refuse_existing(overwrite, output)
        write_navigation(one_map(model), output or "-", **written)
        return

    folder, entries = read_model_set(model)
    to_folder = output is not None and (output.endswith(("/", os.sep)) or Path(output).is_dir())
    if to_folder:
        refuse_existing(overwrite, *(Path(output) / f"nav_{entry['position']:04d}.geojson" for entry in entries))
    else:
        refuse_existing(overwrite, output)
    maps = []
    for entry in entries:
        nav = one_map(folder / entry["file"])
        if world:
            if entry.get("pose") is None:
                raise InputError(f"{folder / 'index.json'}: position {entry['position']} has no pose for --world")
            try:
                pose = Pose.from_dict(entry["pose"])
            except (TypeError, ValueError):
                index = folder / "index.json"
                raise InputError(f"{index}: position {entry['position']}'s pose is not numbers") from None
            nav = nav.in_world(pose)
        maps.append((entry["position"], nav))
    if to_folder:
        if not Path(output).is_dir():
            raise InputError(f"output folder {output} does not exist")
        for position, nav in maps:
            write_navigation(nav, Path(output) / f"nav_{position:04d}.geojson", **written)
    else:
        write_navigation_set(maps, output or "-", **written)
