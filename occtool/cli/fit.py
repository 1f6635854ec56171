"""``occtool fit``: fit a parametric occupancy model to a range log."""

from __future__ import annotations

import click

from occtool.cli.options import (
    config_option, fit_options, log_options, output_option, overwrite_option, refuse_existing, seed_option,
)


@click.command(short_help="Fit a parametric occupancy model to a range log.")
@click.argument("log_path", metavar="LOG", type=click.Path(exists=True, dir_okay=False))
@output_option
@overwrite_option
@click.option("--position", type=click.IntRange(min=0), default=None,
              help="Robot position of a multi-position log to fit (default: the only one).")
@fit_options
@log_options
@seed_option
@config_option
def fit(log_path: str, output: str | None, overwrite: bool, position: int | None, seed: int, **kwargs) -> None:
    """Fit the min/max tree m = F(alpha, h, r) to the features of LOG and write it as JSON.

    With -o DIR/ (an existing folder, or a path ending in '/') and a log of several robot
    positions, one model per position is written to DIR plus DIR/index.json listing each
    position's pose and file.
    """
    import logging
    import os
    import platform
    import sys
    from datetime import datetime, timezone
    from pathlib import Path

    from occtool import __version__
    from occtool.cli.options import fit_from_kwargs, fit_template_for_log, read_log_from_kwargs
    from occtool.io.model import save_model, save_model_set_index

    logger = logging.getLogger("occtool.fit")
    template = fit_from_kwargs(kwargs, seed=seed)
    log = read_log_from_kwargs(log_path, kwargs)
    to_folder = output is not None and (output.endswith(("/", os.sep)) or Path(output).is_dir())
    if to_folder:
        folder = Path(output)
        if not folder.is_dir():
            raise click.ClickException(f"output folder {folder} does not exist")
        chosen = [log.single(position)] if position is not None else list(log.positions)
        if not chosen:
            log.single(None)  # raises the "no range data" error
    else:
        chosen = [log.single(position)]
    template = fit_template_for_log(template, log, chosen)  # planar-laser defaults, geometry warnings (h12)
    if to_folder:
        refuse_existing(overwrite, *(Path(output) / f"model_{item.index:04d}.json" for item in chosen),
                        Path(output) / "index.json")
    else:
        refuse_existing(overwrite, output)

    index = []
    for item in chosen:
        model = _fit_one(template, item.features, logger)
        run = {
            "seconds": round(model.fit_seconds_, 3),
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "occtool_version": __version__,
            "python": platform.python_version(),
            "host": platform.node(),
            "command": "occtool fit " + " ".join(sys.argv[2:]) if len(sys.argv) > 1 else "occtool fit",
            "input": str(log_path),
            "position": item.index,
        }
        if to_folder:
            name = f"model_{item.index:04d}.json"
            save_model(model, Path(output) / name, run=run)
            index.append({"position": item.index, "file": name,
                          "pose": item.pose.to_dict() if item.pose is not None else None,
                          "stamp": item.stamp, "features": len(item.features)})
        else:
            save_model(model, output or "-", run=run)
        logger.info(
            "position %d: %d features, %d samples, %d pieces, RMSE %.4f, %.2f s",
            item.index, model.n_features_, model.n_samples_, model.tree_.n_pieces, model.rmse_, model.fit_seconds_,
        )
    if to_folder:
        save_model_set_index(output, index, source=str(log_path))


def _fit_one(template, features, logger):
    """Fit a copy of the template estimator, with a progress bar on an interactive stderr."""
    import sys

    from occtool.fit import OccupancyRegressor

    progress_bar = None
    if sys.stderr.isatty():
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        progress_bar = Progress(TextColumn("fitting"), BarColumn(), TextColumn("step {task.completed}/{task.total}"),
                                TimeElapsedColumn(), console=Console(stderr=True), transient=True)
    model = OccupancyRegressor(**template.get_params(deep=False))
    if progress_bar is None:
        return model.fit(features)
    with progress_bar:
        task = progress_bar.add_task("fit", total=None)

        def report(sweep: int, total: int) -> None:
            progress_bar.update(task, completed=sweep, total=total)

        return model.fit(features, progress=report)
