"""Options shared by several subcommands.

Each ``*_options`` decorator adds a group of options to a command; the matching
``*_from_kwargs`` helper (where there is one) pops those options out of the command's
keyword arguments and builds the library's parameter object, so every command that
fits, extracts or compares reads them the same way.

``--config FILE`` reads defaults for any option from a TOML file: top-level keys or
keys under ``[sensor]``, ``[fit]``, ``[extract]``, ``[log]`` tables, named as the
options are, with dashes or underscores (``depth-error = 0.03``). Options given on the
command line win.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

F = TypeVar("F", bound=Callable[..., Any])


def _compose(*decorators: Callable[[F], F]) -> Callable[[F], F]:
    def apply(function: F) -> F:
        for decorator in reversed(decorators):
            function = decorator(function)
        return function

    return apply


def float_list(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> tuple[float, ...] | None:
    """Parse ``"-0.9,-0.5,-0.1"`` (or a TOML list) into a tuple of floats."""
    if value is None or value == "":
        return None
    if isinstance(value, (list, tuple)):
        items = list(value)
    else:
        items = [v for v in str(value).replace(" ", "").split(",") if v]
    try:
        return tuple(float(v) for v in items)
    except ValueError:
        raise click.BadParameter(f"expected comma-separated numbers, got {value!r}") from None


# --- configuration file -------------------------------------------------------------

def _load_config(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    if value is None:
        return None
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    try:
        with open(value, "rb") as handle:
            data = tomllib.load(handle)
    except OSError as exc:
        raise click.BadParameter(f"cannot read {value}: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise click.BadParameter(f"{value} is not valid TOML: {exc}") from None
    flat: dict[str, Any] = {}
    for key, item in data.items():
        if isinstance(item, dict):
            for sub_key, sub_item in item.items():
                flat[sub_key.replace("-", "_")] = sub_item
        else:
            flat[key.replace("-", "_")] = item
    known = {p.name for p in ctx.command.params}
    unknown = sorted(set(flat) - known)
    if unknown:
        raise click.BadParameter(f"{value}: unknown settings for `{ctx.info_name}`: {', '.join(unknown)}")
    ctx.default_map = {**(ctx.default_map or {}), **flat}
    return value


config_option = click.option(
    "--config",
    type=click.Path(dir_okay=False),
    callback=_load_config,
    is_eager=True,
    expose_value=False,
    help="TOML file with defaults for any option of this command.",
)

# --- output ---------------------------------------------------------------------------

output_option = click.option(
    "-o", "--output", type=click.Path(dir_okay=True, allow_dash=True), default=None,
    help="Output file ('-' or absent: standard output, where the command allows it).",
)
seed_option = click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")

# --- range-log reading (owner: readers) ------------------------------------------------
# log_options / read_log_from_kwargs go here.

# --- sensor model and fit (owner: core model) -----------------------------------------
# sensor_options / fit_options and their *_from_kwargs helpers go here.

# --- navigation extraction (owner: navigation) ----------------------------------------
# extract_options / extract_from_kwargs go here.
