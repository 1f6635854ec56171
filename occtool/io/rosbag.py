"""ROS bags through ``rosbags`` (pure Python, no ROS install; the ``bags`` extra).

ROS 1 ``.bag`` files and ROS 2 bags (a ``.db3`` or ``.mcap`` storage file in its bag
folder, beside ``metadata.yaml``) are read with the same message types, ``--topic``
and options as MCAP: ``sensor_msgs/LaserScan`` and ``PointCloud2``, ``/tf_static``
for the mounting, ``/tf`` or ``nav_msgs/Odometry`` for poses. Only the container
differs: :class:`BagReader` offers the two methods :func:`occtool.io.mcap.read_mcap`
reads through (``channels``, ``messages``), and the messages are decoded by the same
code as MCAP's, so a bag and its MCAP twin give the same features.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from occtool.errors import InputError, MissingDependencyError

#: The first bytes of a ROS 1 bag (format 2.0) and of an SQLite database (ROS 2 ``.db3``).
ROS1_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"


def _bag_paths(path: Path) -> Path:
    """What ``rosbags`` opens: a ROS 1 file, or a ROS 2 bag's folder."""
    with open(path, "rb") as handle:
        head = handle.read(16)
    if head.startswith(ROS1_MAGIC):
        return path
    if not (path.parent / "metadata.yaml").is_file():
        raise InputError(f"{path} is a ROS 2 bag storage file without its metadata.yaml beside it "
                         "(read the bag's folder as written by ros2 bag record)")
    return path.parent


class BagReader:
    """An open ROS bag with the interface :func:`occtool.io.mcap.read_mcap` reads through."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = str(path)

    def __enter__(self) -> BagReader:  # noqa: PYI034 - as io.mcap._file._Reader
        try:
            from rosbags.highlevel import AnyReader
            from rosbags.typesys import Stores, get_typestore
        except ImportError:
            raise MissingDependencyError("rosbags", "bags", f"reading the ROS bag {self.path}") from None
        target = _bag_paths(Path(self.path))
        if target.is_file() and target.suffix != ".bag":
            # rosbags tells ROS 1 from ROS 2 by the suffix: give a ROS 1 bag its own.
            raise InputError(f"{self.path} is a ROS 1 bag: name it *.bag to read it")
        try:
            self.reader = AnyReader([target], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
            self.reader.open()
        except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds on a damaged bag
            raise self.corrupt(exc) from None
        return self

    def __exit__(self, *exc: object) -> None:
        reader = getattr(self, "reader", None)
        if reader is not None:
            reader.close()

    def corrupt(self, exc: BaseException) -> InputError:
        return InputError(f"{self.path} is not a readable ROS bag (corrupt or truncated): {exc or type(exc).__name__}")

    def channels(self) -> list[tuple[int, str, str, str, int | None]]:
        """``(id, topic, message type, "cdr", message count)`` of each connection, one per topic."""
        by_topic: dict[str, list[Any]] = {}
        for connection in self.reader.connections:
            row = by_topic.setdefault(connection.topic, [len(by_topic), connection.topic, connection.msgtype, "cdr", 0])
            row[4] += connection.msgcount
        return [tuple(row) for row in by_topic.values()]

    def messages(self, topics: Sequence[str]) -> Iterator[tuple[Any, Any, Any, Any]]:
        """``(schema, channel, record, message)`` in time order, as the MCAP reader yields them."""
        wanted = set(topics)
        connections = [c for c in self.reader.connections if c.topic in wanted]
        try:
            for sequence, (connection, stamp, raw) in enumerate(self.reader.messages(connections=connections)):
                message = self.reader.deserialize(raw, connection.msgtype)
                yield (SimpleNamespace(name=connection.msgtype), SimpleNamespace(topic=connection.topic),
                       SimpleNamespace(sequence=sequence, log_time=stamp), message)
        except InputError:
            raise
        except Exception as exc:  # noqa: BLE001
            raise self.corrupt(exc) from None


def read_rosbag(path: str | os.PathLike[str], **options: Any) -> Any:
    """Read the range topics of a ROS bag; the options are those of :func:`occtool.io.mcap.read_mcap`."""
    from occtool.io.mcap import read_mcap

    return read_mcap(path, opener=BagReader, **options)


__all__ = ["ROS1_MAGIC", "SQLITE_MAGIC", "BagReader", "read_rosbag"]
