"""The agent daemon: discovers worlds by liveliness, attaches one link per world, runs each
world's developmental program, answers a status queryable, checkpoints, stops cleanly.

A world that vanishes pauses its link; when it returns (same id) the link resumes with everything
the program learned. With `state_dir`, each link's program is checkpointed atomically and picked up
again by a daemon started later.
"""

from __future__ import annotations

import json
import logging
import os
import pickle
import queue
import threading
import time
from typing import Any, Callable

from sensorimotor.agent.detectors import DEFAULT_DETECTOR, make_detector
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.programs.registry import check_program_params, make_program
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusError, BusMessage
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import (
    Action, AgentEvent, AgentStatus, Embedding, Truth, WorldSpec,
)

log = logging.getLogger("sme.agent")


class AgentDaemon:
    def __init__(self, bus: Bus, agent_id: str = keys.DEFAULT_AGENT_ID, seed: int = 0,
                 state_dir: str | None = None, checkpoint_every: float = 30.0,
                 program_params: dict[str, dict[str, Any]] | None = None,
                 on_output: Callable[[str, Any], None] | None = None, threaded_links: bool = False,
                 detector: str = DEFAULT_DETECTOR) -> None:
        make_detector(detector)  # fail early on an unknown name
        self.detector = detector
        self.bus = bus
        self.threaded_links = threaded_links
        self.agent_id = keys.check_id(agent_id, "agent id")
        self.seed = seed
        self.state_dir = state_dir
        self.checkpoint_every = checkpoint_every
        self.program_params = check_program_params(program_params)  # fail early, typed values only
        self.on_output = on_output
        self.links: dict[str, WorldLink] = {}
        self.counters: dict[str, int] = {"unattached": 0, "attach_failed": 0, "bad_truth": 0}
        self._changes: queue.Queue[tuple[str, bool]] = queue.Queue()
        self._stop = threading.Event()
        self._started = time.time()
        self._pubs: dict[str, Any] = {}
        self._lock = threading.Lock()
        if state_dir:
            os.makedirs(state_dir, exist_ok=True)

    # publishing --------------------------------------------------------------------------------
    def _publisher(self, key: str, schema: str) -> Any:
        pub = self._pubs.get(key)
        if pub is None:
            with self._lock:
                pub = self._pubs.get(key) or self.bus.publisher(key, schema)
                self._pubs[key] = pub
        return pub

    def publish(self, channel: str, msg: Any) -> None:
        wid = msg.world_id
        if channel == "act":
            key = keys.world_act(wid)
        elif channel == "embedding":
            key = keys.agent_embedding(self.agent_id, wid)
        else:
            key = keys.agent_event(self.agent_id, wid)
        try:
            self._publisher(key, codec.schema_name(type(msg))).put(codec.encode(msg))
        except Exception:
            if not self.bus.closed:
                log.exception("publishing on %s failed", key)
        if self.on_output is not None and channel != "act":
            self.on_output(channel, msg)

    def event(self, world_id: str, kind: str, detail: str) -> None:
        self.publish("event", AgentEvent(self.agent_id, world_id, kind, detail, 0, time.time()))

    # bus callbacks (zenoh threads) -----------------------------------------------------------------
    # Observations are answered right in the subscriber callback by default: the lockstep world is
    # waiting for exactly this answer, and a queue hop costs ~70 us of a ~400 us round trip. With
    # threaded_links each link runs on its own thread behind a bounded inbox, so one world's slow
    # embedding cannot delay another world's messages.
    def _on_obs(self, msg: BusMessage) -> None:
        wid = keys.world_of(msg.key)
        link = self.links.get(wid)
        if link is not None and link.state == "attached":
            if self.threaded_links:
                link.inbox.push(msg)
            else:
                link.handle(msg.payload)
            return
        self.counters["unattached"] += 1

    def _on_alive(self, key: str, alive: bool) -> None:
        self._changes.put((keys.last_chunk(key), alive))

    def _on_truth(self, msg: BusMessage) -> None:
        link = self.links.get(keys.world_of(msg.key))
        if link is None:
            return
        try:
            link.truth = codec.decode(Truth, msg.payload)
        except ProtocolError as e:
            self.counters["bad_truth"] += 1
            log.warning("world %s: bad truth message: %s", link.world_id, e)

    def _status(self, key: str, payload: bytes | None) -> bytes:
        return codec.encode(self.status())

    def status(self) -> AgentStatus:
        links = tuple(link.status() for link in list(self.links.values()))
        return AgentStatus(self.agent_id, time.time() - self._started, links, dict(self.counters), time.time())

    # attach / pause ----------------------------------------------------------------------------
    def _fetch(self, key: str, cls: type, tries: int = 3) -> Any:
        last: Exception | None = None
        for _ in range(tries):
            try:
                replies = self.bus.get(key, timeout=1.0)
                if replies:
                    return codec.decode(cls, replies[0].payload)
            except (BusError, ProtocolError) as e:
                last = e
            if self._stop.is_set():
                break
        if last is not None:
            raise last
        return None

    def _checkpoint_path(self, wid: str) -> str | None:
        return os.path.join(self.state_dir, f"{wid}.pkl") if self.state_dir else None

    def _load_checkpoint(self, spec: WorldSpec) -> dict | None:
        path = self._checkpoint_path(spec.world_id)
        if not path or not os.path.exists(path):
            return None
        try:
            with open(path, "rb") as f:
                saved = pickle.load(f)
        except Exception as e:
            log.warning("checkpoint %s unreadable (%s); starting fresh", path, e)
            return None
        old: WorldSpec = saved["spec"]
        if (old.kind, old.program, old.sensors, old.action_space) != (spec.kind, spec.program, spec.sensors,
                                                                       spec.action_space):
            log.warning("checkpoint %s is for a different world body; starting fresh", path)
            return None
        return saved

    def checkpoint(self) -> None:
        if not self.state_dir:
            return
        for wid, link in list(self.links.items()):
            path = self._checkpoint_path(wid)
            with link.lock:
                data = pickle.dumps({"spec": link.spec, "program": link.program, "version": link.version,
                                     "detector": link.detector},
                                    protocol=pickle.HIGHEST_PROTOCOL)
            tmp = f"{path}.tmp"
            with open(tmp, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)

    def _attach(self, wid: str) -> None:
        try:
            keys.check_id(wid, "world id")
            spec = self._fetch(keys.world_spec(wid), WorldSpec)
            if spec is None:
                raise BusError("no reply to the spec query")
        except (ValueError, BusError, ProtocolError) as e:
            self.counters["attach_failed"] += 1
            log.warning("world %s: cannot attach: %s", wid, e)
            self.event(wid, "attach_failed", str(e))
            return
        try:
            truth = self._fetch(keys.world_truth(wid), Truth, tries=1)
        except (BusError, ProtocolError):
            truth = None
        link = self.links.get(wid)
        if link is not None and (link.spec.kind, link.spec.sensors, link.spec.action_space) == (
                spec.kind, spec.sensors, spec.action_space):
            link.truth = truth or link.truth
            link.resume(spec)
            if self.threaded_links:
                link.start()
            log.info("world %s is back: resumed at step %d, embedding v%d", wid, link.counters.steps, link.version)
            self.event(wid, "resumed", f"{spec.kind}: resumed with {link.counters.steps} steps learned")
            return
        if link is not None:
            link.stop()
        saved = self._load_checkpoint(spec)
        try:
            if saved:
                program = saved["program"]
                program.world_restarted()
            else:
                program = make_program(spec, self.seed, **self.program_params.get(spec.program or spec.kind, {}))
        except (ValueError, ProtocolError) as e:
            self.counters["attach_failed"] += 1
            log.warning("world %s: no program: %s", wid, e)
            self.event(wid, "attach_failed", str(e))
            return
        detector = make_detector(self.detector, **program.detector_params)
        link = WorldLink(self.agent_id, spec, program, self.publish, detector)
        link.truth = truth
        if saved:
            link.version = saved["version"]
            link.detector = saved.get("detector") or link.detector
        self.links[wid] = link
        if self.threaded_links:
            link.start()
        how = f"restored from checkpoint at embedding v{link.version}" if saved else "new"
        log.info("world %s attached (%s, program %s, %s)", wid, spec.kind, program.name, how)
        self.event(wid, "attached", f"{spec.kind} with program {program.name} ({how}); config "
                   + json.dumps(self.config(spec)))

    def config(self, spec: WorldSpec) -> dict[str, Any]:
        """What decides a link's behaviour besides its observations: with it, a recording replays
        offline into the same embeddings."""
        name = spec.program or spec.kind
        return {"seed": self.seed, "detector": self.detector, "program": name,
                "program_params": self.program_params.get(name, {})}

    def _detach(self, wid: str) -> None:
        link = self.links.get(wid)
        if link is not None and link.state == "attached":
            link.pause()
            log.info("world %s disappeared: link paused at step %d", wid, link.counters.steps)
            self.event(wid, "paused", "world vanished; waiting for it to return")

    # main loop ---------------------------------------------------------------------------------
    def start(self) -> None:
        self.bus.queryable(keys.agent_status(self.agent_id), self._status, codec.schema_name(AgentStatus))
        self.bus.subscribe(keys.ALL_OBS, self._on_obs)
        self.bus.subscribe(f"{keys.PREFIX}/world/*/truth", self._on_truth)
        self.bus.token(keys.alive_agent(self.agent_id))
        self.bus.watch_alive(keys.ALL_ALIVE_WORLDS, self._on_alive, history=True)

    def run(self, seconds: float | None = None) -> None:
        """Process attach/detach until stop() or `seconds` elapse."""
        t0 = time.monotonic()
        last_ckpt = t0
        while not self._stop.is_set():
            if seconds is not None and time.monotonic() - t0 >= seconds:
                break
            try:
                wid, alive = self._changes.get(timeout=0.1)
            except queue.Empty:
                wid = None
            if wid is not None:
                if alive:
                    self._attach(wid)
                else:
                    self._detach(wid)
            if self.state_dir and time.monotonic() - last_ckpt >= self.checkpoint_every:
                self.checkpoint()
                last_ckpt = time.monotonic()

    def stop(self) -> None:
        self._stop.set()

    def close(self) -> None:
        self._stop.set()
        for link in list(self.links.values()):
            link.stop()
        try:
            self.checkpoint()
        except OSError as e:
            log.warning("final checkpoint failed: %s", e)

    def __enter__(self) -> "AgentDaemon":
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


__all__ = ["AgentDaemon", "Action", "Embedding"]
