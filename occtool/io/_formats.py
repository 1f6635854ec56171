"""The one registry of range-log formats: each name's reader, whole and streamed.

:func:`occtool.io.read_log` calls :data:`READERS` [format] and
:class:`~occtool.io.position_stream.PositionStream` calls :data:`STREAMS` [format] (a
format without one is read whole there). Every entry takes ``(path, format, options)``
and hands the format's reader the :class:`~occtool.io.read_options.ReadOptions` whole,
so no option is listed here. The readers are imported only when their format is read
(numpy and each reader are milliseconds of every fresh process).

A stream entry returns a *source*: ``notes`` (complete after a full iteration) and
``positions()``, an iterator of positions, or ``None`` when the file is better read
whole (occtool's own MCAP channel).
"""

from __future__ import annotations

import contextlib
import os
import zlib
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

from occtool.errors import InputError
from occtool.io.read_options import FORMATS

if TYPE_CHECKING:
    from occtool.features import Position, RangeLog
    from occtool.io.read_options import ReadOptions

PathLike = str | os.PathLike[str]
#: A log's path, or (a scan sequence, ``scans``) its files.
Paths = PathLike | Sequence[PathLike]


def _read_csv(path: PathLike, fmt: str, options: ReadOptions) -> RangeLog:
    from occtool.io.csv import read_csv

    return read_csv(path, options)


def _read_mcap(path: PathLike, fmt: str, options: ReadOptions) -> RangeLog:
    from occtool.io.mcap import read_mcap

    opener = None
    if fmt == "rosbag":  # a bag is read by the MCAP reader, through rosbags' container
        from occtool.io.rosbag import BagReader

        opener = BagReader
    return read_mcap(path, options, opener=opener)


def _read_carmen(path: PathLike, fmt: str, options: ReadOptions) -> RangeLog:
    from occtool.io.carmen import read_carmen

    return read_carmen(path, options)


def _read_urg(path: PathLike, fmt: str, options: ReadOptions) -> RangeLog:
    from occtool.io.urg import read_urg

    return read_urg(path, options)


def _read_depth_folder(path: PathLike, fmt: str, options: ReadOptions) -> RangeLog:
    from occtool.io.depth_folders import read_depth_folder

    return read_depth_folder(path, options, format=fmt)


def _read_pointcloud(path: PathLike, fmt: str, options: ReadOptions) -> RangeLog:
    from occtool.io.pointcloud import read_pointcloud

    return read_pointcloud(path, options, format=fmt)


def _read_scans(path: Paths, fmt: str, options: ReadOptions) -> RangeLog:
    from occtool.io.scans import read_scans

    return read_scans(path, options)


class _Grouped:
    """A reader's scans grouped into positions as they are read (carmen, MCAP, depth folders)."""

    def __init__(self, scans: Any, options: ReadOptions) -> None:
        self.scans = scans
        self.options = options

    @property
    def notes(self) -> list[str]:
        return self.scans.notes

    def positions(self) -> Iterator[Position] | None:
        from occtool.io.positions import group_scans

        prepare = getattr(self.scans, "prepare", None)
        if prepare is not None and not prepare():
            return None
        return group_scans(self.scans, source=self.scans.name, tolerance=self.options.position_tolerance,
                           group_by=self.options.group_by, notes=self.scans.notes)


class _CsvRows:
    """A CSV log's rows a chunk at a time (:func:`occtool.io.csv_stream.iter_csv`)."""

    def __init__(self, path: PathLike, options: ReadOptions) -> None:
        self.path = path
        self.options = options
        self.notes: list[str] = []

    def positions(self) -> Iterator[Position]:
        from occtool.io.csv_stream import iter_csv

        self.notes = []  # each iteration notes afresh
        return iter_csv(self.path, self.options, notes=self.notes)


def _stream_csv(path: PathLike, fmt: str, options: ReadOptions) -> _CsvRows:
    return _CsvRows(path, options)


def _stream_carmen(path: PathLike, fmt: str, options: ReadOptions) -> _Grouped:
    from occtool.io.carmen import CarmenScans

    return _Grouped(CarmenScans(path, options), options)


def _stream_mcap(path: PathLike, fmt: str, options: ReadOptions) -> _Grouped:
    from occtool.io.mcap._reader import McapScans

    opener = None
    if fmt == "rosbag":
        from occtool.io.rosbag import BagReader

        opener = BagReader
    return _Grouped(McapScans(path, options, opener=opener), options)


def _stream_depth_folder(path: PathLike, fmt: str, options: ReadOptions) -> _Grouped:
    from occtool.io.depth_folders import DepthFolderScans

    return _Grouped(DepthFolderScans(path, options, format=fmt), options)


def _stream_scans(path: Paths, fmt: str, options: ReadOptions) -> _Grouped:
    from occtool.io.scans import ScanSequence

    return _Grouped(ScanSequence(path, options), options)


Reader = Callable[[Any, str, "ReadOptions"], "RangeLog"]  # Any: a path, or the files of a scan sequence

#: Format name -> reader of the whole log.
READERS: dict[str, Reader] = {
    "csv": _read_csv, "mcap": _read_mcap, "rosbag": _read_mcap, "carmen": _read_carmen, "urg": _read_urg,
    "tum": _read_depth_folder, "3dmatch": _read_depth_folder,
    "xyz": _read_pointcloud, "pcd": _read_pointcloud, "ply": _read_pointcloud, "scans": _read_scans,
}
#: Format name -> source of its positions one at a time (absent: read whole, one position in practice).
STREAMS: dict[str, Callable[[Any, str, ReadOptions], Any]] = {
    "csv": _stream_csv, "carmen": _stream_carmen, "mcap": _stream_mcap, "rosbag": _stream_mcap,
    "tum": _stream_depth_folder, "3dmatch": _stream_depth_folder, "scans": _stream_scans,
}
assert set(READERS) == set(FORMATS) and set(STREAMS) <= set(FORMATS)  # one list of names



@contextlib.contextmanager
def read_errors(path: Paths) -> Iterator[None]:
    """A damaged compressed file or an I/O error while reading as one :class:`InputError`."""
    try:
        yield
    except (EOFError, zlib.error) as exc:
        raise InputError(f"{path} is truncated or corrupt: {exc}") from None
    except OSError as exc:
        # Decompression errors (a damaged .gz/.bz2) are OSErrors too; missing files and
        # permissions keep their own message.
        if isinstance(exc, (FileNotFoundError, PermissionError, IsADirectoryError)):
            raise
        raise InputError(f"{path} cannot be read: {exc}") from None


def read_whole(path: Paths, fmt: str, options: ReadOptions) -> RangeLog:
    """Read a whole log of format ``fmt`` with its registered reader."""
    return READERS[fmt](path, fmt, options)


__all__ = ["READERS", "STREAMS", "read_errors", "read_whole"]
