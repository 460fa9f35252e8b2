"""Serve any World over the bus, in lockstep.

The node publishes observation k and waits for the Action that answers k; after `resend` seconds
without one it publishes observation k again, and keeps waiting (forever, or until stopped). It
declares a liveliness token (discovery), a spec queryable, a truth queryable, and a control
subscriber. The world is stepped right where the answer arrives (the action subscriber's thread:
handing it to another thread cost ~50 us of a ~450 us round trip), one step at a time under the
node's lock, with controls applied between steps, so worlds need no locks of their own.
What the world reports about itself (a refused action, an applied or refused control) goes out as
a WorldEvent on sme/v1/world/{id}/event. The stepping itself is `worlds.lockstep.Lockstep`.
"""

from __future__ import annotations

import logging
import secrets
import signal
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from sensorimotor.protocol import codec, images, keys
from sensorimotor.protocol.bus import Bus, BusMessage
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import (
    EXTERNAL_PROGRAM,
    Action,
    Control,
    Lease,
    LeaseRequest,
    Observation,
    Truth,
    WorldEvent,
    WorldEventKind,
    WorldSpec,
    clip,
)
from sensorimotor.protocol.params import quote
from sensorimotor.worlds.base import PerturbationError, World
from sensorimotor.worlds.body_changes.layer import served
from sensorimotor.worlds.lease import LeaseCounts, LeaseKeeper
from sensorimotor.worlds.lockstep import Lockstep

log = logging.getLogger("sme.world")


@dataclass
class NodeStats:
    """What a WorldNode did: counts, and step latencies when asked to measure (`sme bench loop`)."""

    steps: int = 0
    episodes: int = 0
    resends: int = 0
    published: int = 0  # observations put on the bus (resends included)
    actions_received: int = 0  # valid actions received (duplicates and stale ones included)
    actions_ignored: int = 0  # of those, answers to a step already answered or not the one awaited
    # actions not from the current lease are not counted above: see `lease` (actions_fenced)
    max_wait: float = 0.0  # longest time (s) an observation waited for its answer (the first one excepted)
    max_wait_at: float = 0.0  # when (time.time()) that answer came
    lease: LeaseCounts = field(default_factory=LeaseCounts)  # the lease keeper's counts (shared)
    rejected: dict[str, int] = field(default_factory=dict)
    controls: int = 0
    latencies: list[float] = field(default_factory=list)
    seconds: float = 0.0
    measured_seconds: float = 0.0
    measured_steps: int = 0
    measured_cpu_seconds: float = 0.0  # the process's CPU time (all threads) over the measured steps

    def summary(self) -> dict:
        """The counts, rates and latency percentiles (ms) as a JSON-ready dict."""
        lat = np.asarray(self.latencies) * 1e3
        out = {
            "steps": self.steps,
            "episodes": self.episodes,
            "resends": self.resends,
            "published": self.published,
            "actions_received": self.actions_received,
            "actions_ignored": self.actions_ignored,
            "controls": self.controls,
            "max_wait_s": round(self.max_wait, 3),
            "max_wait_at": round(self.max_wait_at, 3),
            "rejected": dict(self.rejected),
            **self.lease.summary(),
            "seconds": round(self.seconds, 3),
            "steps_per_s": round(self.steps / self.seconds, 1) if self.seconds else 0.0,
        }
        if self.measured_seconds:
            out["steady_steps_per_s"] = round(self.measured_steps / self.measured_seconds, 1)
            out["cpu_cores"] = round(self.measured_cpu_seconds / self.measured_seconds, 3)
        if self.measured_steps:
            out["cpu_us_per_step"] = round(1e6 * self.measured_cpu_seconds / self.measured_steps, 1)
        if lat.size:
            out.update(
                p50_ms=round(float(np.percentile(lat, 50)), 4),
                p99_ms=round(float(np.percentile(lat, 99)), 4),
                max_ms=round(float(lat.max()), 4),
            )
        return out


class WorldNode:
    """Runs one World on a Bus until stopped or a bound (`max_steps`, `seconds`) is reached.

    The node answers the spec and truth queries, declares the world's liveliness token, applies
    controls between steps, and steps the world in lockstep with the agent's actions.

    Parameters
    ----------
    world : World
        The simulator to serve; the node serves it through `body_changes.layer.BodyChanges`
        (`self.body`), so it also takes the generic body changes, advertised in its spec.
    bus : Bus
        An open bus session (the node does not close it).
    world_id : str or None, default=None
        The id on the bus (default: ``world.world_id``); checked with `keys.check_id`.
    resend : float, default=0.5
        Seconds without an answer after which the same observation is published again.
    max_steps : int or None, default=None
        Stop after this many answered steps.
    seconds : float or None, default=None
        Stop after this many seconds.
    measure : bool, default=False
        Record step latencies in `stats` (after `warmup` steps).
    warmup : int, default=0
        Steps not measured.
    image_every : int, default=10
        Publish a camera frame every this many steps, for worlds that override `World.frame`
        (0: never).
    external : bool, default=False
        Leave the world to an outside controller (a Gymnasium `BusEnv`): the spec says
        ``program: external`` (the world's own hint moves to ``params["program_hint"]``) and agents
        do not attach.
    lease_ttl : float, default=1.5
        Seconds without an action from the lease holder after which its lease may be granted to
        another owner (see `worlds.lease`); a holder whose owner token vanishes loses it at once.

    Examples
    --------
    >>> from sensorimotor.protocol.bus import Bus, BusConfig
    >>> from sensorimotor.worlds.gridworld import GridWorld
    >>> with Bus(BusConfig.for_role("world")) as bus:  # doctest: +SKIP
    ...     node = WorldNode(GridWorld("grid0"), bus, max_steps=1000)
    ...     stats = node.run()
    """

    def __init__(
        self,
        world: World,
        bus: Bus,
        world_id: str | None = None,
        *,
        resend: float = 0.5,
        max_steps: int | None = None,
        seconds: float | None = None,
        measure: bool = False,
        warmup: int = 0,
        image_every: int = 10,
        external: bool = False,
        lease_ttl: float = 1.5,
    ) -> None:
        self.world = world
        self.body = served(world)  # the layer the node steps, perturbs and asks for its spec
        self.bus = bus
        self.world_id = keys.check_id(world_id or world.world_id, "world id")
        self.resend = resend
        self.max_steps = max_steps
        self.seconds = seconds
        self.measure = measure
        self.warmup = warmup
        self.image_every = image_every
        self.session = secrets.token_hex(6)
        self.stats = NodeStats()
        self.lease = LeaseKeeper(self.world_id, self.session, lease_ttl)
        self._owner_lock = threading.Lock()
        self.stats.lease = self.lease.counts
        self.stop_event = threading.Event()
        self._cv = threading.Condition()  # re-entrant: a signal handler may notify while run() holds it
        self._lock_step: Lockstep | None = None  # set while run() serves
        self._pub: Any = None
        self._data = b""  # the observation awaiting an answer, for resends
        self._sent = 0.0  # when the awaited observation was first published (latencies count from it)
        self._put_at = 0.0  # when it was last put (resends count from it)
        self._t0 = 0.0
        self._t_warm: float | None = None
        self._cpu_warm = 0.0
        self._error: BaseException | None = None
        self._controls: list[Control] = []
        self._ctl_lock = threading.Lock()
        self._spec = replace(self.body.spec(), world_id=self.world_id, session=self.session)
        if external:
            hint = {**self._spec.params, "program_hint": self._spec.program}
            self._spec = replace(self._spec, program=EXTERNAL_PROGRAM, params=hint)
        self._truth_bytes: bytes | None = None
        self._refresh_truth()

    # bus callbacks (zenoh threads) -------------------------------------------------------------
    def _reject(self, kind: str, msg: str) -> None:
        self.stats.rejected[kind] = self.stats.rejected.get(kind, 0) + 1
        log.warning("world %s: rejected input: %s", self.world_id, clip(msg))

    def _on_action(self, msg: BusMessage) -> None:
        try:
            act = codec.decode(Action, msg.payload)
        except ProtocolError as e:
            self._reject(e.kind, str(e))
            return
        with self._cv:
            if not self.lease.admit(act, time.monotonic()):
                lost = self.lease.lost_event(act, time.monotonic())
                if lost is not None:
                    log.info("world %s: %s", self.world_id, lost.detail)
                    self._world_event(lost)
                return
            self.stats.actions_received += 1
            lock = self._lock_step
            if lock is None or act.step != lock.step or self.stop_event.is_set():
                self.stats.actions_ignored += 1
                return
            try:
                self._advance(lock, act)
            except Exception as e:  # noqa: BLE001 - the world failed: run() re-raises it on its thread
                self._error = e
                self.stop_event.set()
            if self.stop_event.is_set():
                self._cv.notify_all()  # only then: waking run() on every step would cost ~30 us

    def _on_control(self, msg: BusMessage) -> None:
        try:
            ctl = codec.decode(Control, msg.payload)
        except ProtocolError as e:
            self._reject(e.kind, str(e))
            return
        if ctl.world_id != self.world_id:  # meant for another world: applying it here would change the wrong body
            why = f"control for world {clip(ctl.world_id, 64)!r} arrived on {self.world_id!r}'s key: not applied"
            self._reject("spec_mismatch", why)
            self._world_event(
                WorldEvent(
                    self.world_id,
                    WorldEventKind.CONTROL_REFUSED,
                    clip(ctl.kind, 64),
                    why,
                    session=self.session,
                    timestamp=time.time(),
                    control_id=ctl.id,
                )
            )
            return
        with self._ctl_lock:
            self._controls.append(ctl)

    def _refresh_truth(self) -> None:
        tr = self.world.truth()
        self._truth_bytes = (
            None if tr is None else codec.encode(replace(tr, world_id=self.world_id, timestamp=time.time()))
        )

    def _answer_lease(self, key: str, payload: bytes | None) -> bytes:
        """The lease queryable: a LeaseRequest in, the Lease as it stands after it out."""
        try:
            req = codec.decode(LeaseRequest, payload or b"")
        except ProtocolError as e:
            self._reject(e.kind, f"lease request: {e}")
            raise
        with self._cv:  # the lease is read by every action under the same lock
            before = (self.lease.holder, self.lease.epoch)
            lease = self.lease.request(req, time.monotonic())
        if (lease.holder, lease.epoch) != before:
            log.info(
                "world %s: lease %s -> %s (epoch %d, %s)",
                self.world_id,
                before[0] or "-",
                lease.holder or "-",
                lease.epoch,
                lease.reason,
            )
        return codec.encode(lease)

    def _on_owner(self, key: str, alive: bool) -> None:
        with self._owner_lock:  # not _cv: run() holds it while it declares this watch
            self.lease.owner_alive(keys.last_chunk(key), alive)

    def _answer_truth(self, key: str, payload: bytes | None) -> bytes:
        if self._truth_bytes is None:
            raise LookupError(f"world {self.world_id} has no ground truth")
        return self._truth_bytes

    # main loop ---------------------------------------------------------------------------------
    def _apply_controls(self, step: int) -> None:
        """Apply the queued controls before the action that answers observation `step - 1`: `step`
        is the first observation of the changed body, the step the events carry."""
        with self._ctl_lock:
            todo, self._controls = self._controls, []
        for ctl in todo:
            try:
                what = self.body.perturb(ctl)
                self.stats.controls += 1
                log.info("world %s: %s", self.world_id, what)
                self._world_event(
                    WorldEvent(
                        self.world_id,
                        WorldEventKind.CONTROL_APPLIED,
                        ctl.kind,
                        what,
                        step,
                        session=self.session,
                        timestamp=time.time(),
                        control_id=ctl.id,
                    )
                )
                self._refresh_truth()
                if self._truth_bytes is not None:
                    self.bus.put(
                        keys.world_truth(self.world_id), self._truth_bytes, codec.schema_name(type(self.world.truth()))
                    )
            except (PerturbationError, ValueError) as e:
                self._reject("bad_control", f"control {quote(ctl.kind)}: {e}")
                self._world_event(
                    WorldEvent(
                        self.world_id,
                        WorldEventKind.CONTROL_REFUSED,
                        ctl.kind,
                        str(e),
                        step,
                        session=self.session,
                        timestamp=time.time(),
                        control_id=ctl.id,
                    )
                )

    def _advance(self, lock: Lockstep, act: Action) -> None:
        """Step the world by the action that answers the awaited step and publish the next
        observation (under `_cv`)."""
        st = self.stats
        if self.measure and st.steps >= self.warmup:
            now = time.perf_counter()
            st.latencies.append(now - self._sent)
            if self._t_warm is None:
                self._t_warm, self._cpu_warm = now, time.process_time()
            st.measured_steps += 1
        if self._controls:  # (most steps have none: no lock taken on the hot path)
            self._apply_controls(lock.step + 1)
        episode = lock.episode
        refused = lock.advance(act)
        if refused is not None:
            self._reject("bad_action", refused.detail)
            self._world_event(refused)
        st.episodes += lock.episode - episode
        st.steps += 1
        self._data = self._publish(lock)
        now = time.perf_counter()
        if st.steps > 1 and now - self._sent > st.max_wait:  # (the first waits for an agent to attach)
            st.max_wait, st.max_wait_at = now - self._sent, time.time()
        self._sent = self._put_at = now
        if (self.max_steps is not None and st.steps >= self.max_steps) or (
            self.seconds is not None and self._sent - self._t0 >= self.seconds
        ):
            self.stop_event.set()

    def _publish(self, lock: Lockstep) -> bytes:
        now = time.time()
        data = codec.encode(lock.observation(now))
        self._pub.put(data)
        self.stats.published += 1
        if self._image_pub is not None and lock.step % self.image_every == 0:
            frame = self.world.frame()
            if frame is not None:
                self._image_pub.put(images.encode_image(frame, self.world_id, now))
        return data

    def _world_event(self, ev: WorldEvent) -> None:
        """Publish what the world reports about itself (best effort: the step loop goes on)."""
        try:
            self.bus.put(keys.world_event(self.world_id), codec.encode(ev), codec.schema_name(WorldEvent))
        except Exception as e:  # noqa: BLE001 - a closing bus must not stop the world's loop
            log.debug("world %s: event not published: %s", self.world_id, e)

    def install_signal_handlers(self) -> None:
        """Stop the node cleanly on SIGINT and SIGTERM (main thread only)."""

        def stop(signum, frame):  # noqa: ARG001
            self.stop()

        signal.signal(signal.SIGINT, stop)
        signal.signal(signal.SIGTERM, stop)

    def stop(self) -> None:
        """Ask `run` to return after the current wait (thread-safe)."""
        self.stop_event.set()
        with self._cv:
            self._cv.notify_all()

    def run(self) -> NodeStats:
        """Serve the world until stopped or a bound is reached.

        Returns
        -------
        NodeStats
            What was done (also in `self.stats`).
        """
        wid = self.world_id
        spec_bytes = codec.encode(self._spec)
        bus = self.bus
        bus.queryable(keys.world_spec(wid), lambda k, p: spec_bytes, codec.schema_name(WorldSpec))
        bus.queryable(keys.world_truth(wid), self._answer_truth, codec.schema_name(Truth))
        bus.queryable(keys.world_lease(wid), self._answer_lease, codec.schema_name(Lease))
        bus.subscribe(keys.world_act(wid), self._on_action)
        bus.subscribe(keys.world_ctl(wid), self._on_control)
        pub = bus.publisher(keys.world_obs(wid), codec.schema_name(Observation))
        self._image_pub = (
            bus.publisher(keys.world_image(wid, "camera"), images.SCHEMA, block=False)
            if self.image_every > 0 and type(self.world).frame is not World.frame
            else None
        )
        bus.token(keys.alive_world(wid))
        log.info("world %s (%s) serving on the bus, session %s", wid, self.world.kind, self.session)

        self._pub = pub
        with self._cv:
            self._t0 = time.perf_counter()
            lock = Lockstep(self.body, wid, self.session)
            self._data = self._publish(lock)
            self._sent = self._put_at = time.perf_counter()
            self._lock_step = lock
            # the owners' tokens (a vanished lease holder loses its lease sooner); after the first
            # observation, which nothing here needs to wait for
            bus.watch_alive(keys.ALL_ALIVE_OWNERS, self._on_owner, history=True)
            while not self.stop_event.is_set():
                self._cv.wait(max(self.resend - (time.perf_counter() - self._put_at), 0.001))
                now = time.perf_counter()
                if self.stop_event.is_set() or (self.seconds is not None and now - self._t0 >= self.seconds):
                    break  # (the bound holds for a world nobody answers too)
                if now - self._put_at >= self.resend:
                    self.stats.resends += 1
                    self.stats.published += 1
                    self._pub.put(self._data)  # the same bytes: receivers can tell a resend by its step
                    self._put_at = time.perf_counter()
            self._lock_step = None
        end = time.perf_counter()
        self.stats.seconds = end - self._t0
        if self._t_warm is not None:
            self.stats.measured_seconds = end - self._t_warm
            self.stats.measured_cpu_seconds = time.process_time() - self._cpu_warm
        if self._error is not None:
            raise self._error
        return self.stats
