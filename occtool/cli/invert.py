"""``occtool invert``: write the inverse tree r = F^-1(alpha, h, m) of a model."""

from __future__ import annotations

import click

from occtool.cli.options import config_option, output_option, overwrite_option, refuse_existing


@click.command(short_help="Write the inverted model r = F^-1(alpha, h, m).")
@click.argument("model_path", metavar="MODEL", type=click.Path(exists=True, dir_okay=False))
@output_option
@overwrite_option
@config_option
def invert(model_path: str, output: str | None, overwrite: bool) -> None:
    """Invert MODEL (MIN and MAX swapped, each piece solved for r) and write it as JSON."""
    import platform
    from datetime import datetime, timezone

    from occtool._version import __version__
    from occtool.formats.model import load_model, save_inverse

    refuse_existing(overwrite, output)
    model = load_model(model_path)
    run = {
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "occtool_version": __version__,
        "host": platform.node(),
        "model": str(model_path),
    }
    save_inverse(model.invert(), output or "-", model=model, run=run)
