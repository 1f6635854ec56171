"""Which range-log format a file (or folder) holds: :func:`detect_format`, from the content
first, then the name; :func:`occtool.io.read_log` asks it when no ``format`` is given."""

from __future__ import annotations

import os
from pathlib import Path

from occtool.errors import InputError

PathLike = str | os.PathLike[str]
#: The extensions of a folder's scans (:mod:`occtool.io.scans`), and each one's point-cloud format.
SCAN_SUFFIXES = {".pcd": "pcd", ".ply": "ply", ".bin": "bin"}


def _suffix(path: Path) -> str:
    """The extension that names the format (``.pcd`` of ``a.pcd.gz``), lower case."""
    suffixes = [s.lower() for s in path.suffixes if s.lower() not in (".gz", ".bz2")]
    return suffixes[-1] if suffixes else ""


def is_scan_folder(path: PathLike) -> bool:
    """Whether ``path`` is a folder holding at least one ``*.pcd``, ``*.ply`` or ``*.bin`` file."""
    try:
        with os.scandir(path) as entries:
            return any(_suffix(Path(e.name)) in SCAN_SUFFIXES and e.is_file() for e in entries)
    except OSError:
        return False

def is_log_folder(path: PathLike) -> bool:
    """Whether ``path`` is a folder read as one log: scans (:func:`is_scan_folder`) or depth
    frames with their poses (TUM RGB-D, 3DMatch / 7-Scenes). Looks at names only."""
    if is_scan_folder(path):
        return True
    from occtool.io.depth_folders import depth_layout

    try:
        return Path(path).is_dir() and depth_layout(path) is not None
    except InputError:
        return False


MCAP_MAGIC = b"\x89MCAP0\r\n"
CARMEN_RECORDS = (b"FLASER", b"RLASER", b"ROBOTLASER1", b"ODOM", b"PARAM", b"NEFF", b"SYNC", b"TRUEPOS")


def _head(path: Path, size: int = 4096) -> bytes:
    """The first bytes of a file, decompressed if it is gzip or bzip2 (:func:`occtool._files.open_input`)."""
    from occtool._files import open_input

    try:
        with open_input(path, "rb") as handle:
            head = handle.read(size)
    except (OSError, EOFError) as exc:
        if isinstance(exc, (FileNotFoundError, PermissionError, IsADirectoryError)):
            raise
        raise InputError(f"{path}: the compressed file is corrupt ({exc})") from None
    return head[3:] if head.startswith(b"\xef\xbb\xbf") else head  # a UTF-8 byte-order mark


def detect_format(path: str | os.PathLike[str]) -> str:
    """Name the format of a range log from its content, then its extension.

    Raises
    ------
    InputError
        If the content matches no supported format.
    FileNotFoundError
        If the file does not exist.
    """
    target = Path(path)
    # A folder of depth frames, or its depth.txt / camera-intrinsics.txt: only those names
    # and folders are looked at (depth_folders' import is a few ms of every fresh fit).
    if target.name in ("depth.txt", "camera-intrinsics.txt") or target.is_dir():
        from occtool.io.depth_folders import depth_layout

        layout = depth_layout(target)
        if layout is not None:
            return layout
    if target.is_dir():

        if is_scan_folder(target):
            return "scans"
        raise InputError(f"{target} is a folder, not a range log")
    head = _head(target)
    if not head:
        raise InputError(f"{target} is empty")
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    if head.startswith((b"#ROSBAG V2.0\n", b"SQLite format 3\x00")):  # ROS 1 bag, ROS 2 .db3
        return "rosbag"
    if head.startswith(b"ply") and head[3:4] in (b"\n", b"\r"):
        return "ply"
    text_lines = [line.strip() for line in head.splitlines()[:-1] or head.splitlines()]
    content = [line for line in text_lines if line and not line.startswith(b"#")]
    if b".PCD" in head[:200] or (content and content[0].split()[:1] in ([b"VERSION"], [b"FIELDS"])):
        return "pcd"
    if content and content[0].split()[:1] and content[0].split()[0] in CARMEN_RECORDS:
        return "carmen"
    if content:
        first = content[0].decode("utf-8", "replace")
        names = {c.strip().strip('"').lower() for c in first.split(",")}
        if {"x", "y", "z"} <= names:
            return "csv"
        from occtool.io.urg import looks_like_urg

        if looks_like_urg(first):
            return "urg"
        if _numeric_fields(first) >= 3 and "," not in first:
            return "xyz"
        if first.split()[:1] == ["NODE"]:
            return "xyz"
    suffixes = [s.lower() for s in target.suffixes]
    for suffix in reversed([s for s in suffixes if s not in (".gz", ".bz2")]):
        by_suffix = {".csv": "csv", ".mcap": "mcap", ".log": "carmen", ".dat": "xyz", ".xyz": "xyz",
                     ".pcd": "pcd", ".ply": "ply", ".bag": "rosbag", ".db3": "rosbag",
                     ".bin": "scans"}.get(suffix)  # a KITTI .bin scan: a sequence of one
        if by_suffix:
            return by_suffix
    raise InputError(
        f"cannot tell the format of {target}: expected CSV with an x,y,z header, MCAP, "
        "a CARMEN log, x y z point lines, PCD, PLY, a KITTI .bin scan or a ROS bag (or give format=)"
    )


def _numeric_fields(line: str) -> int:
    count = 0
    for item in line.split():
        try:
            float(item)
        except ValueError:
            return 0
        count += 1
    return count


__all__ = ["CARMEN_RECORDS", "MCAP_MAGIC", "SCAN_SUFFIXES", "detect_format", "is_log_folder", "is_scan_folder"]
