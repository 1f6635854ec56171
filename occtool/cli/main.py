"""The ``occtool`` command group.

Subcommands live one per module in this package and are imported only when invoked,
so ``occtool --help`` stays instant. Library errors (:class:`occtool.errors.OcctoolError`)
and file-system errors become a one-line ``Error: ...`` and exit status 1; usage errors
exit with 2, as click does.
"""

from __future__ import annotations

import importlib
import logging
import sys
from typing import Any

import click

from occtool import __version__

# name -> (module, function, one-line help). Order is the order of `occtool --help`.
COMMANDS: dict[str, tuple[str, str, str]] = {
    "simulate": ("occtool.cli.simulate", "simulate", "Generate a synthetic scene: features.csv and truth.json."),
    "fit": ("occtool.cli.fit", "fit", "Fit a parametric occupancy model to a range log."),
    "info": ("occtool.cli.info", "info", "Describe a model file or a range log."),
    "invert": ("occtool.cli.invert", "invert", "Write the inverted model r = F^-1(alpha, h, m)."),
    "extract": ("occtool.cli.extract", "extract", "Extract the navigation polygon and points as GeoJSON."),
    "evaluate": ("occtool.cli.evaluate", "evaluate", "Score a navigation polygon against a scene's truth."),
    "map": ("occtool.cli.map", "map_command", "Fuse every position of a log into one world map (Nav2, Foxglove)."),
    "evaluate-log": ("occtool.cli.evaluate_log", "evaluate_log", "Score a log's fused map against a grid on held-out scans."),
    "compare-grid": ("occtool.cli.compare_grid", "compare_grid", "Compare the model with occupancy grids."),
    "convert": ("occtool.cli.convert", "convert", "Convert a range log (CSV, MCAP, ...) to CSV or MCAP."),
    "plot": ("occtool.cli.plot", "plot", "Draw features, models, navigation maps and reports."),
}


class LazyGroup(click.Group):
    """A group that imports a subcommand's module only when that subcommand runs."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS:
            return None
        module_name, attribute, _ = COMMANDS[name]
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                return None
            raise
        return getattr(module, attribute)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][2]) for name in self.list_commands(ctx)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)

    def invoke(self, ctx: click.Context) -> Any:
        from occtool.errors import OcctoolError

        try:
            return super().invoke(ctx)
        except OcctoolError as exc:
            raise click.ClickException(str(exc)) from exc
        except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError, FileExistsError) as exc:
            raise click.ClickException(_describe_os_error(exc)) from exc
        except MemoryError as exc:
            raise click.ClickException("out of memory: try fewer features or a coarser resolution") from exc


def _describe_os_error(exc: OSError) -> str:
    if exc.filename is not None and exc.strerror:
        return f"{exc.strerror}: {exc.filename}"
    return str(exc)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", "verbosity", count=True, help="More log messages (repeatable).")
@click.option("-q", "--quiet", "quietness", count=True, help="Fewer log messages (repeatable).")
@click.version_option(__version__, prog_name="occtool")
@click.pass_context
def cli(ctx: click.Context, verbosity: int, quietness: int) -> None:
    """Parametric occupancy models and navigation maps from robot range data.

    Coordinates follow ROS REP-103 (x forward, y left, z up) in metres and radians,
    in the robot frame centred at the sensor.
    """
    level = max(10, min(50, 30 - 10 * (verbosity - quietness)))
    from rich.console import Console
    from rich.logging import RichHandler

    logging.basicConfig(
        level=level,
        format="%(message)s",
        handlers=[RichHandler(console=Console(stderr=True), show_time=False, show_path=False)],
        force=True,
    )
    ctx.ensure_object(dict)
    ctx.obj["verbosity"] = verbosity - quietness


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point."""
    cli.main(args=argv, prog_name="occtool")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
