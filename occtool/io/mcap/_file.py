"""An open MCAP file: its summary and channels, CRC checks, library errors as InputError."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from occtool.errors import InputError
from occtool.io.mcap._channels import (
    CAMERA_INFO,
    DEPTH_KINDS,
    ODOMETRY,
    RANGE_KINDS,
    TF,
    _decoder_factories,
    _protobuf_available,
    channel_kind,
)


@dataclass
class ChannelRow:
    """One channel of an MCAP file as ``occtool info`` shows it."""

    topic: str
    schema: str
    encoding: str
    messages: int | None
    kind: str | None
    support: str


def _mcap_errors() -> tuple[type[BaseException], ...]:
    import struct
    import zlib

    from mcap.exceptions import McapError

    errors: list[type[BaseException]] = [
        McapError, struct.error, EOFError, zlib.error, UnicodeDecodeError, json.JSONDecodeError,
    ]
    try:
        from google.protobuf.message import DecodeError

        errors.append(DecodeError)
    except ImportError:
        pass
    try:  # a corrupt zstd chunk
        from zstandard import ZstdError

        errors.append(ZstdError)
    except ImportError:
        pass
    # A damaged chunk or index also surfaces as a plain error inside the mcap library: a
    # channel id missing from the summary (KeyError), a corrupt lz4 frame (RuntimeError).
    # A corrupt record length can ask for more memory than there is (MemoryError).
    errors += [KeyError, IndexError, ValueError, OverflowError, RuntimeError, MemoryError]
    return tuple(errors)


class _Reader:
    """An open MCAP file with its summary, turning library errors into InputError."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = str(path)
        self.handle = open(path, "rb")

    def __enter__(self) -> _Reader:
        from mcap.reader import make_reader

        try:
            self.reader = make_reader(self.handle, validate_crcs=True, decoder_factories=_decoder_factories())
            self.reader.get_header()
            self.summary = self.reader.get_summary()
        except (*_mcap_errors(), OSError) as exc:  # type: ignore[misc]  # OSError: a seek to a corrupt summary offset
            self.handle.close()
            raise self.corrupt(exc) from None
        return self

    def __exit__(self, *exc: object) -> None:
        self.handle.close()

    def corrupt(self, exc: BaseException) -> InputError:
        detail = str(exc) or type(exc).__name__
        if isinstance(exc, MemoryError):
            detail = "a record's length exceeds the memory available"
        return InputError(f"{self.path} is not a readable MCAP file (corrupt or truncated): {detail}")

    def channels(self) -> list[tuple[int, str, str, str, int | None]]:
        """``(id, topic, schema, encoding, message count)`` of each channel."""
        if self.summary is None:
            return self._scan_channels()
        counts = self.summary.statistics.channel_message_counts if self.summary.statistics else {}
        out = []
        for cid, channel in sorted(self.summary.channels.items()):
            schema = self.summary.schemas.get(channel.schema_id)
            out.append((cid, channel.topic, schema.name if schema else "", channel.message_encoding, counts.get(cid)))
        return out

    def _scan_channels(self) -> list[tuple[int, str, str, str, int | None]]:
        """Without a summary section, list channels by streaming the file once."""
        from mcap.reader import NonSeekingReader

        counts: dict[int, list[Any]] = {}
        with open(self.path, "rb") as handle:
            try:
                for schema, channel, _ in NonSeekingReader(handle, validate_crcs=True).iter_messages():
                    entry = counts.setdefault(
                        channel.id, [channel.topic, schema.name if schema else "", channel.message_encoding, 0]
                    )
                    entry[3] += 1
            except _mcap_errors() as exc:
                raise self.corrupt(exc) from None
        return [(cid, *entry) for cid, entry in sorted(counts.items())]

    def messages(self, topics: Sequence[str]) -> Iterator[tuple[Any, Any, Any, Any]]:
        try:
            yield from self.reader.iter_decoded_messages(topics=list(topics), log_time_order=True)
        except InputError:
            raise
        except _mcap_errors() as exc:
            raise self.corrupt(exc) from None


def describe_channels(path: str | os.PathLike[str]) -> tuple[list[ChannelRow], dict[str, str]]:
    """The channels of an MCAP file and what occtool can read, from its summary.

    Returns
    -------
    rows, extra
        One :class:`ChannelRow` per channel, and further facts (message count,
        duration) to show.
    """
    rows = []
    protobuf = _protobuf_available()
    with _Reader(path) as reader:
        for _, topic, schema, encoding, count in reader.channels():
            kind = channel_kind(schema, encoding)
            if kind in DEPTH_KINDS:
                support = "yes: depth images (depth encodings only)"
            elif kind in RANGE_KINDS:
                support = "yes: range data"
            elif kind == CAMERA_INFO:
                support = "yes: depth intrinsics"
            elif kind == TF:
                support = "yes: static frames" if topic.endswith("tf_static") else "yes: poses"
            elif kind == ODOMETRY:
                support = "yes: poses"
            else:
                support = "no"
            if encoding == "protobuf" and kind is not None and not protobuf:
                support = "needs occtool[protobuf]"
            rows.append(ChannelRow(topic, schema, encoding, count, kind, support))
        extra: dict[str, str] = {}
        stats = reader.summary.statistics if reader.summary else None
        if stats is not None:
            extra["messages"] = f"{stats.message_count:,}"
            if stats.message_count:
                extra["duration"] = f"{(stats.message_end_time - stats.message_start_time) * 1e-9:.3f} s"
        else:
            extra["summary"] = "none (channels counted by reading the file)"
        extra["checksums"] = _describe_checksums(reader)
    return rows, extra


def _describe_checksums(reader: _Reader) -> str:
    """Whether the file's chunks carry CRC32s (read back from each chunk's record header)."""
    import struct

    indexes = reader.summary.chunk_indexes if reader.summary is not None else []
    if not indexes:
        return "unknown: no chunk index (the data section's CRC, if any, is checked on a full read)"
    missing = 0
    for index in indexes:
        # Chunk record: opcode (1), length (8), start time (8), end time (8), uncompressed
        # size (8), then the uncompressed data's CRC32 (4); 0 means "not computed".
        reader.handle.seek(index.chunk_start_offset + 33)
        raw = reader.handle.read(4)
        if len(raw) < 4 or struct.unpack("<I", raw)[0] == 0:
            missing += 1
    if missing == len(indexes):
        return f"none: its {len(indexes):,} chunk(s) carry no CRC32, so corrupt data cannot be detected"
    if missing:
        return (f"{len(indexes) - missing:,} of {len(indexes):,} chunks carry a CRC32 (checked on read); "
                f"{missing:,} do not")
    return f"CRC32 on all {len(indexes):,} chunk(s), checked on read"

