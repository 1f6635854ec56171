"""``occtool convert LOG -o OUT.csv|OUT.mcap``: rewrite a range log as CSV or MCAP."""

from __future__ import annotations

from typing import Any

import click

from occtool.cli.options import config_option, log_options, overwrite_option, refuse_existing


@click.command(short_help="Convert a range log (CSV, MCAP, ...) to CSV or MCAP.")
@click.argument("log", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "-o", "--output", required=True, type=click.Path(dir_okay=False, allow_dash=True),
    help="Output file: .csv (or '-' for CSV on standard output) or .mcap.",
)
@click.option(
    "--to", "target_format", type=click.Choice(["csv", "mcap"]), default=None,
    help="Output format (default: from the output file's extension).",
)
@overwrite_option
@log_options
@config_option
def convert(log: str, output: str, target_format: str | None, overwrite: bool, **kwargs: Any) -> None:
    """Read LOG (any supported format) and write its positions and features to OUTPUT.

    CSV output has columns x, y, z, m, plus position and pose_x, pose_y, pose_z,
    pose_yaw when the log has several positions or poses. MCAP output uses occtool's
    JSON channel (one message per position with its pose), which reads back exactly.
    """
    import logging

    from occtool.cli.options import read_log_from_kwargs
    from occtool.io import write_csv, write_mcap

    if target_format is None:
        lowered = output.lower()
        if lowered.endswith(".mcap"):
            target_format = "mcap"
        elif lowered.endswith((".csv", ".txt")) or output == "-":
            target_format = "csv"
        else:
            raise click.BadParameter("cannot tell the output format: use a .csv or .mcap name or --to", param_hint="-o")
    if target_format == "mcap" and output == "-":
        raise click.BadParameter("MCAP cannot go to standard output: name a file", param_hint="-o")
    refuse_existing(overwrite, output)
    range_log = read_log_from_kwargs(log, kwargs)
    if target_format == "mcap":
        write_mcap(range_log, output)
    else:
        write_csv(range_log, output)
    count = sum(len(p.features) for p in range_log.positions)
    logging.getLogger("occtool").info(
        "wrote %d features at %d position(s) to %s", count, len(range_log.positions), output
    )
