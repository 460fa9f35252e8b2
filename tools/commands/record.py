"""`sme record FILE.mcap`: record every message of a session into a self-describing MCAP file.

The file is created before the bus is touched, so a missing or read-only directory fails at once
(exit 2). A write that fails while recording (a full disk: ENOSPC) stops the recorder with exit 1 and
a clear error; the file then reads back up to its last complete chunk (`sme recover` completes it).
"""

from __future__ import annotations

import argparse
import collections
import errno
import logging
import os
import signal
import sys
import threading
import time
from typing import Any, BinaryIO

from sensorimotor.protocol import codec, heap, keys
from sensorimotor.protocol.bus import (
    Bus,
    BusError,
    BusMessage,
    add_bus_arguments,
    bus_config_from_args,
    check_key_expr,
)
from sensorimotor.protocol.messages import Truth, WorldSpec
from sensorimotor.tools.mcap_io import COMPRESSIONS, McapSink, Record, schema_of

log = logging.getLogger("sme.record")

#: the encoding `Recorder.add_ros2` queues ROS 2 messages under (never a zenoh encoding of ours)
ROS2_ENCODING = "ros2msg;"

#: errno values that mean "no room left": the disk or the user's quota is full
DISK_FULL = (errno.ENOSPC, errno.EDQUOT)


def describe_write_error(e: OSError) -> str:
    """'disk full (...)' for ENOSPC and friends, 'write failed (...)' for other OS errors."""
    what = "disk full" if e.errno in DISK_FULL else "write failed"
    return f"{what} ({e.strerror or e})"


def open_output(path: str) -> BinaryIO:
    """Create (or truncate) the recording file: an OSError with a clear message if the directory is
    missing, not a directory, or not writable. Done before connecting, so nothing waits in vain."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise OSError(errno.ENOENT, f"cannot record to {path}: the directory {folder} does not exist")
    if os.path.isdir(path):
        raise OSError(errno.EISDIR, f"cannot record to {path}: it is a directory")
    try:
        return open(path, "wb")  # buffered: McapSink.flush() pushes it to the OS
    except OSError as e:
        raise OSError(e.errno, f"cannot record to {path}: {e.strerror or e}") from None


def observation_step(payload: bytes, world_id: str | None = None) -> int | None:
    """The `step` (field 4) of an encoded Observation, read without decoding the tensors; None
    when the bytes do not start like one of schema version 1 (fields 1-4 in order, as every
    encoder writes them) or, with `world_id`, are for another world: only real observations count."""
    i, n = 0, len(payload)
    version, wid, step = 0, "", 0
    while i < n:
        tag, i = _varint(payload, i)
        if tag is None:
            return None
        field, wire = tag >> 3, tag & 7
        if field > 4:
            break
        if wire == 0 and field in (1, 3, 4):
            value, i = _varint(payload, i)
            if value is None:
                return None
            if field == 1:
                version = value
            elif field == 4:
                step = value
                break
        elif wire == 2 and field == 2:
            size, i = _varint(payload, i)
            if size is None or i + size > n:
                return None
            wid = payload[i : i + size].decode("utf-8", "replace")
            i += size
        else:
            return None
    if version != 1 or (world_id is not None and wid != world_id):
        return None
    return step  # proto3 leaves a 0 out


def _varint(data: bytes, i: int) -> tuple[int | None, int]:
    value, shift = 0, 0
    while i < len(data) and shift < 64:
        b = data[i]
        i += 1
        value |= (b & 0x7F) << shift
        if not b & 0x80:
            return value, i
        shift += 7
    return None, i


class Recorder:
    """Subscribes to `key_expr` and writes every message on one writer thread. Chunks are closed
    and pushed to the OS at least every `flush_every` seconds (0.2 s), so a
    recorder killed with SIGKILL loses at most the last 0.2 s (or chunk) of messages: what reached the
    OS survives the kill. Every `trim_every` seconds (10 s) freed heap memory goes back to the OS
    (`protocol.heap.trim`), so a recording of hours keeps a flat resident size. When a world
    appears, its spec and truth (served by queryables, not published) are fetched and written too,
    so a recording can be replayed into a fresh agent.

    A write, flush or finish that fails (a full disk) stops the writing: `error` says why (it
    contains "disk full" for ENOSPC), `failed` is set, further messages are dropped, and the file
    keeps everything up to its last complete chunk. `stream` is an already opened file (see
    `open_output`); by default `path` is opened here.

    A recorder never slows the session it records: the bus drops the messages a stalled reader
    cannot take (see `Bus.publisher`), and messages that arrive faster than the file is written
    wait in a backlog of at most `max_backlog_bytes`; beyond it new ones are dropped. Both losses
    are counted: `dropped` (backlog full) and `lost` (observation steps of a world that never
    arrived: gaps in its step counter, e.g. after the recorder was frozen)."""

    def __init__(
        self,
        bus: Bus,
        path: str,
        key_expr: str = keys.ALL,
        compression: str = "zstd",
        chunk_size: int = 1024 * 1024,
        flush_every: float = 0.2,
        trim_every: float = 10.0,
        stream: BinaryIO | None = None,
        max_backlog_bytes: int = 256 * 1024 * 1024,
    ) -> None:
        self.bus = bus
        self.max_backlog_bytes = max_backlog_bytes
        self.path = path
        self.key_expr = key_expr
        self.flush_every = flush_every
        self.trim_every = trim_every
        self.error: str | None = None
        self.failed = threading.Event()
        self._file = stream if stream is not None else open_output(path)
        try:
            self._sink = McapSink(self._file, compression, chunk_size)  # writes the header
        except OSError as e:
            self._fail(e, "starting")
        self._queue: collections.deque[tuple[int, BusMessage]] = collections.deque()
        self._cv = threading.Condition()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self.received = 0
        self.by_key: collections.Counter[str] = collections.Counter()
        self.max_backlog = 0
        self.dropped = 0  # messages dropped because the backlog was full
        self.lost = 0  # observation steps missing from a world's sequence (never reached the recorder)
        self._backlog_bytes = 0
        self._last_step: dict[str, int] = {}  # obs key -> last observation step seen
        self._worlds: set[str] = set()
        self._seq = 0
        self._ros2_defs: dict[str, str] = {}  # ROS 2 type -> its message definition (add_ros2)

    def _fail(self, e: OSError, when: str) -> None:
        """Remember the first write error and stop writing (the file keeps its complete chunks)."""
        if self.error is None:
            self.error = f"{describe_write_error(e)} while {when} {self.path}"
            log.debug("%s", self.error)  # `error` carries it; `sme record` prints it
        self.failed.set()

    def _on(self, msg: BusMessage) -> None:
        if msg.kind != "put" or self.failed.is_set():
            return
        if msg.key.endswith("/obs"):
            self._count_gap(msg)
        with self._cv:
            self.received += 1
            if self._backlog_bytes + len(msg.payload) > self.max_backlog_bytes:
                self.dropped += 1
                return
            self._queue.append((time.time_ns(), msg))
            self._backlog_bytes += len(msg.payload)
            self.max_backlog = max(self.max_backlog, len(self._queue))
            self._cv.notify()

    def add_ros2(self, sample: Any) -> None:
        """Queue one ROS 2 message (a `worlds.ros2.tap.TappedSample`) for its own ``ros2msg`` channel."""
        self._ros2_defs.setdefault(sample.ros_type, sample.msgdef)
        self._on(BusMessage(sample.topic, sample.payload, ROS2_ENCODING + sample.ros_type))

    def _count_gap(self, msg: BusMessage) -> None:
        """Count the observation steps of a world that never reached the recorder (a lockstep world
        numbers them 1, 2, 3, ...; a resend repeats one; a restarted world starts again lower)."""
        step = observation_step(msg.payload, msg.key.split("/")[-2])
        if step is None:
            return
        last = self._last_step.get(msg.key)
        if last is not None and step > last + 1:
            self.lost += step - last - 1
        self._last_step[msg.key] = step

    def _on_alive(self, key: str, alive: bool) -> None:
        wid = keys.last_chunk(key)
        if alive and wid not in self._worlds:
            self._worlds.add(wid)
            threading.Thread(target=self._fetch_world, args=(wid,), daemon=True).start()
        elif not alive:
            self._worlds.discard(wid)

    def _fetch_world(self, wid: str) -> None:
        for key, cls in ((keys.world_spec(wid), WorldSpec), (keys.world_truth(wid), Truth)):
            try:
                for r in self.bus.get(key, timeout=2.0):
                    self._on(BusMessage(key, r.payload, f"application/protobuf;{codec.schema_name(cls)}"))
            except BusError as e:
                log.debug("world %s: %s", wid, e)

    def start(self) -> Recorder:
        self._thread.start()
        self.bus.subscribe(self.key_expr, self._on)
        if self.key_expr in (keys.ALL, f"{keys.PREFIX}/**"):
            self.bus.watch_alive(keys.ALL_ALIVE_WORLDS, self._on_alive, history=True)
        return self

    def _run(self) -> None:
        try:
            self._write_loop()
        except OSError as e:  # ENOSPC and friends, from a write or a flush
            self._fail(e, "writing")
        with self._cv:  # nothing more will be written
            self._queue.clear()

    def _write_loop(self) -> None:
        last_flush = last_trim = time.monotonic()
        while not self.failed.is_set():
            with self._cv:
                if not self._queue:
                    if self._stop.is_set():
                        break
                    self._cv.wait(0.2)
                batch = list(self._queue)
                self._queue.clear()
                self._backlog_bytes = 0
            for t, msg in batch:
                self._seq += 1
                if msg.encoding.startswith(ROS2_ENCODING):
                    rt = msg.encoding[len(ROS2_ENCODING) :]
                    self._sink.write_ros2(msg.key, rt, self._ros2_defs[rt], t, msg.payload, self._seq)
                else:
                    self._sink.write(Record(msg.key, schema_of(msg.encoding), t, msg.payload, self._seq))
                self.by_key[msg.key] += 1
            if time.monotonic() - last_flush >= self.flush_every:
                self._sink.flush()
                last_flush = time.monotonic()
            if last_flush - last_trim >= self.trim_every:  # see protocol/heap.py: RSS stays flat
                heap.trim()
                last_trim = last_flush

    @property
    def written(self) -> int:
        """Messages handed to the MCAP writer (after a write error, not all of them are in the file)."""
        sink = getattr(self, "_sink", None)
        return sink.count if sink is not None else 0

    def stop(self) -> None:
        """Write everything received, finish the file (summary and index), close it. After a write
        error the file is closed as it is (readable up to its last complete chunk); a finish or
        close that fails now sets `error` too. Never raises an OSError."""
        self._stop.set()
        with self._cv:
            self._cv.notify_all()
        if self._thread.is_alive():
            self._thread.join()
        if not self.failed.is_set():
            try:
                self._sink.finish()
            except OSError as e:
                self._fail(e, "finishing")
        try:
            self._file.close()  # flushes what is buffered: may fail on a full disk too
        except OSError as e:
            self._fail(e, "closing")

    def __enter__(self) -> Recorder:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "record",
        help="record a session to an MCAP file",
        description="Record every message on the bus (observations, actions, controls, truth, "
        "specs, embeddings, agent events, camera frames as foxglove.RawImage) into an MCAP file "
        "with its protobuf schemas embedded, so standard tools (mcap CLI, Foxglove, `rerun mcap "
        "convert`) read it. Chunks are flushed every 0.2 s: a recorder killed with SIGKILL "
        "leaves a file `sme replay` reads up to its last complete chunk, and `sme recover` turns "
        "into a complete one. FILE is created before connecting (a missing or read-only directory: "
        "exit 2); a disk that fills stops the recorder with exit 1 and the file readable up to its last "
        "complete chunk. Stop with Ctrl-C or --seconds.",
    )
    p.add_argument("file", help="output .mcap file")
    p.add_argument(
        "--keys", default=keys.ALL, metavar="EXPR", help=f"zenoh key expression to record (default {keys.ALL})"
    )
    p.add_argument("--seconds", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--compression", choices=sorted(COMPRESSIONS), default="zstd", help="chunk compression")
    p.add_argument(
        "--chunk-kb",
        type=int,
        default=1024,
        help="largest chunk in KB (default 1024). Chunks are also closed every 0.2 s, so a kill loses at most "
        "that; larger chunks compress better and mean fewer chunk-index entries held until the file is finished",
    )
    p.add_argument(
        "--ros2",
        default=None,
        metavar="ENDPOINT",
        help="also record every topic of the ROS 2 robot whose rmw_zenohd router is at ENDPOINT, as CDR with "
        "its ros2msg schema (the channels rosbag2 and Foxglove read; docs/ros2.md)",
    )
    p.add_argument("--ros2-domain", type=int, default=0, metavar="N", help="the robot's ROS_DOMAIN_ID (default 0)")
    add_bus_arguments(p, "reader")
    p.set_defaults(func=main_args)


def main_args(args: argparse.Namespace) -> int:
    try:
        check_key_expr(args.keys)
    except ValueError as e:
        print(f"sme record: error: argument --keys: {e}", file=sys.stderr)
        return 2
    try:
        out = open_output(args.file)  # before connecting: a bad path fails at once
    except OSError as e:
        print(f"sme record: {e.strerror or e}", file=sys.stderr)
        return 2
    try:
        bus = Bus(bus_config_from_args(args, "reader"), wait_limit=args.seconds)
    except BusError as e:
        out.close()
        print(f"sme record: {e}", file=sys.stderr)
        return 2
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    t0 = time.monotonic()
    with bus:
        rec = Recorder(bus, args.file, args.keys, args.compression, args.chunk_kb * 1024, stream=out).start()
        tap = None
        if args.ros2:
            from sensorimotor.worlds.ros2.tap import RosTap

            try:
                tap = RosTap(args.ros2, rec.add_ros2, args.ros2_domain)
            except BusError as e:
                rec.stop()
                print(f"sme record: the ROS 2 router at {args.ros2}: {e}", file=sys.stderr)
                return 2
        print(f"sme record: recording {args.keys} to {args.file}; Ctrl-C stops", file=sys.stderr, flush=True)
        next_tick = 5.0
        while not stop.is_set() and not rec.failed.is_set():
            el = time.monotonic() - t0
            if args.seconds is not None and el >= args.seconds:
                break
            if el >= next_tick:
                next_tick += 5.0
                lossy = f", lost {rec.lost} observation steps, dropped {rec.dropped}" if rec.lost or rec.dropped else ""
                print(
                    f"  {el:5.0f} s  {rec.written} messages written ({rec.received / el:,.0f}/s){lossy}",
                    file=sys.stderr,
                    flush=True,
                )
            stop.wait(0.1)
        if tap is not None:
            tap.close()
        rec.stop()
    el = time.monotonic() - t0
    if rec.error is not None:
        print(
            f"sme record: {rec.error}; recording stopped after {el:.1f} s. The file reads back up to its "
            f"last complete chunk (`sme replay`, or `sme recover {args.file} NEW.mcap` for a complete file)",
            file=sys.stderr,
        )
        return 1
    print(
        f"sme record: {rec.written} messages in {el:.1f} s ({rec.written / max(el, 1e-9):,.0f}/s), "
        f"{len(rec.by_key)} channels, received {rec.received}, max backlog {rec.max_backlog}, "
        f"lost {rec.lost} observation steps (never reached the recorder), dropped {rec.dropped} (backlog full)",
        file=sys.stderr,
    )
    return 0
