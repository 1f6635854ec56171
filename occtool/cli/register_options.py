"""The registration options of ``occtool map`` (:mod:`occtool.register`, which also reads
the map's log and writes its poses), kept apart from the map command so that its own
options and these merge independently."""

from __future__ import annotations

from collections.abc import Callable
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


__all__ = ["register_options"]
