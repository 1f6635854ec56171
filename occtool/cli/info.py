"""``occtool info``: a readable summary of a model file, an inverse file or a range log."""

from __future__ import annotations

import click

from occtool.cli.options import log_option


@click.command(short_help="Describe a model file or a range log.")
@click.argument("path", metavar="FILE", type=click.Path(exists=True, dir_okay=False))
@click.option("--pieces/--no-pieces", "show_pieces", default=True, show_default=True,
              help="List the coefficients of every piece.")
@log_option("skip_invalid",
            help="Range log: count invalid rows/points in a note instead of stopping at the first.")
@log_option("no_return_range",
            help="Range log: count laser beams that returned nothing as free rays at this range "
                 "(as fit --no-return-range does).")
def info(path: str, show_pieces: bool, skip_invalid: bool, no_return_range: float | None) -> None:
    """Summarise FILE: a model or inverse file (pieces, tree, constraints, fit error,
    samples, run) or any range log the readers understand."""
    from rich.console import Console

    from occtool.formats.model import read_any

    console = Console()
    found = read_any(path)
    if found is None:
        from occtool.io import describe_log

        console.print(describe_log(path, skip_invalid=skip_invalid, no_return_range=no_return_range))
        return
    kind, obj = found
    if kind == "model":
        console.print(_model_summary(path, obj, show_pieces))
    else:
        console.print(_inverse_summary(path, obj, show_pieces))


def _pieces_table(tree, title: str):
    from rich.table import Table

    table = Table(title=title, show_lines=False)
    table.add_column("piece", justify="right")
    names = list(tree.pieces()[0])
    for name in names:
        table.add_column(name, justify="right")
    for i, piece in enumerate(tree.pieces()):
        table.add_row(f"p{i}", *(f"{piece[n]:.4g}" for n in names))
    return table


def _model_summary(path: str, model, show_pieces: bool):
    from rich.console import Group
    from rich.table import Table

    tree = model.tree_
    basis = "a1 cos(alpha) + a2 sin(alpha) + b h + c r + d" if tree.basis == "trig" else "a alpha + b h + c r + d"
    table = Table(title=f"occtool model: {path}", show_header=False)
    table.add_column("key", style="bold")
    table.add_column("value")
    table.add_row("pieces", f"{tree.n_pieces} ({basis})")
    table.add_row("tree", f"depth {tree.depth()}: {tree.describe()}")
    table.add_row("constraints", f"c >= {model.c_min:g}, |dF/dalpha| <= {model.a_max:g}, |b| <= {model.b_max:g}")
    table.add_row("slope bounds", ", ".join(f"{k} {v:.4g}" for k, v in model.slope_bounds_.items()))
    table.add_row(
        "fit error", f"RMSE {model.rmse_:.4f}, loss {model.loss_:.5f} ({model.loss} loss), {model.n_sweeps_} sweeps"
    )
    counts = ", ".join(f"{k} {v}" for k, v in model.sample_counts_.items() if v)
    table.add_row("training", f"{model.n_features_} features -> {model.n_samples_} samples ({counts})")
    table.add_row("input sha256", model.features_digest_)
    guard = model.guard_
    table.add_row("return guard", "none (fitted with --no-guard, or an older file)" if guard is None else
                  f"{guard.n_returns_bins} of {guard.bins} pan bins hold returns (evidence >= {guard.level:g}), "
                  f"nearest {float(guard.distance.min()):.3f} m" if guard.n_returns_bins else
                  f"no returns in the body band (of {guard.bins} pan bins)")
    sensor = model.sensor_
    table.add_row("sensor model", f"depth error {sensor.depth_error:g}, near {sensor.near_positions} x r with "
                  f"{sensor.near_values} x m, floor {sensor.floor}, footprint {sensor.footprint_samples}, "
                  f"background {sensor.background_samples}")
    robot = model.robot_
    table.add_row("robot", f"radius {robot.radius:g} m, sensor height {robot.sensor_height:g} m, body height "
                  f"{robot.body_height:g} m, clearance {robot.ground_clearance:g} m")
    run = getattr(model, "run_", {})
    if run:
        table.add_row(
            "run", ", ".join(f"{k} {v}" for k, v in run.items() if k in ("seconds", "date", "occtool_version", "host"))
        )
    return Group(table, _pieces_table(tree, "pieces")) if show_pieces else table


def _inverse_summary(path: str, inverse, show_pieces: bool):
    from rich.console import Group
    from rich.table import Table

    table = Table(title=f"occtool inverse model: {path}", show_header=False)
    table.add_column("key", style="bold")
    table.add_column("value")
    table.add_row("function", "r = F^-1(alpha, h, m)")
    table.add_row("pieces", f"{inverse.n_pieces} ({inverse.basis} basis)")
    table.add_row("tree", f"depth {inverse.depth()}: {inverse.describe()}")
    return Group(table, _pieces_table(inverse, "inverse pieces")) if show_pieces else table
