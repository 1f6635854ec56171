"""``occtool map``: one world map of a whole log, for Nav2, Foxglove and GIS."""

from __future__ import annotations

from typing import Any

import click

from occtool.cli.options import (
    KEYFRAME_SHARE_HELP,
    config_option,
    fit_options,
    jobs_options,
    log_options,
    memory_limit_option,
    overwrite_option,
    seed_option,
)
from occtool.cli.register_options import register_options


def _occupancy(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> float:
    if not 0.0 < float(value) < 1.0:
        raise click.BadParameter(f"an occupancy threshold must lie strictly between 0 and 1, got {value}")
    return float(value)


#: What a model set's map takes from the command line: the map's own options and the robot's
#: (its navigation maps'); the fit, log, keyframe and registration options apply to a log.
MODEL_SET_OPTIONS = frozenset({
    "sources", "output", "resolution", "nav2_mode", "threshold", "combination", "max_range", "simplify", "precision",
    "origin", "mcap", "overwrite", "config", "register", "jobs", "scheduler",
})
#: The robot options and the :class:`occtool.robot.Robot` fields they set.
ROBOT_FIELDS = {"robot_radius": "radius", "sensor_height": "sensor_height", "body_height": "body_height",
                "ground_clearance": "ground_clearance"}


def _choice(choice: dict[str, Any] | None) -> str:
    """How a 3D map's cell size was chosen, for the log."""
    if not choice or "inner_auc" not in choice:
        return (choice or {}).get("why", "given")
    scores = ", ".join(f"{size} m {auc:.3f}" for size, auc in choice["inner_auc"].items())
    return f"held-out AUC on {choice['held_out_positions']} of its {choice['positions']} positions: {scores}"


def _given(ctx: click.Context) -> dict[str, click.Parameter]:
    """The parameters set on the command line or in a --config file (not left at their defaults)."""
    from click.core import ParameterSource

    return {p.name: p for p in ctx.command.params
            if p.name and ctx.get_parameter_source(p.name) not in (ParameterSource.DEFAULT, None)}


def _model_set_robot(ctx: click.Context, kwargs: dict[str, Any]) -> dict[str, float]:
    """The robot fields a model set's map overrides; a usage error naming the first option
    given that cannot apply to a set (its models are fitted already)."""
    given = _given(ctx)
    for name, param in given.items():
        if name in MODEL_SET_OPTIONS or name in ROBOT_FIELDS:
            continue
        flags = param.opts if not (param.secondary_opts and ctx.params.get(name) is False) else param.secondary_opts
        flag = max(flags, key=len) if flags else name
        raise click.UsageError(f"{flag} applies to a log, not to a model set (its models are fitted already)", ctx)
    return {field: kwargs[name] for name, field in ROBOT_FIELDS.items() if name in given}


@click.command(short_help="Fuse every position of a log into one world map (Nav2, Foxglove, GeoJSON).")
@click.argument("sources", metavar="LOG|MODELS", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=True))
@click.option("-o", "--output", required=True, type=click.Path(file_okay=False),
              help="Output folder (created if missing).")
@click.option("--resolution", type=click.FloatRange(min=0.0, min_open=True, max=100.0), default=0.05,
              show_default=True, help="Cell size of the Nav2 map and the Foxglove grid, metres.")
@click.option("--nav2-mode", type=click.Choice(["trinary", "scale"]), default="trinary", show_default=True,
              help="The Nav2 map's mode: trinary writes map.pgm (free / occupied / unknown); scale writes "
                   "map.png with the fused occupancy graded between free and occupied, unknown transparent "
                   "(needs Pillow: the png extra).")
@click.option("--threshold", type=float, default=0.6, show_default=True, callback=_occupancy,
              help="Fused occupancy at or above which a place is occupied, in (0, 1): it cuts each "
                   "position's navigation polygon (navigation.geojson) and, in fusing, marks the occupied margin "
                   "in front of a position's first obstacles that is left to the other positions. It does not "
                   "grade the Nav2 map: map.pgm is occupied where the world "
                   "map's occupancy reaches 0.65 and free where it is at most 0.35 (unknown between), and "
                   "map.yaml says occupied_thresh 0.65, free_thresh 0.196, which is how map_server reads "
                   "those pixels (not map_saver's old 0.25, which reads unknown as free).")
@click.option("--keyframe-share", type=click.FloatRange(min=0.0, max=1.0), default=0.05, show_default=True,
              help=KEYFRAME_SHARE_HELP + " 0 fits every position.")
@click.option("--combination", type=click.Choice(["log_odds", "dempster_shafer", "mean"]), default="log_odds",
              show_default=True, help="How the positions that observed a place are combined.")
@click.option("--max-range", type=click.FloatRange(min=0.0, min_open=True), default=1.5, show_default=True,
              help="Radius of each position's navigation polygon, metres.")
@click.option("--simplify", type=click.FloatRange(min=0.0), default=None, metavar="METRES",
              help="Simplify the navigation polygons in the GeoJSON to this tolerance.")
@click.option("--precision", type=click.IntRange(min=0, max=17), default=None,
              help="Decimal places of the GeoJSON coordinates (default: full precision).")
@click.option("--origin", default=None, metavar="LAT,LON[,HEADING]",
              help="Write the GeoJSON in WGS84 longitude/latitude: the map origin's latitude and longitude "
                   "and the compass bearing of the map's +x axis, degrees (default 90: x east). Needs the geo extra.")
@click.option("--mcap/--no-mcap", default=True, show_default=True,
              help="Write map.mcap for Foxglove (needs the protobuf extra).")
@click.option("--world", "world", type=click.Choice(["auto", "2d", "3d"]), default="auto", show_default=True,
              help="The world map's kind. 3d: surfaces (planar patches) and the space the rays crossed, in x, y, z "
                   "(world.occmap version 6; occtool query answers at x, y, z in the frame of the log's poses) and "
                   "map.pgm its body band over the ground found per tile (a ramp is ground, a table top an "
                   "obstacle). 2d: the body band's walls (version 4). auto: 3d for a depth camera or a 3D lidar "
                   "(returns above and below the sensor), 2d for a 2D laser.")
@click.option("--world-resolution", type=click.FloatRange(min=0.01, max=10.0), default=None, metavar="METRES",
              help="Cell size of a 3D world map [default: chosen among 0.1, 0.2 and 0.4 m by holding out "
                   "blocks of the log's own positions and scoring each on them; summary.json says which].")
@fit_options
@log_options
@register_options
@seed_option
@overwrite_option
@memory_limit_option
@jobs_options("the number of tasks (keyframes' fits, navigation maps, bands of raster rows) run at once",
              subject="Large maps", default="1, this process")
@config_option
def map_command(sources: tuple[str, ...], output: str, resolution: float, nav2_mode: str, threshold: float,
                keyframe_share: float,
                combination: str, max_range: float,
                simplify: float | None, precision: int | None, origin: str | None, mcap: bool, world: str,
                world_resolution: float | None, seed: int, overwrite: bool, memory_limit: str | None,
                jobs: int | None, scheduler: str | None, **kwargs: Any) -> None:
    """Fuse every robot position of LOG (fitted here with the fit options) or of MODELS (a
    folder written by `occtool fit LOG -o MODELS/`) into one world-frame map and write, in
    the output folder: map.yaml + map.pgm (Nav2 map_server, trinary; map.png with --nav2-mode
    scale), world.occmap (the world map, for occtool query), map.mcap (Foxglove:
    foxglove.Grid on /map, foxglove.SceneUpdate per position on /positions), the GeoJSON
    layers navigation.geojson (polygons), obstacles.geojson and frontiers.geojson (points),
    and summary.json.

    A depth camera or a 3D lidar gets a 3D world map (--world): the surfaces and the space
    every ray crossed, in x, y, z; map.pgm is its body band over the ground under it.

    Several logs (day1.log day2.log) whose poses share a frame map as one log, their
    positions one after the other; several point clouds (a.pcd b.pcd) as one scan sequence,
    registered when they have no poses.

    Each local model speaks only where its position observed (in front of its first
    obstacle, within its reach); places no position observed stay unknown (205 in the
    Nav2 map), never free. For a 2D laser give its height: --sensor-height 0.3
    --body-height 0.5 --no-return-range 5 (docs/map.md).

    With -j N or --scheduler ADDRESS (a Dask cluster) the keyframes' fits, the navigation
    maps and the raster's bands of rows run as tasks there; the files are the same bytes.

    MODELS were fitted already: the robot options given replace the fitted robot's in the
    navigation maps (the navigation region, obstacles and frontiers), and the fit, log,
    keyframe and registration options are refused.
    """
    import logging
    from pathlib import Path

    from occtool import fuse
    from occtool.cli.options import fit_from_kwargs, pop_log_options, read_log_from_kwargs
    from occtool.features import log_notes

    logger = logging.getLogger("occtool.map")
    georeference = None
    if origin is not None:
        from occtool.errors import InputError
        from occtool.formats.wgs84 import Georeference, parse_origin

        try:
            georeference = Georeference(*parse_origin(origin))
        except InputError as exc:
            raise click.BadParameter(str(exc), param_hint="--origin") from None
        georeference.to_lonlat([[0.0, 0.0]])  # a missing pyproj is reported before any work
    if nav2_mode == "scale":
        try:
            import PIL  # noqa: F401  (checked before the fit, not after it)
        except ImportError:
            raise click.ClickException("--nav2-mode scale writes a PNG and needs Pillow: "
                                       "pip install 'occtool[png]'") from None
    if not overwrite:
        for path in fuse.output_paths(output, nav2_mode):
            if path.exists():
                raise click.ClickException(f"{path} exists already (pass --overwrite to replace it)")
    if Path(output).exists() and not Path(output).is_dir():
        raise click.ClickException(f"{output} exists and is not a folder")
    written: dict[str, Any] = {
        "resolution": resolution, "nav2_mode": nav2_mode, "threshold": threshold, "combination": combination,
        "max_range": max_range, "simplify": simplify, "precision": precision, "georeference": georeference,
        "mcap": mcap, "overwrite": overwrite, "jobs": 1 if jobs is None else jobs, "scheduler": scheduler}
    from occtool.io.scans import is_log_folder

    source = sources[0]  # several files: one scan sequence, each file a scan
    # A folder is a model set unless it is read as a log (scans, depth frames) and holds no index.
    folder = Path(source).is_dir() and ((Path(source) / "index.json").exists() or not is_log_folder(source))
    if len(sources) == 1 and (folder or Path(source).name == "index.json"):
        if kwargs.get("register"):
            raise click.ClickException("--register applies to a log, not to a model set (its poses are fitted in)")
        robot = _model_set_robot(click.get_current_context(), kwargs)
        result = fuse.map_model_set(source, output, robot_overrides=robot, **written)
        logger.info("%d models read from %s", len(result.models), source)
    else:
        from occtool.register import RegistrationSettings

        ctx = click.get_current_context()
        estimator = fit_from_kwargs(kwargs, seed=seed)
        registration = RegistrationSettings(loop_closure=kwargs.pop("loop_closure", True))
        register = kwargs.pop("register", None)
        read_options = pop_log_options(kwargs)
        log = read_log_from_kwargs(source, dict(read_options)) if str(source) == "-" else \
            source if len(sources) == 1 else list(sources)
        result = fuse.map_log(log, output, estimator=estimator, read_options=read_options, register=register,
                              registration=registration, keyframe_share=keyframe_share, **written,
                              heights_from_data=not {"sensor_height", "body_height"} & set(_given(ctx)),
                              world=world, world_resolution=world_resolution, seed=seed,
                              memory_limit=memory_limit, lean=True)
        report = result.report
        assert report is not None
        log_notes(logger, Path(source).name, report.notes)
        for index, message in report.skipped:
            logger.warning("position %d skipped: %s", index, message)
        logger.info("%d positions fitted in %.1f s (%d covered by earlier keyframes, not fitted)", report.positions,
                    report.fit_seconds, len(report.not_keyframes))
    summary = result.summary
    world_map = summary["world_map"]
    parts = (f"{world_map['segments']} wall segments" if world_map["kind"] == "2d" else
             f"3D, {world_map['patches']} surface patches in {world_map['resolution']:g} m cells "
             f"({_choice(world_map.get('resolution_choice'))})")
    logger.info("fused map: %d positions, %.1f KB; world map %s: %s, %.1f KB; raster %dx%d: %s",
                summary["positions"], summary["fused_map_bytes"] / 1e3, Path(output) / "world.occmap",
                parts, world_map["bytes"] / 1e3, summary["raster"]["columns"],
                summary["raster"]["rows"], summary["raster"]["cells"])
    for path in result.written:
        logger.debug("wrote %s", path)
