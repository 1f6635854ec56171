"""Sequences of 3D scans, each a file, with a KITTI-style poses file: the ``scans`` format.

A *scan sequence* is a folder of scans, or several point-cloud files given together:

* the files: ``*.pcd`` (binary PCDs zero-padded after their points too, as SC-A-LOAM
  writes them), ``*.ply`` and KITTI Velodyne ``*.bin`` (float32 ``x y z intensity``), of a
  folder, sorted by name (``000000.pcd``, ``000001.pcd``, ...), each read by
  :func:`occtool.io.pointcloud.pointcloud_scans`; or a list of point-cloud files in the
  order given (``xyz`` too);
* the poses (``ReadOptions.poses``): a text file as KITTI's odometry poses, A-LOAM /
  SC-A-LOAM's and FAST-LIO's ``optimized_poses.txt``: line i holds 12 numbers, the
  row-major 3x4 ``[R | t]`` taking points of scan i into the world
  (``p_world = R p + t``). Lines beyond the scans are allowed (SC-A-LOAM saves every
  keyframe's pose and a sample of the scans); fewer is an error. The file is checked once,
  whole: 12 finite numbers a line, ``R`` a rotation (orthonormal within 1e-3, determinant
  +1), ``t`` within :data:`~occtool.limits.MAX_WORLD_COORDINATE` (:func:`occtool.io.positions.check_pose`).

Each scan is one robot position's scan: with a pose, its points are rotated into the
sensor-centred robot frame (REP-103: sensor at the origin, z the world's up, x along the
sensor's heading; its roll and pitch applied, its heading kept in the
:class:`~occtool.features.Pose`), as a depth camera's frame is
(:func:`occtool.io.depth.body_scan`). The poses' world z is taken as up. Without a poses
file, a scan keeps its file's own pose (a PCD ``VIEWPOINT``) or has none, and
``occtool map`` registers the sequence (:mod:`occtool.register`). A file with its own pose
and a poses file: the file's pose is composed with the poses file's.

:class:`ScanSequence` reads one file at a time (the streamed source of
:func:`occtool.io.iter_positions`); :func:`read_scans` reads the whole log.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import RangeLog
from occtool.io._detect import SCAN_SUFFIXES, _suffix, detect_format, is_log_folder, is_scan_folder
from occtool.io.positions import Scan, build_log, check_pose
from occtool.io.read_options import ReadOptions, as_read_options, options_as_keywords

FloatArray = NDArray[np.float64]
PathLike = str | os.PathLike[str]

#: The point-cloud formats a listed file may have (a folder's are :data:`SCAN_SUFFIXES`).
FILE_FORMATS = ("pcd", "ply", "bin", "xyz")
#: Most scans in one sequence, and most lines of a poses file.
MAX_SCANS = 1_000_000


def scan_files(path: PathLike | Sequence[PathLike]) -> list[Path]:
    """The scans of a sequence: a folder's ``*.pcd``/``*.ply``/``*.bin`` sorted by name, a
    list of files in its order, or one file.

    Raises
    ------
    InputError
        For a folder without scans, or too many; a listed path that is a folder.
    """
    if isinstance(path, (str, os.PathLike)):
        target = Path(path)
        if not target.is_dir():
            return [target]
        files = sorted(p for p in target.iterdir() if _suffix(p) in SCAN_SUFFIXES and p.is_file())
        if not files:
            raise InputError(f"{target} holds no scans (*.pcd, *.ply or KITTI *.bin files)")
    else:
        files = [Path(p) for p in path]
        for file in files:
            if file.is_dir():
                raise InputError(f"{file} is a folder: give a folder of scans alone, or point-cloud files")
        if not files:
            raise InputError("no scan files given")
    if len(files) > MAX_SCANS:
        raise InputError(f"{path} holds more than {MAX_SCANS:,} scans")
    return files


def sequence_name(path: PathLike | Sequence[PathLike]) -> str:
    """How notes and errors name a sequence: the folder or file, or the files listed."""
    if isinstance(path, (str, os.PathLike)):
        return str(path)
    names = [str(p) for p in path]
    return " ".join(names) if len(names) <= 3 else f"{names[0]} ... {names[-1]} ({len(names)} files)"


def _pose_line(text: str, where: str) -> FloatArray:
    """One poses-file line as a checked 3x4 ``[R | t]`` (``where`` names the file and line)."""
    parts = text.split()
    if len(parts) != 12:
        raise InputError(f"{where}: expected 12 numbers (a row-major 3x4 scan-to-world transform), "
                         f"got {len(parts)}")
    try:
        values = [float(v) for v in parts]
    except ValueError:
        bad = next(v for v in parts if not _is_number(v))
        raise InputError(f"{where}: {bad[:40]!r} is not a number") from None
    matrix = np.array(values, dtype=np.float64).reshape(3, 4)
    check_pose(where, matrix[:, 3], rotation=matrix[:, :3])  # the one pose check every reader makes
    return matrix


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_poses(path: PathLike) -> FloatArray:
    """A KITTI-style poses file as a ``(K, 3, 4)`` array: line i the row-major 3x4
    scan-to-world transform of scan i, checked (see the module). Blank lines at the end are
    ignored; anywhere else a blank or ``#`` line would shift every later scan's pose, and is
    an error.

    Raises
    ------
    InputError
        One line naming the file and line, for the first line that is not a pose; for a
        file without poses.
    """
    poses: list[FloatArray] = []
    blank: int | None = None
    with open(path, encoding="utf-8", errors="replace") as handle:
        for number, line in enumerate(handle, 1):
            text = line.strip()
            if not text:
                blank = blank or number
                continue
            where = f"{path}, line {number}"
            if blank is not None:
                raise InputError(f"{path}, line {blank}: a blank line among the poses (line i is scan i's pose)")
            if text.startswith("#"):
                raise InputError(f"{where}: a comment among the poses (line i is scan i's pose)")
            if number > MAX_SCANS:
                raise InputError(f"{path} holds more than {MAX_SCANS:,} poses")
            poses.append(_pose_line(text, where))
    if not poses:
        raise InputError(f"{path} holds no poses")
    return np.stack(poses)


def _placed(scan: Scan, transform: FloatArray) -> Scan:
    """``scan`` placed by its scan-to-world ``transform`` (3x4), composed with the scan's own pose."""
    from occtool.io.depth import body_scan

    rotation, translation = transform[:, :3], transform[:, 3]
    if scan.pose is not None:  # the file's own pose (a PCD VIEWPOINT): its points are in that frame
        translation = rotation @ scan.pose.translation + translation
        rotation = rotation @ scan.pose.rotation
    points, pose = body_scan(scan.points, rotation, translation)
    return Scan(points, scan.evidence, pose, scan.stamp, scan.source)


def _note_key(note: str) -> tuple[tuple[str, str], int]:
    """A file's note as a key and a count: ``dropped 12 point(s) ...`` counts 12 under
    ``("dropped ", " point(s) ...")``, summed over the files; another note counts 0 under
    ``(note, "")``."""
    match = _COUNTED.fullmatch(note)
    if match is None:
        return (note, ""), 0
    return (match[1], match[3]), int(match[2])


_COUNTED = re.compile(r"((?:dropped|skipped) )(\d+)( .+)", re.DOTALL)


class ScanSequence:
    """A scan sequence's scans, one file at a time (an iterable of
    :class:`~occtool.io.positions.Scan`): the streamed source of ``scans`` logs.

    The poses file is read and checked once, at the first iteration (before any scan);
    each iteration reads every scan file again, holding one at a time. ``notes`` is
    complete after a full iteration. Parameters are those of :func:`read_scans`.
    """

    def __init__(self, path: PathLike | Sequence[PathLike], options: ReadOptions | None = None,
                 **keywords: Any) -> None:
        self.settings = as_read_options(options, **keywords)
        self.path = path
        self.name = sequence_name(path)
        self.files = scan_files(path)
        self.listed = not isinstance(path, (str, os.PathLike))
        self.notes: list[str] = []
        self._poses: FloatArray | None = None

    def _formats(self) -> list[str]:
        """Each file's point-cloud format: from its extension, else (a listed file) its content."""

        formats = []
        for file in self.files:
            fmt = SCAN_SUFFIXES.get(_suffix(file)) or {".xyz": "xyz", ".dat": "xyz"}.get(_suffix(file))
            if fmt is None:
                fmt = detect_format(file)
            if fmt not in FILE_FORMATS:
                raise InputError(f"{file} is {fmt}: a scan sequence's files are point clouds (PCD, PLY, "
                                 "KITTI .bin, x y z)")
            formats.append(fmt)
        return formats

    def prepare(self) -> bool:
        """Read and check the poses file, once (see the class); True: the scans stream."""
        if self._poses is None and self.settings.poses is not None:
            poses = read_poses(self.settings.poses)
            if poses.shape[0] < len(self.files):
                raise InputError(f"{self.settings.poses} holds {poses.shape[0]:,} poses for {len(self.files):,} "
                                 f"scans in {self.name}: line i is scan i's pose")
            self._poses = poses
        self._file_formats = getattr(self, "_file_formats", None) or self._formats()
        return True

    def __iter__(self) -> Iterator[Scan]:
        from occtool.io.pointcloud import pointcloud_scans

        self.prepare()
        self.notes.clear()
        counts: dict[tuple[str, str], list[int]] = {}  # each note once: [files it is of, points it counts]
        settings = self.settings.replace(format=None)
        for index, (file, fmt) in enumerate(zip(self.files, self._file_formats)):
            scans, notes = pointcloud_scans(file, settings, format=fmt)
            for note in notes:
                key, number = _note_key(note)
                seen = counts.setdefault(key, [0, 0])
                seen[0] += 1
                seen[1] += number
            for scan in scans:
                if self._poses is not None:
                    scan = _placed(scan, self._poses[index])
                yield Scan(scan.points, scan.evidence, scan.pose, scan.stamp, file.name if not self.listed
                           else str(file))
        total = len(self.files)
        for (head, tail), (files, number) in counts.items():
            note = f"{head}{number}{tail}" if tail else head
            self.notes.append(note if total == 1 else f"{note} (each of the {total} scans)" if files == total
                              else f"{note} (in {files} of the {total} scans)")
        if self._poses is not None:
            extra = self._poses.shape[0] - len(self.files)
            self.notes.append(f"poses from {self.settings.poses}: line i for scan i"
                              + (f" ({extra:,} lines beyond the {len(self.files):,} scans unused)" if extra else ""))


def read_scans(path: PathLike | Sequence[PathLike], options: ReadOptions | None = None,
               **keywords: Any) -> RangeLog:
    """Read a scan sequence (see the module): a folder of scans, a list of point-cloud
    files, or one, with the poses file ``poses`` if given.

    ``options`` and ``keywords`` are those of :func:`occtool.io.read_log`: ``poses``,
    ``evidence_field``, ``evidence``, ``position_tolerance``, ``group_by`` and
    ``skip_invalid``.

    Raises
    ------
    InputError
        For a folder without scans, a damaged scan or poses file (one line naming the file,
        and the line of a poses file), fewer poses than scans.
    """
    sequence = ScanSequence(path, options, **keywords)
    scans = list(sequence)
    if not any(s.points.shape[0] for s in scans):
        raise InputError(f"{sequence.name} holds no valid points")
    log = build_log(scans, source=sequence.name, tolerance=sequence.settings.position_tolerance,
                    group_by=sequence.settings.group_by, notes=sequence.notes)
    if sequence.settings.poses is not None:
        log.pose_kind = "log"
    return log


options_as_keywords(read_scans)
options_as_keywords(ScanSequence)

__all__ = ["FILE_FORMATS", "MAX_SCANS", "SCAN_SUFFIXES", "ScanSequence", "is_log_folder", "is_scan_folder",
           "read_poses", "read_scans", "scan_files", "sequence_name"]
