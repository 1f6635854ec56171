"""The registration options of ``occtool map`` (:mod:`occtool.register`), kept apart from
the map command so that its own options and these merge independently."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

F = TypeVar("F", bound=Callable[..., Any])


def register_options(function: F) -> F:
    function = click.option(
        "--loop-closure/--no-loop-closure", default=True, show_default=True,
        help="With registration: re-align revisited places (a pose graph over the scans).")(function)
    function = click.option(
        "--register/--no-register", "register", default=None,
        help="Estimate the poses by registering the scans (needs the register extra). Default: when the log "
             "has no poses or only wheel odometry (which then seeds it); --no-register keeps the log's "
             "poses.")(function)
    return function


def read_map_log(source: str, kwargs: dict[str, Any]) -> tuple[Any, Any]:
    """Pop the log and registration options, read the log (registered if asked or needed)
    and return it with the registration report (``None`` when its own poses are kept)."""
    import logging

    from occtool.cli.options import LOG_OPTION_NAMES, read_log_from_kwargs
    from occtool.register import RegistrationSettings, read_registered_log

    register = kwargs.pop("register", None)
    loop_closure = kwargs.pop("loop_closure", True)
    if str(source) == "-":
        return read_log_from_kwargs(source, kwargs), None
    options = {name: kwargs.pop(name) for name in LOG_OPTION_NAMES if name in kwargs}
    if "topics" in options:
        options["topics"] = list(options["topics"]) or None
    log, report = read_registered_log(source, options, register,
                                      settings=RegistrationSettings(loop_closure=loop_closure))
    logger = logging.getLogger("occtool.io")
    for note in log.notes:
        logger.warning("%s: %s", Path(source).name, note)
    return log, report


def write_map_poses(report: Any, output: str, overwrite: bool) -> Path | None:
    """``OUTPUT/poses.csv``: every scan's registered pose. Without registration nothing is
    written, and a ``poses.csv`` left by an earlier registered run is removed (it would
    describe another map) unless ``overwrite`` is off."""
    if report is None:
        stale = Path(output) / "poses.csv"
        if overwrite and stale.is_file():
            stale.unlink()
        return None
    from occtool.register import write_poses_csv

    path = Path(output) / "poses.csv"
    write_poses_csv(report, path, overwrite=overwrite)
    return path


def trajectory(report: Any) -> list[Any]:
    """``(stamp, pose)`` of every registered scan, for the map's ``/tf`` (empty without registration)."""
    return [] if report is None else list(zip(report.stamps, report.poses))


__all__ = ["read_map_log", "register_options", "trajectory", "write_map_poses"]
