"""Reading flight logs, finished or cut short, and salvaging a cut-short one into a finished MCAP file.

A writer killed before ``finish()`` leaves a file without summary and footer: mcap's seeking reader rejects it and
its non-seeking reader in log-time order yields nothing. :func:`read_log` therefore always streams the records in
file order (schemas, channels, metadata, chunks), keeps every message of every complete chunk, catches whatever the
torn end raises and reports ``truncated=True``. A finished file reads the same way (file order is faster than
log-time order), then every topic is put in log-time order. :func:`salvage` streams the same records into a new
writer and finishes it, so the result opens in Foxglove and in mcap's seeking reader.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from mcap.exceptions import InvalidMagic
from mcap.records import Attachment, Channel, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader


class LogError(Exception):
    """The file cannot be read as a flight log at all (missing, unreadable, not MCAP)."""


class LogMessage(NamedTuple):
    """One message: log time and publish time (ns since the Unix epoch), per-channel sequence, decoded JSON."""

    log_time: int
    publish_time: int
    sequence: int
    data: Any


@dataclass
class LogData:
    """Everything in a flight log. ``topics`` maps each topic to its messages in log-time order; ``schemas`` each
    topic to its schema name; ``metadata`` each metadata record's name to its string map. ``truncated`` is true when
    the file ends before its footer (a killed writer); ``stop_reason`` then says what the torn end raised."""

    path: Path
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    topics: dict[str, list[LogMessage]] = field(default_factory=dict)
    schemas: dict[str, str] = field(default_factory=dict)
    truncated: bool = False
    stop_reason: str = ""
    undecodable: int = 0
    library: str = ""

    @property
    def message_count(self) -> int:
        return sum(len(v) for v in self.topics.values())

    @property
    def counts(self) -> dict[str, int]:
        """Messages per topic."""
        return {topic: len(msgs) for topic, msgs in self.topics.items()}

    @property
    def start_ns(self) -> int | None:
        times = [m[0].log_time for m in self.topics.values() if m]
        return min(times) if times else None

    @property
    def end_ns(self) -> int | None:
        times = [m[-1].log_time for m in self.topics.values() if m]
        return max(times) if times else None

    def summary(self) -> dict[str, Any]:
        """Counts: messages in all and per topic, first and last log time, truncation."""
        return {
            "message_count": self.message_count,
            "counts": self.counts,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "truncated": self.truncated,
        }

    def messages(self, topic: str) -> list[LogMessage]:
        """The messages of ``topic`` (empty if absent)."""
        return self.topics.get(topic, [])


def _open(path: str | Path):
    path = Path(path)
    if not path.exists():
        raise LogError("no such file")
    if path.is_dir():
        raise LogError("is a directory, not an MCAP file")
    try:
        return open(path, "rb")
    except OSError as err:
        raise LogError(f"cannot open: {err.strerror or err}") from None


def _records(f) -> Iterator[Any]:
    """The file's records in file order (chunks opened, CRCs checked); raises on a torn end."""
    reader = StreamReader(f, validate_crcs=True)
    records = reader.records
    try:
        first = next(records)
    except InvalidMagic:
        raise LogError("not an MCAP file (bad magic)") from None
    except StopIteration:
        raise LogError("not an MCAP file (empty)") from None
    except Exception:  # noqa: BLE001 - EndOfFile, struct.error: magic, then nothing readable
        raise LogError("not an MCAP file (no header record)") from None
    if not isinstance(first, Header):
        raise LogError("not an MCAP file (no header record)")
    yield first
    yield from records


def read_log(path: str | Path) -> LogData:
    """Read every message of a flight log (finished, or cut short by a kill: then ``truncated=True``).

    Raises :class:`LogError` when the file is missing, unreadable or not MCAP."""
    data = LogData(Path(path))
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    lists: dict[int, list[LogMessage]] = {}
    decode = json.loads
    finished = False
    with _open(path) as f:
        records = _records(f)
        try:
            for record in records:
                if isinstance(record, Message):
                    target = lists.get(record.channel_id)
                    if target is None:
                        if record.channel_id not in channels:
                            data.undecodable += 1
                            continue
                        topic, _ = channels[record.channel_id]
                        target = lists[record.channel_id] = data.topics.setdefault(topic, [])
                    payload: Any = record.data
                    if channels[record.channel_id][1] == "json":
                        try:
                            payload = decode(payload)
                        except ValueError:
                            data.undecodable += 1
                            continue
                    target.append(LogMessage(record.log_time, record.publish_time, record.sequence, payload))
                elif isinstance(record, Channel):
                    if record.id not in channels:
                        channels[record.id] = (record.topic, record.message_encoding)
                        data.topics.setdefault(record.topic, [])
                        data.schemas[record.topic] = schemas.get(record.schema_id, "")
                elif isinstance(record, Schema):
                    schemas.setdefault(record.id, record.name)
                elif isinstance(record, Metadata):
                    data.metadata.setdefault(record.name, dict(record.metadata))
                elif isinstance(record, Header):
                    data.library = record.library
                elif isinstance(record, Footer):
                    finished = True
        except LogError:
            raise
        except Exception as err:  # noqa: BLE001 - a torn end raises EndOfFile, struct.error, CRC errors, ...
            data.stop_reason = f"{type(err).__name__}: {err}".rstrip(": ")
    data.truncated = not finished
    for msgs in data.topics.values():
        if any(msgs[i].log_time > msgs[i + 1].log_time for i in range(len(msgs) - 1)):
            msgs.sort(key=lambda m: m.log_time)
    return data


@dataclass(frozen=True)
class SalvageResult:
    """What :func:`salvage` copied: messages, channels, metadata records; whether the source was truncated."""

    messages: int
    channels: int
    metadata: int
    truncated: bool
    stop_reason: str


def salvage(src: str | Path, dst: str | Path) -> SalvageResult:
    """Rewrite ``src`` (typically a log cut short by a kill) into a finished MCAP file ``dst``: the header, every
    schema, channel, metadata record, attachment and every message of every complete chunk, with a summary and
    footer, so mcap's seeking reader and Foxglove accept it. Raises :class:`LogError` for a file that is not MCAP."""
    from mcap.writer import CompressionType, Writer

    src, dst = Path(src), Path(dst)
    if src.resolve() == dst.resolve():
        raise ValueError("salvage needs a destination other than the source")
    part = dst.with_name(dst.name + ".part")
    schema_map: dict[int, int] = {}
    channel_map: dict[int, int] = {}
    messages = metadata = 0
    data_end = finished = False
    reason = ""
    source = _open(src)
    try:
        with source as f, open(part, "wb") as out:
            writer: Writer | None = None
            try:
                for record in _records(f):
                    if isinstance(record, Header):
                        writer = Writer(out, compression=CompressionType.ZSTD)
                        writer.start(profile=record.profile, library=record.library or "rpf_fly salvage")
                        continue
                    if writer is None:
                        raise LogError("not an MCAP file (no header record)")
                    if isinstance(record, Message):
                        channel = channel_map.get(record.channel_id)
                        if channel is not None:
                            writer.add_message(
                                channel, record.log_time, record.data, record.publish_time, record.sequence
                            )
                            messages += 1
                    elif isinstance(record, Schema):
                        if record.id not in schema_map:
                            schema_map[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                    elif isinstance(record, Channel):
                        if record.id not in channel_map:
                            channel_map[record.id] = writer.register_channel(
                                record.topic,
                                record.message_encoding,
                                schema_map.get(record.schema_id, 0),
                                dict(record.metadata),
                            )
                    elif isinstance(record, Metadata):
                        if not data_end:
                            writer.add_metadata(record.name, dict(record.metadata))
                            metadata += 1
                    elif isinstance(record, Attachment):
                        if not data_end:
                            writer.add_attachment(
                                record.create_time, record.log_time, record.name, record.media_type, record.data
                            )
                    elif isinstance(record, DataEnd):
                        data_end = True  # the summary section repeats schemas and channels: already copied
                    elif isinstance(record, Footer):
                        finished = True
            except LogError:
                raise
            except Exception as err:  # noqa: BLE001 - the torn end
                reason = f"{type(err).__name__}: {err}".rstrip(": ")
            if writer is None:
                raise LogError("not an MCAP file (no header record)")
            writer.finish()
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    os.replace(part, dst)
    return SalvageResult(messages, len(channel_map), metadata, not finished, reason)
