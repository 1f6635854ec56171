"""Writing a log on occtool's own MCAP channel."""

from __future__ import annotations

import base64
import json
import os

import numpy as np

from occtool.errors import InputError
from occtool.features import Features, Position, RangeLog
from occtool.io.mcap._channels import OCCTOOL_FORMAT_VERSION, OCCTOOL_JSON_SCHEMA, OCCTOOL_SCHEMA_NAME, OCCTOOL_TOPIC


def write_mcap(log: RangeLog | Features, path: str | os.PathLike[str]) -> None:
    """Write a log as MCAP on occtool's JSON channel ``/occtool/features``.

    One message per position, holding its features (base64 float64, so values round
    trip exactly), pose and stamp; the channel's JSON schema documents the layout.
    The file is written atomically.

    Parameters
    ----------
    log
        The positions to write (a bare :class:`Features` is one position without pose).
    path
        Output ``.mcap`` file.
    """
    from mcap.writer import CompressionType, Writer

    from occtool._files import atomic_write
    from occtool._version import __version__

    if isinstance(log, Features):
        log = RangeLog(positions=[Position(0, log)])
    if str(path) == "-":
        raise InputError("MCAP output needs a file name, not standard output")
    with atomic_write(path, "wb") as handle:
        writer = Writer(handle, compression=CompressionType.ZSTD if _has_zstd() else CompressionType.NONE)
        writer.start(profile="", library=f"occtool {__version__}")
        schema_id = writer.register_schema(
            name=OCCTOOL_SCHEMA_NAME, encoding="jsonschema", data=json.dumps(OCCTOOL_JSON_SCHEMA).encode()
        )
        channel_id = writer.register_channel(
            topic=OCCTOOL_TOPIC, message_encoding="json", schema_id=schema_id,
            metadata={"frame": "sensor-centred robot frame (REP-103)"},
        )
        for k, position in enumerate(log.positions):
            f = position.features
            payload = {
                "version": OCCTOOL_FORMAT_VERSION,
                "position": k,
                "stamp": position.stamp,
                "frame": "sensor-centred robot frame (REP-103)",
                "pose": position.pose.to_dict() if position.pose is not None else None,
                "count": len(f),
                "points": base64.b64encode(np.ascontiguousarray(f.points, dtype="<f8").tobytes()).decode("ascii"),
                "evidence": base64.b64encode(np.ascontiguousarray(f.evidence, dtype="<f8").tobytes()).decode("ascii"),
            }
            # log_time orders messages: the stamp when known, else the position index.
            time_ns = int(round(position.stamp * 1e9)) if position.stamp is not None and position.stamp >= 0 else k
            writer.add_message(channel_id, log_time=time_ns, publish_time=time_ns, sequence=k,
                               data=json.dumps(payload).encode())
        writer.finish()


def _has_zstd() -> bool:
    try:
        import zstandard  # noqa: F401
    except ImportError:
        return False
    return True

