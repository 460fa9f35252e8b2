"""Reading and writing the project's MCAP files (the only module besides record/replay that imports mcap).

Every message is stored with its Zenoh key as the channel topic, its log time (ns since the epoch,
when the recorder received it) and its protobuf schema (a FileDescriptorSet: the file is
self-describing; standard tools decode it). Payloads with no protobuf encoding are stored with an
empty schema and message encoding "" (raw bytes).

Reading is tolerant: a file cut short (a recorder killed with SIGKILL) is read up to its last
complete chunk, and `recover()` rewrites such a file into a complete one that every tool opens.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass
from typing import BinaryIO

from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, IndexType, Writer

log = logging.getLogger("sme.mcap")

PROFILE = ""
LIBRARY = "sensorimotor-embedding"
COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


@dataclass(frozen=True)
class Record:
    """One message of a recording.

    Attributes
    ----------
    topic : str
        The zenoh key it was published on.
    schema : str
        Its protobuf full name, or "" for raw payloads.
    log_time : int
        When the recorder received it, in ns since the epoch.
    data : bytes
        The payload.
    sequence : int
        The writer's sequence number.
    """

    topic: str  # the zenoh key
    schema: str  # protobuf full name, or "" for raw payloads
    log_time: int  # ns since the epoch
    data: bytes
    sequence: int = 0


class McapSink:
    """An MCAP writer that registers one channel per key and one schema per message type."""

    def __init__(self, stream: BinaryIO, compression: str = "zstd", chunk_size: int = 64 * 1024) -> None:
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {sorted(COMPRESSIONS)}")
        # No per-chunk message indexes: the writer keeps every chunk's index in memory until finish()
        # writes the summary, and with a chunk every 0.2 s the message indexes (one offset per channel
        # per chunk) were most of a long recording's memory (3000 chunks x 20 channels: 4.5 MB with
        # them, 0.9 MB without). Chunk indexes stay, so readers still seek by time; they read each
        # chunk whole, which they do anyway for chunks this small.
        self._w = Writer(
            stream,
            chunk_size=chunk_size,
            compression=COMPRESSIONS[compression],
            index_types=IndexType.CHUNK | IndexType.ATTACHMENT | IndexType.METADATA,
        )
        self._w.start(profile=PROFILE, library=LIBRARY)
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self.count = 0

    def _schema_id(self, schema: str) -> int:
        sid = self._schemas.get(schema)
        if sid is None:
            if not schema:
                sid = 0
            else:
                from sensorimotor.protocol.codec import descriptor_set

                try:
                    sid = self._w.register_schema(schema, "protobuf", descriptor_set(schema))
                except KeyError:
                    log.warning("no descriptor for %s: stored as raw bytes", schema)
                    sid = 0
            self._schemas[schema] = sid
        return sid

    def write(self, rec: Record) -> None:
        """Append one message, registering its channel and schema on first use."""
        key = (rec.topic, rec.schema)
        cid = self._channels.get(key)
        if cid is None:
            sid = self._schema_id(rec.schema)
            cid = self._w.register_channel(rec.topic, "protobuf" if sid else "", sid)
            self._channels[key] = cid
        self._w.add_message(cid, rec.log_time, rec.data, rec.log_time, rec.sequence)
        self.count += 1

    def write_ros2(self, topic: str, ros_type: str, msgdef: str, log_time: int, data: bytes, sequence: int = 0) -> None:
        """Append one ROS 2 message (CDR) on channel `topic` with its ``ros2msg`` schema (as rosbag2
        writes them: Foxglove and the ROS tools decode it)."""
        key = (topic, "ros2msg:" + ros_type)
        cid = self._channels.get(key)
        if cid is None:
            sid = self._schemas.get(key[1])
            if sid is None:
                sid = self._schemas[key[1]] = self._w.register_schema(ros_type, "ros2msg", msgdef.encode())
            cid = self._channels[key] = self._w.register_channel(topic, "cdr", sid)
        self._w.add_message(cid, log_time, data, log_time, sequence)
        self.count += 1

    def flush(self) -> None:
        """Close the chunk in progress and push it to the file (a later kill cannot lose it)."""
        self._w.flush()

    def finish(self) -> None:
        """Write the summary and footer: the file is complete (the stream stays open)."""
        self._w.finish()


def schema_of(encoding: str) -> str:
    """'application/protobuf;sme.v1.Observation' -> 'sme.v1.Observation'; anything else -> ''."""
    prefix = "application/protobuf;"
    return encoding[len(prefix) :] if encoding.startswith(prefix) else ""


def read(path: str) -> Iterator[Record]:
    """Every message in write order, up to the end of the file or its last complete chunk (ROS 2
    channels, CDR-encoded, are left out: they are for ROS tools)."""
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    ros2: set[int] = set()
    with open(path, "rb") as f:
        reader = StreamReader(f, skip_magic=False, emit_chunks=False)
        it = iter(reader.records)
        while True:
            try:
                rec = next(it)
            except StopIteration:
                return
            except Exception as e:  # EndOfFile at a cut, or a damaged record: either way, the end
                log.warning(
                    "%s: stopped at a truncated or damaged record (%s): read what came before it",
                    path,
                    type(e).__name__,
                )
                return
            if isinstance(rec, Schema):
                schemas[rec.id] = rec.name
            elif isinstance(rec, Channel):
                if rec.message_encoding == "cdr":  # a ROS 2 topic (`sme record --ros2`): for ROS tools, not replayed
                    ros2.add(rec.id)
                channels[rec.id] = (rec.topic, schemas.get(rec.schema_id, ""))
            elif isinstance(rec, Message):
                if rec.channel_id in ros2:
                    continue
                topic, schema = channels.get(rec.channel_id, ("?", ""))
                yield Record(topic, schema, rec.log_time, bytes(rec.data), rec.sequence)


def recover(src: str, dst: str, compression: str = "zstd") -> int:
    """Rewrite a (possibly truncated) recording into a complete MCAP file; returns messages kept."""
    with open(dst, "wb") as f:
        sink = McapSink(f, compression)
        for rec in read(src):
            sink.write(rec)
        sink.finish()
        return sink.count
