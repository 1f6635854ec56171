"""``occtool compare-grid``: the parametric model against a dense grid and OctoMap."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import click

from occtool.cli.options import (
    config_option,
    extract_options,
    fit_options,
    json_option,
    log_options,
    overwrite_option,
    refuse_existing,
    seed_option,
    write_json_report,
)
from occtool.limits import MAX_REPEATS


def _unique_params(function: Callable[..., Any]) -> Callable[..., Any]:
    """Keep one copy of each option: ``fit_options`` and ``extract_options`` both carry the
    robot's options, and click would otherwise list them twice."""
    params = getattr(function, "__click_params__", [])
    seen: set[str | None] = set()
    unique = []
    for param in params:
        if param.name in seen:
            continue
        seen.add(param.name)
        unique.append(param)
    function.__click_params__ = unique  # type: ignore[attr-defined]
    return function


def _holdout(ctx: click.Context | None, param: click.Parameter | None, value: float) -> float:
    if not 0.0 <= value <= 0.5:
        raise click.BadParameter(f"must lie in [0, 0.5], got {value}")
    return value


@click.command(short_help="Compare the model with occupancy grids.")
@click.argument("log_path", metavar="LOG", type=click.Path(exists=True, dir_okay=False))
@click.option("--resolution", type=click.FloatRange(min=0.0, min_open=True), default=0.05, show_default=True,
              help="Cell edge of the grids, metres.")
@click.option("--octomap", "use_octomap", is_flag=True, default=False,
              help="Also build an OctoMap (needs the extra: pip install 'occtool[octomap]').")
@click.option("--octomap-scans", type=click.IntRange(min=1, max=MAX_REPEATS), default=10, show_default=True,
              help="Insert the features into OctoMap as this many scans (it updates a cell once per scan).")
@click.option("--unknown", type=click.Choice(["free", "occupied"]), default="free", show_default=True,
              help="Read unobserved space in the grids' navigation polygons as free (its prior 0.5, below the "
                   "threshold), or occupied as a careful planner does: rays end at the first cell whose column "
                   "has no observed cell across the robot's body.")
@click.option("--truth", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Scene truth (truth.json from `occtool simulate`) to score the polygons against.")
@click.option("--holdout", type=float, default=0.1, show_default=True, callback=_holdout,
              help="Share of the features held out of every model to score occupancy (ROC AUC).")
@click.option("--repeat", type=click.IntRange(min=1, max=MAX_REPEATS), default=1, show_default=True,
              help="Build and extract each model this many times; report the shortest time.")
@click.option("--position", type=click.IntRange(min=0), default=None,
              help="Robot position of a multi-position log (default: the only one).")
@json_option("the report")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
              help="Draw the navigation polygons to this image (needs the plot extra).")
@overwrite_option
@_unique_params
@fit_options
@extract_options
@log_options
@seed_option
@config_option
def compare_grid(
    log_path: str,
    resolution: float,
    use_octomap: bool,
    octomap_scans: int,
    unknown: str,
    truth: str | None,
    holdout: float,
    repeat: int,
    position: int | None,
    json_path: str | None,
    plot_path: str | None,
    overwrite: bool,
    seed: int,
    **kwargs: Any,
) -> None:
    """Compare the parametric model of LOG with a dense 3D grid (and OctoMap).

    Every model is built from the same features (less the --holdout share) with the same
    sensor model; from each the navigation polygon is extracted with the same threshold,
    heights, robot radius and max range. The grids get the parametric model's prior that
    the robot's footprint is free. Unobserved space reads as free in the grids' polygons
    unless --unknown occupied is given. Reported: samples, build and extraction time, memory,
    agreement with the parametric polygon, ROC AUC of occupancy on held-out features,
    and with --truth IoU and safety violation against the scene.
    """
    import logging

    refuse_existing(overwrite, json_path, plot_path)
    from occtool.cli.options import (
        extract_from_kwargs,
        fit_from_kwargs,
        read_log_from_kwargs,
    )
    from occtool.compare import compare_grid as run_comparison
    from occtool.compare import report_json

    logger = logging.getLogger("occtool.compare")
    regressor = fit_from_kwargs(kwargs, seed=seed)
    # fit_from_kwargs took the robot's options; the navigation uses the same robot.
    navigation = extract_from_kwargs(kwargs, robot=regressor.robot)
    log = read_log_from_kwargs(log_path, kwargs)
    features = log.single(position).features
    scene = None
    if truth is not None:
        from occtool.simulate import load_truth

        scene = load_truth(truth)
    if use_octomap:
        from occtool.grid import octomap_available

        if not octomap_available():
            from occtool.errors import MissingDependencyError

            raise MissingDependencyError("pyoctomap", "octomap", "The OctoMap baseline (--octomap)")
    logger.info("comparing on %d features of %s at %.3g m resolution", len(features), log_path, resolution)
    report = run_comparison(
        features,
        regressor=regressor,
        navigation=navigation,
        resolution=resolution,
        octomap=use_octomap,
        octomap_scans=octomap_scans,
        truth=scene,
        holdout=holdout,
        seed=seed,
        repeat=repeat,
        unknown=unknown,
    )
    report["input"] = str(log_path)
    to_stdout = write_json_report(json_path, report_json(report))
    if plot_path is not None:
        from occtool.plot import compare_figure, save_figure

        save_figure(compare_figure(report, source=str(log_path)), plot_path)
    if not to_stdout:
        from rich.console import Console

        Console().print(report_table(report))


def report_table(report: dict[str, Any]) -> Any:
    """The comparison report as a rich table (one column per model)."""
    from rich.table import Table

    models = report["models"]
    names = list(models)
    settings = report["settings"]
    table = Table(
        title=(
            f"{report['features']} features ({report['features_held_out']} held out), "
            f"grids at {settings['resolution']:g} m, threshold {settings['threshold']:g}, "
            f"max range {settings['max_range']:g} m"
        ),
        caption=(
            "The grids get the parametric model's free prior on the robot's footprint; "
            + (
                "they read unobserved space as occupied (columns unseen across the body band)."
                if settings.get("unknown") == "occupied"
                else "they read unobserved space as free."
            )
        ),
    )
    table.add_column("")
    for name in names:
        table.add_column(name, justify="right")

    def row(label: str, values: list[str]) -> None:
        table.add_row(label, *values)

    row("samples", [f"{models[n]['samples']:,}" for n in names])
    row("build time", [_seconds(models[n]["build_s"]) for n in names])
    row("extract time", [_seconds(models[n]["extract_s"]) for n in names])
    row("memory", [_bytes(models[n]["memory_bytes"]) for n in names])
    row("file", [_bytes(models[n]["file_bytes"]) for n in names])
    row("memory ratio", ["1" if n == "parametric" else f"{report['ratios'][n]['memory']:,.0f}x" for n in names])
    row("time ratio", ["1" if n == "parametric" else f"{report['ratios'][n]['time']:.3g}x" for n in names])
    row("IoU with parametric", ["-" if n == "parametric" else f"{report['agreement'][n]['iou']:.3f}" for n in names])
    row("ROC AUC (held out)", [_number(report["auc"].get(n)) for n in names])
    row("AUC in front of 1st obstacle", [_number(report["auc_front"].get(n)) for n in names])
    if "truth" in report:
        row("IoU with truth", [_number(report["truth"][n]["iou"]) for n in names])
        row("violation", [f"{100 * report['truth'][n]['violation']:.2f}%" for n in names])
    row("polygon area", [f"{models[n]['polygon_area']:.2f} m²" for n in names])
    return table


def _number(value: float | None) -> str:
    return "-" if value is None or value != value else f"{value:.3f}"


def _seconds(value: float) -> str:
    return f"{value * 1000:.1f} ms" if value < 1 else f"{value:.2f} s"


def _bytes(value: int) -> str:
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("KB", 1e3)):
        if value >= size:
            return f"{value / size:.1f} {unit}"
    return f"{value} B"
