"""`sme replay FILE.mcap`: put a recorded session back on the bus, or re-learn it offline.

Online: the recorded worlds come back to life: a liveliness token, spec and truth queryables, and
their observations (and truth updates and camera frames) published at the recorded timing scaled
by --speed. A fresh agent attaches and learns from them as if live; since programs are
deterministic given their seed and observations, it takes the same decisions as the recorded agent
did, i.e. it observes the recorded actions. Before the timed replay starts, the first observation
is repeated until an agent answers it, so nothing is missed; after that each observation waits for
the agent's answer to the one before (at most --answer-timeout), so a slow agent slows the replay
down instead of losing observations: --speed is an upper bound.

Offline: the recording is fed straight through the daemon's WorldLink and programs, no bus; the
embeddings are printed (or written) and compared byte for byte with those the live agent published
while the session was recorded.
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import sys
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

from sensorimotor.agent.attach import AgentConfig, attach
from sensorimotor.agent.detectors import DETECTORS
from sensorimotor.agent.link import WorldLink
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusError, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import (
    Action,
    AgentEvent,
    AttachConfig,
    Embedding,
    EventKind,
    Observation,
    Truth,
    WorldSpec,
)
from sensorimotor.tools.common import describe_trigger, embedding_dict, print_json
from sensorimotor.tools.mcap_io import Record, read

log = logging.getLogger("sme.replay")

_WORLD_KEY = re.compile(rf"^{keys.PREFIX}/world/([^/]+)/(obs|act|ctl|truth|spec|image/[^/]+)$")
_AGENT_KEY = re.compile(rf"^{keys.PREFIX}/agent/([^/]+)/(embedding|event)/([^/]+)$")


def classify(topic: str) -> tuple[str, str, str]:
    """(kind, world id, agent id) of a recorded key; kind is obs/act/ctl/truth/spec/image/embedding/event/other."""
    m = _WORLD_KEY.match(topic)
    if m:
        return m.group(2).split("/")[0], m.group(1), ""
    m = _AGENT_KEY.match(topic)
    if m:
        return m.group(2), m.group(3), m.group(1)
    return "other", "", ""


# --- offline ------------------------------------------------------------------------------------


@dataclass
class OfflineResult:
    embeddings: list[Embedding] = field(default_factory=list)
    events: list[AgentEvent] = field(default_factory=list)
    live_embeddings: list[Embedding] = field(default_factory=list)
    unattached: int = 0
    links: dict[str, WorldLink] = field(default_factory=dict)

    def compare(self) -> tuple[int, int]:
        """(embeddings identical to the live ones, embeddings compared), matched by world and version."""
        live = {(e.world_id, e.version): e for e in self.live_embeddings}
        same = n = 0
        for e in self.embeddings:
            le = live.get((e.world_id, e.version))
            if le is None:
                continue
            n += 1
            same += int(le.ids == e.ids and le.coordinates.tobytes() == e.coordinates.tobytes())
        return same, n


def recorded_config(records: Iterable[Record]) -> dict[str, AttachConfig]:
    """The configuration the live agent attached each world with (the `config` field of the first
    recorded `attached` event per world)."""
    out: dict[str, AttachConfig] = {}
    for rec in records:
        kind, wid, _ = classify(rec.topic)
        if kind == "event" and wid not in out:
            try:
                ev = codec.decode(AgentEvent, rec.data)
            except ProtocolError:
                continue
            if ev.kind == EventKind.ATTACHED and ev.config is not None:
                out[wid] = ev.config
    return out


def replay_offline(
    path: str,
    seed: int | None = None,
    detector: str | None = None,
    program_params: dict[str, dict[str, Any]] | None = None,
    agent_id: str = "offline",
) -> OfflineResult:
    """Re-learn a recording without the bus, through the daemon's attach path. Settings not given
    are taken from the recording's `attached` events (what the live agent ran with), else the
    daemon's defaults."""
    cfg = recorded_config(read(path))
    res = OfflineResult()

    def publisher(channel: str, msg: Any) -> None:
        if channel == "embedding":
            res.embeddings.append(msg)
        elif channel == "event":
            res.events.append(msg)

    for rec in read(path):
        kind, wid, _ = classify(rec.topic)
        link = res.links.get(wid)
        if kind == "spec":
            try:
                spec = codec.decode(WorldSpec, rec.data)
            except ProtocolError as e:
                log.warning("bad recorded spec for %s: %s", wid, e)
                continue
            config = AgentConfig.from_attach(agent_id, cfg.get(wid, AttachConfig()))
            config = replace(
                config,
                seed=config.seed if seed is None else seed,
                detector=detector or config.detector,
                program_params=config.program_params if program_params is None else program_params,
            )
            res.links[wid] = attach(spec, config, publisher, truth=link.truth if link else None, previous=link).link
        elif kind == "truth" and link is not None:
            try:
                link.truth = codec.decode(Truth, rec.data)
            except ProtocolError:
                pass
        elif kind == "obs":
            if link is None:
                res.unattached += 1
            else:
                link.handle(rec.data)
        elif kind == "embedding":
            try:
                res.live_embeddings.append(codec.decode(Embedding, rec.data))
            except ProtocolError:
                pass
    return res


# --- online -------------------------------------------------------------------------------------


def _remap(rec: Record, kind: str, wid: str, remap: dict[str, str], session: str) -> Record:
    new = remap.get(wid, wid)
    if new == wid and not session:
        return rec
    topic = rec.topic.replace(f"/world/{wid}/", f"/world/{new}/", 1)
    data = rec.data
    try:
        if kind == "obs":
            o = codec.decode(Observation, data)
            data = codec.encode(replace(o, world_id=new, session=o.session + session))
        elif kind == "spec":
            data = codec.encode(replace(codec.decode(WorldSpec, data), world_id=new))
        elif kind == "truth":
            data = codec.encode(replace(codec.decode(Truth, data), world_id=new))
    except ProtocolError:
        pass  # replay bad bytes as they were recorded
    return replace(rec, topic=topic, data=data)


class Replayer:
    WORLD_KINDS = ("obs", "truth", "image")

    def __init__(
        self,
        bus: Bus,
        path: str,
        speed: float = 1.0,
        start: float = 0.0,
        end: float | None = None,
        remap: dict[str, str] | None = None,
        what: str = "world",
        handshake: float = 10.0,
        answer_timeout: float = 5.0,
    ) -> None:
        if speed <= 0:
            raise ValueError("--speed must be > 0")
        if what not in ("world", "all"):
            raise ValueError("--what must be 'world' or 'all'")
        self.bus, self.path, self.speed = bus, path, speed
        self.start, self.end = start, end
        self.remap = remap or {}
        self.what = what
        self.handshake = handshake
        self.answer_timeout = answer_timeout
        self.published = 0
        self.unanswered = 0
        self.stop_event = threading.Event()
        self._specs: dict[str, bytes] = {}
        self._truths: dict[str, bytes] = {}
        self._answered: dict[str, threading.Event] = {}
        self._last_answer: dict[str, int] = {}
        self._pending: dict[str, int] = {}
        self._cond = threading.Condition()

    def _on_action(self, wid: str, msg: Any) -> None:
        try:
            step = codec.decode(Action, msg.payload).step
        except ProtocolError:
            return
        with self._cond:
            self._last_answer[wid] = max(step, self._last_answer.get(wid, -1))
            self._cond.notify_all()
        self._answered[wid].set()

    def _wait_answer(self, wid: str) -> None:
        """Block until the agent answered the last observation published for `wid` (bounded)."""
        want = self._pending.pop(wid, None)
        if want is None:
            return
        with self._cond:
            ok = self._cond.wait_for(
                lambda: self._last_answer.get(wid, -1) >= want or self.stop_event.is_set(), self.answer_timeout
            )
        if not ok:
            self.unanswered += 1
            if self.unanswered == 1:
                log.warning(
                    "world %s: no answer to step %d within %.1f s; going on without it", wid, want, self.answer_timeout
                )

    def _declare_world(self, wid: str) -> None:
        self._answered[wid] = threading.Event()

        def spec(k: str, p: bytes | None, w: str = wid) -> bytes:
            return self._specs[w]

        def on_action(m: Any, w: str = wid) -> None:
            self._on_action(w, m)

        self.bus.queryable(keys.world_spec(wid), spec, codec.schema_name(WorldSpec))

        def truth(k: str, p: bytes | None, w: str = wid) -> bytes:
            if w not in self._truths:
                raise LookupError(f"no truth recorded for {w}")
            return self._truths[w]

        self.bus.queryable(keys.world_truth(wid), truth, codec.schema_name(Truth))
        self.bus.subscribe(keys.world_act(wid), on_action)
        self.bus.token(keys.alive_world(wid))

    def run(self, loop_index: int = 0) -> int:
        records = list(read(self.path))
        if not records:
            return 0
        session = f"-replay{loop_index}" if loop_index else ""
        with self._cond:  # each pass is a new world session whose steps count from 0 again
            self._last_answer.clear()
            self._pending.clear()
        t_first = records[0].log_time
        t_lo = t_first + int(self.start * 1e9)
        t_hi = None if self.end is None else t_first + int(self.end * 1e9)
        for rec in records:  # specs and first truths before anything else: the agent attaches at once
            kind, wid, _ = classify(rec.topic)
            new = self.remap.get(wid, wid)
            if kind == "spec" and new not in self._specs:
                self._specs[new] = _remap(rec, kind, wid, self.remap, session).data
            elif kind == "truth" and new not in self._truths:
                self._truths[new] = _remap(rec, kind, wid, self.remap, session).data
        if self.what == "world":
            for wid in self._specs:
                if wid not in self._answered:
                    self._declare_world(wid)
        pubs: dict[str, Any] = {}
        t0_wall: float | None = None
        t0_rec = 0
        for rec in records:
            if self.stop_event.is_set():
                break
            if rec.log_time < t_lo or (t_hi is not None and rec.log_time > t_hi):
                continue
            kind, wid, _ = classify(rec.topic)
            if kind == "spec" or (self.what == "world" and kind not in self.WORLD_KINDS):
                continue
            rec = _remap(rec, kind, wid, self.remap, session)
            new = self.remap.get(wid, wid)
            if kind == "truth":
                self._truths[new] = rec.data
            if t0_wall is not None:
                delay = (rec.log_time - t0_rec) / 1e9 / self.speed - (time.monotonic() - t0_wall)
                if delay > 0:
                    self.stop_event.wait(delay)
            paced = kind == "obs" and new in self._answered and t0_wall is not None
            if paced:
                self._wait_answer(new)
            pub = pubs.get(rec.topic)
            if pub is None:
                pub = pubs[rec.topic] = self.bus.publisher(rec.topic, rec.schema or None)
            pub.put(rec.data)
            self.published += 1
            if paced:
                try:
                    self._pending[new] = codec.decode(Observation, rec.data).step
                except ProtocolError:
                    pass  # bad recorded bytes: nobody will answer them
            if t0_wall is None and kind == "obs" and self.what == "world" and new in self._answered:
                # hold the first observation until an agent answers it
                deadline = time.monotonic() + self.handshake
                while (
                    not self._answered[new].wait(0.5) and time.monotonic() < deadline and not self.stop_event.is_set()
                ):
                    pub.put(rec.data)
                t0_wall, t0_rec = time.monotonic(), rec.log_time
            elif t0_wall is None:
                t0_wall, t0_rec = time.monotonic(), rec.log_time
        for wid in list(self._pending):
            self._wait_answer(wid)
        return self.published


# --- CLI ----------------------------------------------------------------------------------------


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay",
        help="replay a recording onto the bus, or re-learn it offline",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", help="a recording made by `sme record` (a truncated one is read up to its last chunk)")
    p.add_argument("--speed", type=float, default=1.0, help="time scale: 10 replays ten times faster (default 1)")
    p.add_argument("--loop", action="store_true", help="replay again and again (each loop is a new world session)")
    p.add_argument("--start", type=float, default=0.0, metavar="S", help="skip the first S seconds of the recording")
    p.add_argument("--end", type=float, default=None, metavar="S", help="stop S seconds into the recording")
    p.add_argument("--remap", action="append", metavar="OLD=NEW", help="replay world OLD as world NEW, repeatable")
    p.add_argument(
        "--what",
        choices=["world", "all"],
        default="world",
        help="world: the worlds' side only, for a fresh agent to learn from (default; waits for `sme agent`); "
        "all: every recorded message (embeddings and events too), for `sme watch`/`sme view`, no agent needed "
        "(with none running the replay is the router on the default endpoint)",
    )
    p.add_argument(
        "--answer-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="--what world: wait at most S seconds for the agent's answer to an observation before "
        "publishing the next one (default 5); the replay never outruns the agent",
    )
    p.add_argument(
        "--offline",
        action="store_true",
        help="no bus: feed the recording through the agent's programs and print the embeddings",
    )
    p.add_argument("--json", action="store_true", help="--offline: one JSON object per embedding")
    p.add_argument(
        "--out", default=None, metavar="FILE", help="--offline: write embeddings (JSON lines, with coordinates) to FILE"
    )
    p.add_argument(
        "--plot",
        default=None,
        metavar="DIR",
        help="--offline: write each world's latest embedding as DIR/<world>.png (truth, the map coloured by "
        "true position, the eigenvalue spectrum)",
    )
    p.add_argument("--seed", type=int, default=None, help="--offline: program seed (default: as recorded)")
    p.add_argument(
        "--detector", choices=sorted(DETECTORS), default=None, help="--offline: detector (default: as recorded)"
    )
    add_bus_arguments(p, "world")
    p.set_defaults(func=main_args)


def _open_bus(args: argparse.Namespace) -> Bus:
    """The replay's session. `--what world` waits for an agent to learn from it (it is a client of
    the agent's router). `--what all` needs no agent: unless --mode or --listen says otherwise, it
    joins a router that answers on the --connect endpoint (default tcp/127.0.0.1:7447) and, when none
    does, is the router there itself, so `sme watch` and `sme view` (clients of it) see the replay."""
    cfg = bus_config_from_args(args, "world")
    if args.what != "all" or args.mode or args.listen:
        return Bus(cfg)
    try:
        return Bus(replace(cfg, retry=False))  # a router is up (an agent, or another replay): join it
    except BusError:
        pass
    log.warning(
        "no agent at %s: this replay is the router there (`sme watch` and `sme view` connect to it)",
        ", ".join(cfg.connect),
    )
    return Bus(replace(cfg, mode="router", connect=(), listen=cfg.connect, retry=False))


def main_args(args: argparse.Namespace) -> int:
    import os

    if not os.path.exists(args.file):
        print(f"sme replay: no such file {args.file}", file=sys.stderr)
        return 2
    if args.plot and not args.offline:
        print("sme replay: --plot goes with --offline (a live replay is drawn by `sme view`)", file=sys.stderr)
        return 2
    if args.offline:
        res = replay_offline(args.file, args.seed, args.detector)
        out = open(args.out, "w") if args.out else None
        for e in res.embeddings:
            if args.json:
                print_json(embedding_dict(e))
            else:
                err = "n/a" if e.procrustes_error is None else f"{e.procrustes_error:.4f}"
                print(f"[{e.world_id}] embedding v{e.version} ({describe_trigger(e)}) n={len(e.ids)} procrustes={err}")
            if out:
                out.write(json.dumps(embedding_dict(e, coordinates=True)) + "\n")
        if out:
            out.close()
        if args.plot:
            from sensorimotor.tools.plot import plot_embedding

            latest = {e.world_id: e for e in res.embeddings if e.trigger != "policy_map"}
            for wid, e in sorted(latest.items()):
                link = res.links.get(wid)
                versions = [x for x in res.embeddings if x.world_id == wid and x.trigger != "policy_map"]
                drawn = plot_embedding(e, link.truth if link is not None else None, args.plot, history=versions)
                how = "coloured by true position" if drawn.coloured_by_truth else "no truth to colour by"
                print(
                    f"sme replay --offline: wrote {drawn.path}: embedding v{e.version}, {drawn.n_points} points, {how}",
                    file=sys.stderr,
                )
        same, n = res.compare()
        print(
            f"sme replay --offline: {len(res.embeddings)} embeddings; {same} of {n} identical (same bytes) to "
            f"those published live during the recording",
            file=sys.stderr,
        )
        return 0 if same == n else 1
    remap = {}
    for item in args.remap or []:
        old, eq, new = item.partition("=")
        if not eq:
            print(f"sme replay: --remap expects OLD=NEW, got {item!r}", file=sys.stderr)
            return 2
        remap[keys.check_id(old, "world id")] = keys.check_id(new, "world id")
    import signal

    try:
        bus = _open_bus(args)
    except BusError as e:
        print(f"sme replay: {e}", file=sys.stderr)
        return 2
    with bus:
        rp = Replayer(
            bus, args.file, args.speed, args.start, args.end, remap, args.what, answer_timeout=args.answer_timeout
        )
        signal.signal(signal.SIGINT, lambda *a: rp.stop_event.set())
        signal.signal(signal.SIGTERM, lambda *a: rp.stop_event.set())
        t0 = time.monotonic()
        i = 0
        while True:
            rp.run(i)
            i += 1
            if not args.loop or rp.stop_event.is_set():
                break
        time.sleep(0.5)  # let the last puts leave
    late = f"; {rp.unanswered} observations not answered in time" if rp.unanswered else ""
    print(
        f"sme replay: {rp.published} messages in {time.monotonic() - t0:.1f} s ({i} pass{'es' if i > 1 else ''}){late}",
        file=sys.stderr,
    )
    return 0


def recover_main(args: argparse.Namespace) -> int:
    from sensorimotor.tools.mcap_io import recover

    n = recover(args.src, args.dst)
    print(f"sme recover: {n} messages written to {args.dst}")
    return 0


def add_recover_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "recover",
        help="rewrite a truncated recording into a complete MCAP file",
        description="Read a recording up to its last complete chunk (e.g. after the recorder was "
        "killed) and write a complete MCAP file (summary and index) that every tool opens.",
    )
    p.add_argument("src", help="the damaged or truncated .mcap")
    p.add_argument("dst", help="the new .mcap")
    p.set_defaults(func=recover_main)
