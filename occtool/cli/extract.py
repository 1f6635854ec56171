"""``occtool extract``: the navigation polygon, obstacle and exploration points as GeoJSON."""

from __future__ import annotations

from typing import Any

import click

from occtool.cli.options import (
    ROBOT_FIELDS,
    config_option,
    extract_from_kwargs,
    extract_options,
    geojson_options,
    jobs_options,
    output_option,
    overwrite_option,
    refuse_existing,
)


def _is_model_set(path: str) -> bool:
    from pathlib import Path

    return Path(path).is_dir() or Path(path).name == "index.json"


def _robot_given(ctx: click.Context) -> set[str]:
    """The robot options set on the command line or in a --config file (not defaults)."""
    from click.core import ParameterSource

    return {
        name for name in ROBOT_FIELDS
        if ctx.get_parameter_source(name) not in (ParameterSource.DEFAULT, None)
    }


@click.command(short_help="Extract the navigation polygon and points as GeoJSON.")
@click.argument("models", metavar="MODEL...", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=True))
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
@jobs_options("the number of position models whose navigation maps are extracted at once")
@overwrite_option
@config_option
def extract(
    models: tuple[str, ...], output: str | None, ignore_bounds: bool, straight_line: bool, world: bool,
    overwrite: bool, jobs: int | None, scheduler: str | None, **kwargs: Any,
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
    by its position's pose. Several model sets (or a folder of them, as `occtool fit A B
    -o DIR/` writes) need -o OUT/: one sub-folder per set. Positions run on -j local
    processes or a Dask cluster (--scheduler); a failing position is reported and the
    others are written.

    The robot's geometry defaults to the one the model was fitted for; the --robot-radius,
    --sensor-height, --body-height and --ground-clearance given override it.

    Coordinates are x, y metres in the robot frame (base_link), not longitude/latitude;
    the collection's properties say so. Written to standard output without -o.
    """
    import logging
    import os
    from pathlib import Path

    from occtool.formats.geojson import write_navigation
    from occtool.modelset import navigation_map_of_file

    logger = logging.getLogger("occtool.extract")
    given = _robot_given(click.get_current_context())
    options = extract_from_kwargs(kwargs)
    navigation = {
        **{k: v for k, v in options.items() if k != "robot"}, "robot": options["robot"],
        # The model was fitted for a robot (its floor, its body): keep what the user did not override.
        "robot_overrides": {field: getattr(options["robot"], field) for name, field in ROBOT_FIELDS.items()
                            if name in given},
        "straight_line": straight_line, "bounds": not ignore_bounds,
    }
    written = {
        "sequence": kwargs["sequence"], "indent": kwargs["indent"], "precision": kwargs["precision"],
        "include_slices": kwargs["include_slices"], "overwrite": overwrite,
    }
    paths = list(models)
    if len(paths) == 1 and not _is_model_set(paths[0]):
        if world:
            raise click.UsageError("--world needs a model set (a folder from `occtool fit -o DIR/`) with poses")
        if jobs is not None or scheduler is not None:
            logger.debug("-j/--scheduler apply to model sets only")
        refuse_existing(overwrite, output)
        nav, messages = navigation_map_of_file(paths[0], **navigation)
        for level, text in messages:
            logger.log(level, "%s", text)
        write_navigation(nav, output or "-", **written)
        return
    for path in paths:
        if not _is_model_set(path):
            raise click.UsageError(f"{path} is not a model set: several MODELs must all be model sets")

    from occtool.cli.fit import _progress_bar, _report
    from occtool.modelset import extract_model_set

    per_position = output is not None and (output.endswith(("/", os.sep)) or Path(output).is_dir())
    written.pop("overwrite")
    with _progress_bar("extracting") as progress:
        summary = extract_model_set(paths, output, per_position=per_position, world=world, jobs=jobs,
                                    scheduler=scheduler, overwrite=overwrite, progress=progress, geojson=written,
                                    **navigation)
    _report(summary, logger, "extracted")
