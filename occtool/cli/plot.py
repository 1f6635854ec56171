"""``occtool plot``: draw features, models, navigation maps and comparison reports.

Each subcommand is a thin shell over :mod:`occtool.plot`; the picture's format (PNG,
SVG or PDF) follows the output's extension, and the file is written completely or
not at all.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import click

from occtool.cli.options import (
    LIBRARY_DEFAULTS,
    _compose,
    config_option,
    log_options,
    overwrite_option,
    read_memory_limit_option,
    refuse_existing,
)
from occtool.limits import MAX_ROBOT_SIZE

DEFAULT_DPI = 100.0


def _figure_options(function: Callable[..., Any]) -> Callable[..., Any]:
    return _compose(
        config_option,
        click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
                     help="Image to write: .png, .svg or .pdf."),
        overwrite_option,
        click.option("--dpi", type=click.FloatRange(min=1.0, min_open=False), default=DEFAULT_DPI,
                     show_default=True, help="Resolution, dots per inch (PNG pixels = size x dpi)."),
        click.option("--size", default=None,
                     help="Figure size W,H in inches ('7,6') or pixels ('800,600px'); default per picture."),
        click.option("--title", default=None, help="Title replacing the automatic one."),
    )(function)


def _prepare(output: str, size: str | None, dpi: float, overwrite: bool) -> tuple[float, float] | None:
    """Fail fast, before any input is read: matplotlib present, format known, size valid,
    no existing output with --no-overwrite."""
    from occtool.plot import output_format, parse_size, require_matplotlib

    require_matplotlib()
    output_format(output)
    refuse_existing(overwrite, output)
    return parse_size(size, dpi) if size else None


def _write(figure: Any, output: str) -> None:
    from occtool.plot import save_figure

    save_figure(figure, output)
    click.echo(output)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def plot() -> None:
    """Draw features, models, navigation maps and reports to PNG, SVG or PDF.

    The format follows the output's extension. Axes are in metres, equal aspect,
    REP-103 (x forward, y left). Needs the optional extra: pip install 'occtool[plot]'.
    """


@plot.command("features", short_help="Range data projected on the floor (Figure 5a).")
@click.argument("log", type=click.Path(exists=True, dir_okay=False))
@log_options
@click.option("--position", type=click.IntRange(min=0), default=None,
              help="Draw this robot position only (default: the only one, or all along the path).")
@click.option("--robot-radius", type=click.FloatRange(min=0.0, max=MAX_ROBOT_SIZE),
              default=LIBRARY_DEFAULTS["robot_radius"], show_default=True, help="Radius of the robot disc, metres.")
@_figure_options
def features(log: str, position: int | None, robot_radius: float, output: str, overwrite: bool, dpi: float,
             size: str | None, title: str | None, **kwargs: Any) -> None:
    """Range data of LOG projected on the floor (the paper's Figure 5a).

    Brighter where the evidence is higher, the robot at the centre. A log of several
    positions with poses is drawn in the world frame along the robot's path unless
    --position picks one.
    """
    figure_size = _prepare(output, size, dpi, overwrite)
    from occtool.cli.options import read_log_from_kwargs
    from occtool.plot import DEFAULT_SIZE, features_figure
    from occtool.robot import Robot

    range_log = read_log_from_kwargs(log, kwargs)
    figure = features_figure(range_log, position=position, robot=Robot(radius=robot_radius),
                             size=figure_size or DEFAULT_SIZE, dpi=dpi, title=title)
    _write(figure, output)


@plot.command("model", short_help="The occupancy model: F > level and F at a height (Figure 5b).")
@click.argument("model", type=click.Path(exists=True, dir_okay=False))
@click.option("--level", type=click.FloatRange(0.0, 1.0), default=0.4, show_default=True,
              help="Occupancy level: F > level is drawn as occupied, and contoured on the heat map.")
@click.option("--height", type=float, default=None,
              help="Sensor-frame height h of the heat map, metres (negative below the sensor; "
                   "default: the middle of the robot's body).")
@click.option("--heights", default=None,
              help="Sensor-frame heights of the floor projection, comma-separated metres "
                   "(default: six across the robot's body).")
@click.option("--extent", type=click.FloatRange(min=0.0, min_open=True), default=None,
              help="Half-width of the area drawn, metres (default: the model's range, else 5).")
@click.option("--pieces/--no-pieces", default=False, show_default=True,
              help="Add a panel coloured by which linear piece of the tree is active.")
@click.option("--resolution", type=click.IntRange(min=8, max=2000), default=160, show_default=True,
              help="Heat-map cells along each side.")
@_figure_options
def model(model: str, level: float, height: float | None, heights: str | None, extent: float | None,
          pieces: bool, resolution: int, output: str, overwrite: bool, dpi: float, size: str | None,
          title: str | None) -> None:
    """The occupancy model in MODEL (the paper's Figure 5b), and F at one height.

    Where F > --level, projected on the floor, beside a heat map of F over (x, y) at
    --height; --pieces adds the regions of the tree's linear pieces.
    """
    figure_size = _prepare(output, size, dpi, overwrite)
    from occtool.cli.options import float_list
    from occtool.formats.model import load_model
    from occtool.plot import model_extent, model_figure, model_robot

    fitted = load_model(model)
    robot = model_robot(fitted)
    height_list = float_list(None, None, heights) if heights else None
    figure = model_figure(fitted, level=level, height=height, heights=height_list,
                          extent=extent or model_extent(fitted, level, robot), robot=robot, pieces=pieces,
                          resolution=resolution, source=model, size=figure_size, dpi=dpi, title=title)
    _write(figure, output)


@plot.command("nav", short_help="Navigation polygon, slices and points (Figure 5c).")
@click.argument("maps", metavar="NAV...", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("--features", "features_log", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Range log drawn underneath (the matching position; all positions for several maps).")
@log_options
@click.option("--position", type=click.IntRange(min=0), default=None,
              help="The --features log's position under a single map (when the log has several).")
@click.option("--truth", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Scene truth JSON (occtool simulate) whose obstacles are drawn on top.")
@click.option("--slices/--no-slices", default=True, show_default=True, help="Draw the per-height slices.")
@_figure_options
def nav(maps: tuple[str, ...], features_log: str | None, position: int | None, truth: str | None, slices: bool,
        output: str, overwrite: bool, dpi: float, size: str | None, title: str | None, **kwargs: Any) -> None:
    """Navigation map(s) NAV from occtool extract (the paper's Figure 5c).

    The polygon, per-height slices, obstacle and exploration points, the max-range
    circle and the robot disc, optionally over the features and the true geometry.

    The maps of several positions (a file from `occtool extract DIR/`, several files,
    or a folder of them) are drawn in the world frame along the robot's path: maps
    extracted with --world stay where they are, robot-frame maps are placed at the
    poses of the --features log's positions.
    """
    figure_size = _prepare(output, size, dpi, overwrite)
    from occtool.cli.options import read_log_from_kwargs
    from occtool.plot import (
        DEFAULT_SIZE,
        expand_navigation_paths,
        navigation_figure,
        read_navigation_maps,
    )

    paths = expand_navigation_paths(maps)
    tagged = [pair for path in paths for pair in read_navigation_maps(path)]
    range_log = read_log_from_kwargs(features_log, kwargs) if features_log else None
    scene = None
    if truth:
        from occtool.simulate import load_truth

        scene = load_truth(truth)
    source = str(paths[0]) if len(paths) == 1 else (maps[0] if len(maps) == 1 else "")
    figure = navigation_figure([nav for _, nav in tagged], positions=[number for number, _ in tagged],
                               log=range_log, position=position, truth=scene, slices=slices, source=source,
                               size=figure_size or DEFAULT_SIZE, dpi=dpi, title=title)
    _write(figure, output)


@plot.command("compare", short_help="Parametric and grid polygons, scaling curves.")
@click.argument("report", type=click.Path(exists=True, dir_okay=False))
@click.option("--bench", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Benchmark results JSON (bench/results.json) for the scaling curves.")
@_figure_options
def compare(report: str, bench: str | None, output: str, overwrite: bool, dpi: float, size: str | None,
            title: str | None) -> None:
    """The grid comparison REPORT from occtool compare-grid --json.

    Each model's navigation polygon side by side; time and memory against scene scale
    and feature count come from --bench, on log axes.
    """
    figure_size = _prepare(output, size, dpi, overwrite)
    from occtool.plot import compare_figure, read_json

    document = read_json(report)
    bench_document = read_json(bench) if bench else None
    figure = compare_figure(document, bench=bench_document, source=report, size=figure_size, dpi=dpi, title=title)
    _write(figure, output)


@plot.command("map", short_help="A run's fused map (occtool map), its path and frontiers.")
@click.argument("folder", type=click.Path(exists=True, file_okay=False))
@click.option("--path/--no-path", "draw_path", default=True, show_default=True, help="Draw the run's path.")
@click.option("--frontiers/--no-frontiers", default=True, show_default=True, help="Draw the frontier points.")
@click.option("--walls/--no-walls", default=False, show_default=True,
              help="Draw the world map's wall segments (FOLDER/world.occmap) over the cells.")
@read_memory_limit_option
@_figure_options
def map_picture(folder: str, draw_path: bool, frontiers: bool, walls: bool, memory_limit: str | None, output: str,
                overwrite: bool, dpi: float, size: str | None, title: str | None) -> None:
    """The map FOLDER written by `occtool map`: free, occupied and unknown cells as Nav2
    reads them, the robot's path and the frontier points; with --walls, the wall segments
    of the world map (world.occmap) coloured by how many positions trusted them."""
    figure_size = _prepare(output, size, dpi, overwrite)
    from occtool.plot import DEFAULT_MAP_SIZE, map_figure

    figure = map_figure(folder, size=figure_size or DEFAULT_MAP_SIZE, dpi=dpi, title=title, path=draw_path,
                        frontiers=frontiers, walls=walls, memory_limit=memory_limit)
    _write(figure, output)
