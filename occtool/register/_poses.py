"""The map's poses: every registered scan's pose written as ``poses.csv`` and handed to the
map's ``/tf``."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from occtool.features import Pose, RangeLog, log_notes
from occtool.register._core import RegistrationReport, RegistrationSettings
from occtool.register._scans import read_registered_log


def write_poses_csv(report: RegistrationReport, path: str | Any, *, overwrite: bool = True) -> None:
    """Every scan's registered pose as CSV: ``scan,stamp,x,y,z,yaw`` (the world ``map``
    frame, metres and radians; ``stamp`` in seconds, empty when the log has none)."""
    from occtool._files import atomic_write

    with atomic_write(path, "w", overwrite=overwrite) as handle:
        handle.write("scan,stamp,x,y,z,yaw\n")
        for k, (pose, stamp) in enumerate(zip(report.poses, report.stamps)):
            when = "" if stamp is None else f"{stamp:.6f}"
            handle.write(f"{k},{when},{pose.x:.6f},{pose.y:.6f},{pose.z:.6f},{pose.yaw:.6f}\n")


def read_map_log(source: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
                 read_options: Mapping[str, Any] | None = None, *,
                 register: bool | None = None, settings: RegistrationSettings | None = None
                 ) -> tuple[RangeLog, RegistrationReport | None]:
    """Read the log of a map (:func:`occtool.fuse.map_log`): with ``read_options`` (the
    keywords of :func:`occtool.io.read_log`; ``source`` a log, or point-cloud files read as one
    scan sequence), registered when ``register`` is true or, by
    default (``None``), when it needs it (:func:`needs_registration`). Its notes are logged
    (``occtool.io``, each at its level: :func:`occtool.features.log_notes`). Returns the log
    and the registration report (``None`` when its own poses are kept)."""
    import logging

    path = str(source) if isinstance(source, (str, os.PathLike)) else list(source)  # several files: a sequence
    log, report = read_registered_log(path, dict(read_options or {}), register, settings=settings)
    logger = logging.getLogger("occtool.io")
    name = Path(path).name if isinstance(path, str) else f"{len(path)} files"
    log_notes(logger, name, log.notes)
    return log, report


def write_map_poses(report: RegistrationReport | None, folder: str | os.PathLike[str], *,
                    overwrite: bool = True) -> Path | None:
    """``folder/poses.csv``: every scan's registered pose. Without registration nothing is
    written, and a ``poses.csv`` left by an earlier registered run is removed (it would
    describe another map) unless ``overwrite`` is off."""
    path = Path(folder) / "poses.csv"
    if report is None:
        if overwrite and path.is_file():
            path.unlink()
        return None
    write_poses_csv(report, path, overwrite=overwrite)
    return path


def trajectory(report: RegistrationReport | None) -> list[tuple[float | None, Pose]]:
    """``(stamp, pose)`` of every registered scan, for the map's ``/tf`` (empty without registration)."""
    return [] if report is None else list(zip(report.stamps, report.poses))
