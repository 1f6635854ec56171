"""A model set's index (``index.json``): written as positions finish, read back checked.

The index lists each position's model file, pose, stamp, feature count and the digest of
its features (the ``occtool-model-set`` format); :func:`read_model_set` reads it and
checks that every file it names is a regular file inside the set's folder.
"""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path
from typing import Any

from occtool._files import atomic_write
from occtool._json import loads
from occtool.errors import InputError

#: The index of a model set: one model per robot position (``occtool fit LOG -o DIR/``).
MODEL_SET_FORMAT = "occtool-model-set"


def save_model_set_index(folder: str | os.PathLike[str], entries: list[dict[str, Any]], *, source: str,
                         complete: bool = True, failed: list[dict[str, Any]] | None = None) -> None:
    """Write ``folder/index.json`` for a model set (one model file per robot position), atomically.

    Each entry has ``position``, ``file``, ``pose`` (a dict in the world frame, or
    ``None``), ``stamp`` and ``features``; :func:`read_model_set` reads it back.
    ``complete`` is false while a fit is running or after it was interrupted;
    ``failed`` lists ``{"position", "reason"}`` of positions that could not be fitted.
    """
    header = json.dumps({"format": MODEL_SET_FORMAT, "format_version": 1, "source": source,
                         "frame": "base_link", "poses_frame": "map", "complete": bool(complete),
                         "failed": list(failed or []), "models": "@@models@@"}, indent=1)
    # One entry a line, by the C encoder: a running fit rewrites the index often.
    models = "[\n  " + ",\n  ".join(json.dumps(entry) for entry in entries) + "\n ]" if entries else "[]"
    with atomic_write(Path(folder) / "index.json", "w") as handle:
        handle.write(header.replace('"@@models@@"', models, 1) + "\n")


#: Largest index.json read (a set of a million positions takes about 300 MB).
MAX_INDEX_BYTES = 512 * 1024 * 1024
#: Versions of the index :func:`read_model_set` reads.
READS = (1,)
#: The keys of an entry's pose (:meth:`occtool.features.Pose.to_dict`), every one required.
POSE_KEYS = ("x", "y", "z", "yaw")
#: Deepest an index's JSON nests (entries nest 3 deep: ``"models": [{"pose": {}}]``).
MAX_INDEX_DEPTH = 16
#: Largest stamp (seconds) an entry may carry: times written as signed 64-bit nanoseconds
#: (ROS, protobuf's Timestamp) end in the year 2262; a stamp past that is damage, not a time.
MAX_STAMP = float(2**63 - 1) / 1e9


def check_pose(pose: Any, where: str) -> None:
    """An :class:`InputError` naming ``where`` unless ``pose`` is an object of exactly
    :data:`POSE_KEYS`, each a finite number (not a boolean) of at most
    :data:`occtool.limits.MAX_WORLD_COORDINATE` (metres, radians for ``yaw``)."""
    from occtool.limits import MAX_WORLD_COORDINATE

    if not isinstance(pose, dict):
        raise InputError(f"{where}: 'pose' is not an object")
    missing = [key for key in POSE_KEYS if key not in pose]
    extra = sorted(str(key)[:20] for key in pose if key not in POSE_KEYS)
    if missing or extra:
        raise InputError(f"{where}: 'pose' needs exactly {', '.join(POSE_KEYS)}"
                         + (f" (missing {', '.join(missing)})" if missing else f" (unknown {', '.join(extra)})"))
    for key in POSE_KEYS:
        value = pose[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"{where}: pose {key} is {type(value).__name__}, not a number")
        if not (math.isfinite(value) and abs(value) <= MAX_WORLD_COORDINATE):
            raise InputError(f"{where}: pose {key} = {value!r:.30} is not a finite number of at most "
                             f"{MAX_WORLD_COORDINATE:g}")


def check_stamp(stamp: Any, where: str) -> None:
    """An :class:`InputError` naming ``where`` unless ``stamp`` is ``None`` or a finite
    number (not a boolean) of at most :data:`MAX_STAMP` seconds either way (a log's
    stamps may count from any origin; the MCAP writer places a negative one by order)."""
    if stamp is None:
        return
    if isinstance(stamp, bool) or not isinstance(stamp, (int, float)):
        raise InputError(f"{where}: stamp is {type(stamp).__name__}, not a number of seconds or null")
    if not (math.isfinite(stamp) and abs(stamp) <= MAX_STAMP):
        raise InputError(f"{where}: stamp = {stamp!r:.30} is not a finite time of at most {MAX_STAMP:.4g} s")


def _set_member(folder: Path, name: str, where: str) -> Path:
    """``folder / name`` if it names a regular file inside the set's folder, else InputError.

    Checked with ``os.stat`` before anything opens it: a FIFO or device would block or
    never end, and ``../x.json``, an absolute path or a link out of the folder would read
    files the set does not own.
    """
    relative = Path(name)
    if not name or relative.is_absolute() or ".." in relative.parts or "\x00" in name:
        raise InputError(f"{where}: file {name!r} must be a name inside the set's folder")
    target = folder / relative
    try:
        inside = target.resolve().is_relative_to(folder.resolve())
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        raise InputError(f"{where}: file {name!r} does not exist") from None
    except (OSError, RuntimeError) as exc:  # a loop of links, a name too long
        raise InputError(f"{where}: file {name!r} cannot be read ({exc})") from None
    if not inside:
        raise InputError(f"{where}: file {name!r} leads out of the set's folder")
    if not stat.S_ISREG(mode):
        raise InputError(f"{where}: file {name!r} is not a regular file")
    return target


def read_model_set(path: str | os.PathLike[str]) -> tuple[Any, list[dict[str, Any]]]:
    """The folder and entries of a model set (``occtool fit -o DIR/``): ``DIR`` or ``DIR/index.json``.

    Returns
    -------
    folder, entries
        Each entry has ``position``, ``file`` and ``pose`` (a dict or ``None``); every
        ``file`` is a regular file inside ``folder``, no position appears twice and every
        pose is checked once here (:func:`check_pose`): readers of the set take it as it is.

    Raises
    ------
    InputError
        If the index is missing or malformed (JSON nested deeper than
        :data:`MAX_INDEX_DEPTH`, a ``format_version`` not in :data:`READS`), or an entry
        names a file outside the folder, a missing or non-regular file, a position listed
        before, a pose that is no pose (a key missing or unknown, a boolean, NaN,
        infinite or past :data:`occtool.limits.MAX_WORLD_COORDINATE`) or a stamp that is
        no time (:func:`check_stamp`); the message names the file and the entry.
    """
    index = Path(path) / "index.json" if Path(path).is_dir() else Path(path)
    try:
        mode = os.stat(index).st_mode
    except OSError:
        mode = 0
    if not stat.S_ISREG(mode):
        raise InputError(
            f"{path}: a folder without index.json is not a model set (write one with `occtool fit -o DIR/`)"
        )
    if os.stat(index).st_size > MAX_INDEX_BYTES:
        raise InputError(f"{index}: larger than {MAX_INDEX_BYTES >> 20} MB, not a model-set index")
    try:
        data = loads(index.read_text(encoding="utf-8"), max_depth=MAX_INDEX_DEPTH)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{index}: not valid JSON ({exc})") from None
    is_index = isinstance(data, dict) and data.get("format") == MODEL_SET_FORMAT
    if not (is_index and isinstance(data.get("models"), list)):
        raise InputError(f"{index}: not an occtool model-set index")
    version = data.get("format_version")
    if isinstance(version, bool) or version not in READS:
        raise InputError(f"{index}: format_version {version!r:.30}, this occtool reads "
                         f"{', '.join(map(str, READS))} (a newer occtool wrote it, or it is damaged)")
    folder = index.parent
    entries = []
    positions: set[int] = set()
    files: set[str] = set()
    for number, entry in enumerate(data["models"], start=1):
        named = isinstance(entry, dict) and isinstance(entry.get("file"), str)
        if not (named and isinstance(entry.get("position"), int) and not isinstance(entry.get("position"), bool)):
            raise InputError(f"{index}: model entry {number} needs an integer 'position' and a 'file'")
        if entry["position"] < 0:
            raise InputError(f"{index}: model entry {number}'s position {entry['position']} is negative")
        if entry.get("pose") is not None:
            check_pose(entry["pose"], f"{index}: model entry {number} (position {entry['position']})")
        check_stamp(entry.get("stamp"), f"{index}: model entry {number} (position {entry['position']})")
        if entry["position"] in positions:
            raise InputError(f"{index}: position {entry['position']} is listed twice")
        _set_member(folder, entry["file"], f"{index}: model entry {number}")
        if os.path.normpath(entry["file"]) in files:
            raise InputError(f"{index}: file {entry['file']!r} is listed twice")
        positions.add(entry["position"])
        files.add(os.path.normpath(entry["file"]))
        entries.append(entry)
    if not entries:
        raise InputError(f"{index}: the model set lists no models")
    return folder, entries


__all__ = ["MAX_INDEX_BYTES", "MODEL_SET_FORMAT", "POSE_KEYS", "check_pose", "check_stamp", "read_model_set",
           "save_model_set_index"]
