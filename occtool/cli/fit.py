"""``occtool fit``: fit a parametric occupancy model to a range log, or model sets to many."""

from __future__ import annotations

import click

from occtool.cli.options import (
    config_option,
    fit_options,
    jobs_options,
    log_options,
    output_option,
    overwrite_option,
    refuse_existing,
    seed_option,
)


@click.command(short_help="Fit a parametric occupancy model to a range log.")
@click.argument("log_paths", metavar="LOG...", nargs=-1, required=True)
@output_option
@overwrite_option
@click.option("--position", type=click.IntRange(min=0), default=None,
              help="Robot position of a multi-position log to fit (default: the only one).")
@jobs_options("the number of robot positions whose models are fitted at once")
@click.option("--skip-existing", is_flag=True, default=False,
              help="Model sets: keep each model file whose input and settings match (resume a stopped run).")
@fit_options
@log_options
@seed_option
@config_option
def fit(log_paths: tuple[str, ...], output: str | None, overwrite: bool, position: int | None, seed: int,
        jobs: int | None, scheduler: str | None, skip_existing: bool, **kwargs) -> None:
    """Fit the min/max tree m = F(alpha, h, r) to the features of LOG and write it as JSON.

    With -o DIR/ (an existing folder, or a path ending in '/'; created if missing) one
    model per robot position is written to DIR plus DIR/index.json listing each position's
    pose, file and input digest: a model set. Several LOGs (or globs) give one sub-folder
    of DIR per log, named after the log's file (intel-corrected.log.gz -> DIR/intel-corrected/).
    Positions run on -j local processes (default: the cores) or, with --scheduler, on a
    Dask cluster; the models are the same bytes either way. A position that fails is
    reported and the rest is written; an interrupted run leaves an index marked
    incomplete, and --skip-existing resumes it. LOG '-' reads standard input.
    """
    import logging
    import os
    import sys
    from pathlib import Path

    from occtool.cli.options import (
        fit_from_kwargs,
        pop_log_options,
        read_log_from_kwargs,
    )

    logger = logging.getLogger("occtool.fit")
    template = fit_from_kwargs(kwargs, seed=seed)
    logs = _expand(log_paths)
    to_folder = output is not None and (output.endswith(("/", os.sep)) or Path(output).is_dir())
    if len(logs) > 1 and not to_folder:
        raise click.UsageError("several logs need an output folder: -o DIR/")
    if to_folder:
        from occtool.modelset import fit_model_set

        read_options = pop_log_options(kwargs)
        command = "occtool fit " + " ".join(sys.argv[2:]) if len(sys.argv) > 1 else "occtool fit"
        with _progress_bar("fitting") as progress:
            summary = fit_model_set(
                logs, output, estimator=template, read_options=read_options,
                positions=None if position is None else [position], jobs=jobs, scheduler=scheduler,
                skip_existing=skip_existing, overwrite=overwrite, progress=progress, command=command,
                planar_defaults=not _heights_given(),
            )
        _report(summary, logger, "fitted")
        return

    refuse_existing(overwrite, output)
    log = read_log_from_kwargs(logs[0], kwargs)
    item = log.single(position)
    from occtool.formats.model import save_model
    from occtool.modelset import estimator_for_log, settings_digest

    template = estimator_for_log(template, [item], planar_defaults=not _heights_given())
    model = _fit_one(template, item.features)

    run = _run_details(model, logs[0], item.index)
    run["settings_sha256"] = settings_digest(template)
    save_model(model, output or "-", run=run)
    logger.info(
        "position %d: %d features, %d samples, %d pieces, RMSE %.4f, %.2f s",
        item.index, model.n_features_, model.n_samples_, model.tree_.n_pieces, model.rmse_, model.fit_seconds_,
    )


def _expand(paths: tuple[str, ...]) -> list[str]:
    """The logs named: each argument a file, '-' or a glob pattern that matches files
    (glob is imported for a pattern only: a few ms of every fresh fit otherwise)."""
    import os

    logs: list[str] = []
    for path in paths:
        if path == "-" or os.path.exists(path):
            if os.path.isdir(path):
                raise click.BadParameter(f"{path} is a folder, not a range log", param_hint="LOG")
            logs.append(path)
            continue
        import glob

        matches = sorted(p for p in glob.glob(path) if os.path.isfile(p))
        if not matches:
            raise click.BadParameter(f"{path} does not exist (nor matches any file)", param_hint="LOG")
        logs.extend(matches)
    if logs.count("-") > 1:
        raise click.BadParameter("standard input ('-') can be read once", param_hint="LOG")
    return logs


def _report(summary, logger, verb: str) -> None:
    """The summary line, each failure, and a non-zero exit if a position failed."""
    for failure in summary.failures[:20]:
        where = failure.source if failure.position is None else f"{failure.source}, position {failure.position}"
        logger.warning("failed: %s: %s", where, failure.reason)
    if len(summary.failures) > 20:
        logger.warning("... and %d more failures (listed in each set's index.json)", len(summary.failures) - 20)
    logger.info("%s", summary.describe(verb))
    if summary.failures:
        where = "; see 'failed' in index.json" if verb == "fitted" else ""
        raise click.ClickException(
            f"{len(summary.failures)} of {summary.positions or len(summary.failures)} position(s) failed "
            f"(the rest is written{where}): {summary.failures[0].reason}"
        )
    if logger.getEffectiveLevel() > 20:
        import sys

        if sys.stderr.isatty():
            click.echo(summary.describe(verb), err=True)


def _progress_bar(label: str):
    """A context giving a progress callback: one rich bar over positions (and logs) with
    rate and ETA on an interactive stderr, else ``None``."""
    import contextlib
    import sys

    if not sys.stderr.isatty():
        return contextlib.nullcontext(None)
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    bar = Progress(TextColumn(label), BarColumn(), MofNCompleteColumn(), TaskProgressColumn(),
                   TextColumn("{task.fields[rate]}"), TextColumn("{task.fields[logs]}"), TimeElapsedColumn(),
                   TextColumn("ETA"), TimeRemainingColumn(), console=Console(stderr=True), transient=True)

    @contextlib.contextmanager
    def running():
        with bar:
            task = bar.add_task(label, total=None, rate="", logs="")

            def update(event) -> None:
                speed = bar.tasks[0].speed
                logs = f"log {event.logs_read}/{event.logs_total}" if event.logs_total > 1 else ""
                bar.update(task, completed=event.done, total=event.total or None,
                           rate=f"{speed:.1f}/s" if speed else "", logs=logs)

            yield update

    return running()


def _run_details(model, log_path: str, position: int) -> dict:
    import platform
    import sys
    from datetime import datetime, timezone

    from occtool._version import __version__

    return {
        "seconds": round(model.fit_seconds_, 3),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "occtool_version": __version__,
        "python": platform.python_version(),
        "host": platform.node(),
        "command": "occtool fit " + " ".join(sys.argv[2:]) if len(sys.argv) > 1 else "occtool fit",
        "input": str(log_path),
        "position": position,
    }


def _heights_given() -> bool:
    """Whether --sensor-height or --body-height was given (command line or --config)."""
    from click.core import ParameterSource

    ctx = click.get_current_context(silent=True)
    return ctx is not None and any(ctx.get_parameter_source(name) not in (ParameterSource.DEFAULT, None)
                                   for name in ("sensor_height", "body_height"))


def _fit_one(template, features):
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
        task = progress_bar.add_task("fit", total=1)

        def report(sweep: int, total: int) -> None:
            progress_bar.update(task, completed=sweep, total=total)

        return model.fit(features, progress=report)
