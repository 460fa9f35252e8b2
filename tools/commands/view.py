"""`sme view [FILE.mcap]`: what the agent knows, in Rerun - live from the bus, or from a recording.

Per world: each embedding version as 2-D points (coloured by the true coordinates when the world
gives truth), its Procrustes error, the episode reward and its moving average, the drop detector's
statistic (polled from the daemon's status), agent events as a text log, and camera frames. A body
change is marked under ``{world}/changes`` three times: when the world applied it, when the agent
noticed (a drop detected) and when the relearned map came.
"""

from __future__ import annotations

import argparse
import collections
import signal
import sys
import threading
import time
from typing import Any

import numpy as np

from sensorimotor.protocol import codec, images, keys
from sensorimotor.protocol.bus import Bus, BusError, BusMessage, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import AgentEvent, AgentStatus, Embedding, Observation, Truth, WorldEvent
from sensorimotor.tools.commands.replay import classify
from sensorimotor.tools.commands.watch import change_mark

PALETTE = np.array(
    [[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189], [140, 86, 75], [227, 119, 194]],
    dtype=np.uint8,
)


def cluster_colours(labels: tuple[int, ...]) -> np.ndarray:
    """One colour per cluster label (a policy map's `labels`), cycling through a fixed palette."""
    return PALETTE[np.asarray(labels, dtype=np.int64) % len(PALETTE)]


def truth_colours(truth: Truth | None, ids: tuple[int, ...]) -> np.ndarray | None:
    """RGB from the true coordinates (x -> red, y -> green, blue constant) so that a good
    embedding shows the same smooth colour gradient as the world."""
    if truth is None or "positions" not in truth.tensors:
        return None
    pos = np.asarray(truth.tensors["positions"], dtype=np.float64)
    idx = np.asarray(ids, dtype=np.int64)
    if idx.size == 0 or idx.max() >= pos.shape[0]:
        return None
    p = pos[idx][:, :2] if pos.shape[1] >= 2 else np.c_[pos[idx], np.zeros(idx.size)]
    span = np.ptp(p, axis=0)
    span[span == 0] = 1.0
    n = (p - p.min(axis=0)) / span
    return (np.c_[n[:, 0], n[:, 1], np.full(len(n), 0.6)] * 255).astype(np.uint8)


class RerunLogger:
    """Turns bus messages (live or recorded) into Rerun entities. Not thread-safe: one caller."""

    MA = 100

    def __init__(self, rr: Any) -> None:
        self.rr = rr
        self.truth: dict[str, Truth] = {}
        self.rewards: dict[str, collections.deque] = collections.defaultdict(lambda: collections.deque(maxlen=self.MA))
        self.logged = 0

    def _time(self, t: float, step: int | None = None) -> None:
        self.rr.set_time("time", timestamp=t)
        if step is not None:
            self.rr.set_time("step", sequence=int(step))

    def handle(self, topic: str, payload: bytes, t: float) -> None:
        kind, wid, _ = classify(topic)
        rr = self.rr
        try:
            if topic.startswith(f"{keys.PREFIX}/world/") and topic.endswith("/event"):  # a world's own report
                w = codec.decode(WorldEvent, payload)
                wid = w.world_id
                mark = change_mark(w.kind)
                if mark is None:
                    return
                self._time(t, w.step or None)
                rr.log(f"{wid}/changes", rr.TextLog(f"{mark}: {w.reason}: {w.detail}", level="WARN"))
                self.logged += 1
                return
            if kind == "embedding":
                e = codec.decode(Embedding, payload)
                self._time(t, e.step)
                pts = e.coordinates if e.coordinates.shape[1] >= 2 else np.c_[e.coordinates, np.zeros(len(e.ids))]
                # a policy map (clustered traces of a trained policy) is its own picture, coloured by cluster
                rr.log(
                    f"{wid}/policy_map" if e.labels else f"{wid}/embedding",
                    rr.Points2D(
                        pts[:, :2],
                        colors=cluster_colours(e.labels) if e.labels else truth_colours(self.truth.get(wid), e.ids),
                        radii=0.5 if len(e.ids) < 200 else 0.2,
                    ),
                )
                if e.procrustes_error is not None:
                    rr.log(f"{wid}/procrustes_error", rr.Scalars(e.procrustes_error))
                rr.log(f"{wid}/events", rr.TextLog(f"embedding v{e.version} ({e.trigger})", level="INFO"))
            elif kind == "event":
                e = codec.decode(AgentEvent, payload)
                self._time(t, e.step or None)
                level = "WARN" if e.kind in ("drop_detected", "bad_input", "program_error") else "INFO"
                rr.log(f"{wid}/events", rr.TextLog(f"{e.kind}: {e.detail}", level=level))
                mark = change_mark(e.kind, e.reason)
                if mark is not None and e.kind != "world_event":  # the world's own report is marked
                    rr.log(f"{wid}/changes", rr.TextLog(f"{mark}: {e.detail}", level=level))
            elif kind == "obs":
                o = codec.decode(Observation, payload)
                if o.done or o.reward:
                    self._time(t, o.step)
                    buf = self.rewards[wid]
                    buf.append(o.reward)
                    rr.log(f"{wid}/reward/episode", rr.Scalars(o.reward))
                    rr.log(f"{wid}/reward/moving_average", rr.Scalars(float(np.mean(buf))))
                else:
                    return
            elif kind == "truth":
                self.truth[wid] = codec.decode(Truth, payload)
                return
            elif kind == "image":
                self._time(t)
                rr.log(f"{wid}/camera", rr.Image(images.decode_image(payload)))
            else:
                return
        except (ProtocolError, ValueError):
            return
        self.logged += 1

    def status(self, st: AgentStatus, t: float) -> None:
        self._time(t)
        for ln in st.links:
            self.rr.log(f"{ln.world_id}/detector_statistic", self.rr.Scalars(ln.detector_statistic))


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "view",
        help="live view in Rerun (or of a recording)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", nargs="?", default=None, help="a recording (.mcap) to show instead of the live bus")
    p.add_argument(
        "--save", default=None, metavar="FILE.rrd", help="write to an .rrd file (for a machine with no screen)"
    )
    p.add_argument(
        "--serve",
        action="store_true",
        help="serve a gRPC stream for a viewer elsewhere (`rerun URL`); note: rerun binds all interfaces",
    )
    p.add_argument(
        "--connect-viewer",
        default=None,
        metavar="URL",
        help="stream to a running Rerun viewer, e.g. rerun+http://127.0.0.1:9876/proxy",
    )
    p.add_argument("--seconds", type=float, default=None, help="live: stop after this many seconds")
    p.add_argument("--agent", default=keys.DEFAULT_AGENT_ID, help="agent whose status is polled (default a0)")
    add_bus_arguments(p, "reader")
    p.set_defaults(func=main_args)


def main_args(args: argparse.Namespace) -> int:
    import rerun as rr

    rr.init("sensorimotor-embedding", spawn=False)
    if args.save:
        rr.save(args.save)
    elif args.serve:
        print(f"sme view: serving at {rr.serve_grpc()}", file=sys.stderr)
    elif args.connect_viewer:
        rr.connect_grpc(args.connect_viewer)
    else:
        rr.spawn()
    log = RerunLogger(rr)
    if args.file:
        from sensorimotor.tools.mcap_io import read

        for rec in read(args.file):
            log.handle(rec.topic, rec.data, rec.log_time / 1e9)
        rr.disconnect()
        print(f"sme view: {log.logged} entities logged from {args.file}", file=sys.stderr)
        return 0
    try:
        bus = Bus(bus_config_from_args(args, "reader"), wait_limit=args.seconds)
    except BusError as e:
        print(f"sme view: {e}", file=sys.stderr)
        return 2
    inbox: collections.deque[tuple[BusMessage, float]] = collections.deque(maxlen=100_000)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    t0 = time.monotonic()
    with bus:
        for expr in (
            keys.ALL_EMBEDDINGS,
            keys.ALL_EVENTS,
            keys.ALL_OBS,
            f"{keys.PREFIX}/world/*/truth",
            keys.ALL_WORLD_EVENTS,
            f"{keys.PREFIX}/world/*/image/*",
        ):
            bus.subscribe(expr, lambda m: inbox.append((m, time.time())))
        last_poll = 0.0
        while not stop.is_set() and (args.seconds is None or time.monotonic() - t0 < args.seconds):
            while inbox:
                m, t = inbox.popleft()
                log.handle(m.key, m.payload, t)
            if time.monotonic() - last_poll >= 1.0:
                last_poll = time.monotonic()
                try:
                    r = bus.get(keys.agent_status(args.agent), timeout=0.5)
                    if r:
                        log.status(codec.decode(AgentStatus, r[0].payload), time.time())
                except (BusError, ProtocolError):
                    pass
            stop.wait(0.05)
    rr.disconnect()
    print(f"sme view: {log.logged} entities logged", file=sys.stderr)
    return 0
