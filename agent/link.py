"""One world link: decodes and checks the world's observations, runs its program, answers with
actions, scores and publishes embeddings and events. `handle()` is called for each observation,
either straight from the bus callback or (threaded mode, `start()`) from the link's own thread fed
by a bounded inbox."""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from sensorimotor.agent.detectors import DropDetector
from sensorimotor.agent.evaluation import embedding_scores, evaluate_embedding
from sensorimotor.agent.programs.base import Decision, EmbeddingOutput, EventOutput, Program
from sensorimotor.protocol import codec
from sensorimotor.protocol.bus import Inbox
from sensorimotor.protocol.errors import ProtocolError, SpecMismatch
from sensorimotor.protocol.messages import (
    Action,
    AgentEvent,
    AttachConfig,
    Embedding,
    EventKind,
    LinkStatus,
    Observation,
    Truth,
    WorldEvent,
    WorldSpec,
    clip,
)

log = logging.getLogger("sme.agent")

Publish = Callable[[str, Any], None]  # (channel "act"|"embedding"|"event", message)


def check_against_spec(obs: Observation, spec: WorldSpec) -> None:
    """Raise SpecMismatch if the observation lacks a sensor the spec declares, or has it with
    another dtype or shape."""
    for s in spec.sensors:
        a = obs.tensors.get(s.name)
        if a is None:
            raise SpecMismatch(f"observation step {obs.step} has no tensor {s.name!r} (spec declares it)")
        if codec.dtype_name(a.dtype) != s.dtype or a.shape != tuple(s.shape):
            raise SpecMismatch(
                f"observation step {obs.step}: tensor {s.name!r} is {a.dtype.name}{list(a.shape)}, "
                f"spec says {s.dtype}{list(s.shape)}"
            )


def check_truth(truth: Truth, world_id: str) -> None:
    """Raise SpecMismatch unless `truth` is this world's (its world id) and holds `positions` as a
    2-D float array (row i = start state or point i), the only tensor the evaluation reads. A truth
    that fails would otherwise replace the good one and break every later score."""
    if truth.world_id != world_id:
        raise SpecMismatch(f"truth for world {truth.world_id!r} arrived on {world_id!r}'s key")
    pos = truth.tensors.get("positions")
    if pos is None or pos.ndim != 2 or pos.dtype.kind != "f":
        what = "no 'positions'" if pos is None else f"'positions' {pos.dtype.name}{list(pos.shape)}"
        raise SpecMismatch(f"truth of world {world_id!r} has {what}; expected a 2-D float array")


@dataclass
class LinkCounters:
    """What a link has seen and done: counts of steps, episodes, rejected inputs, embeddings, drops."""

    steps: int = 0
    episodes: int = 0
    duplicates: int = 0
    stale: int = 0
    dropped: int = 0  # steps never answered: gaps in the world's step counter (a flood lost on the way)
    rejected: dict[str, int] = field(default_factory=dict)
    program_errors: int = 0
    world_events: dict[str, int] = field(default_factory=dict)
    embeddings: int = 0
    drops: int = 0
    reward_mean: float = 0.0
    last_error: float = float("nan")


class WorldLink:
    """The agent's side of one world: checks its observations, runs its program, answers with
    actions, watches the program's performance with a drop detector, and scores and publishes
    the embeddings and events the program produces.

    Parameters
    ----------
    agent_id : str
        Id of the agent, carried by every message the link publishes.
    spec : WorldSpec
        The world's spec: observations are checked against its sensors.
    program : Program
        The developmental program that answers the observations.
    publish : callable
        `publish(channel, message)`, channel one of "act", "embedding", "event".
    detector : DropDetector, optional
        Watches `program.performance`; on a detection the program's `on_drop` is called.
    inbox_size : int, default 256
        Capacity of the bounded inbox of threaded mode (`start`).

    Examples
    --------
    In-process, without a bus::

        link = WorldLink("agent", spec, make_program(spec), publish, make_detector())
        action = link.handle(observation_payload)  # or link.answer(observation)
    """

    REWARD_EMA = 0.01
    EVENT_RATE = 5.0  # bad-input and error events per second at most; counters count everything
    MAX_PROGRAM_FAILURES = 20  # consecutive program failures before the link is paused

    @property
    def learned_steps(self) -> int:
        """Steps this state has learned from: this link's and, when it was restored from a
        checkpoint, those before it."""
        return self.steps_before + self.counters.steps

    def __init__(
        self,
        agent_id: str,
        spec: WorldSpec,
        program: Program,
        publish: Publish,
        detector: DropDetector | None = None,
        inbox_size: int = 256,
    ) -> None:
        self.agent_id = agent_id
        self.detector = detector
        self.spec = spec
        self.world_id = spec.world_id
        self.program = program
        self.publish = publish
        self.inbox = Inbox(inbox_size)
        self.truth: Truth | None = None
        self.counters = LinkCounters()
        self.steps_before = 0  # steps learned by earlier links of this state (restored from a checkpoint)
        self.version = 0
        self.state = "attached"
        self.session = spec.session
        self.owner = ""  # the owner id and lease epoch every action carries (see agent.lease)
        self.epoch = 0
        self.lock = threading.RLock()  # held while the program runs: checkpoints take it too
        self._last_step = -1
        self._last_action: Action | None = None
        self._event_budget = self.EVENT_RATE
        self._event_clock = time.monotonic()
        self._failures = 0  # consecutive program failures
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._outputs: ThreadPoolExecutor | None = None  # see outputs_in_background
        self._pending: deque[Future[None]] = deque()
        self._out_lock = threading.Lock()  # acts and the daemon's thread both queue outputs

    # lifecycle ---------------------------------------------------------------------------------
    def start(self) -> None:
        """Threaded mode: run `handle` on the link's own thread, fed by its inbox."""
        if self._thread is None or not self._thread.is_alive():
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name=f"link-{self.world_id}", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """Stop the link's thread (if any), publish what its output thread still holds, and close
        its inbox."""
        self._stop.set()
        self.inbox.close()
        if self._thread is not None:
            self._thread.join(timeout=5)
        outputs, self._outputs = self._outputs, None
        if outputs is not None:
            outputs.shutdown(wait=True)
            self._pending.clear()

    MAX_PENDING_OUTPUTS = 8  # embeddings and events queued for the output thread before an act waits

    def outputs_in_background(self) -> None:
        """Publish this link's embeddings and events from one thread of its own, in the order they
        were made. An embedding's field scores (trustworthiness and the rest: O(n^2), about 100 ms at
        1000 points) are then computed off the act path, which a live agent shares with every other
        world it answers; in-process uses (tests, `sme replay --offline`, `sme reproduce`) keep
        publishing synchronously. Actions are always published at once."""
        if self._outputs is None:
            self._outputs = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"out-{self.world_id}")

    def _output(self, job: Callable[[], None]) -> None:
        """Run `job` (which publishes) now, or queue it for the output thread, in order."""
        outputs = self._outputs
        if outputs is None:
            job()
            return

        def run() -> None:
            try:
                job()
            except Exception:  # noqa: BLE001 - a failed publish must not end the output thread
                log.exception("world %s: publishing an output failed", self.world_id)

        with self._out_lock:
            pending = self._pending
            while pending and pending[0].done():
                pending.popleft()
            if len(pending) >= self.MAX_PENDING_OUTPUTS:  # the thread is behind: wait for its oldest job
                pending.popleft().result()
            try:
                pending.append(outputs.submit(run))
                return
            except RuntimeError:  # shut down meanwhile (the link is being stopped)
                pass
        job()

    def set_lease(self, owner: str, epoch: int) -> None:
        """Answer as `owner` under lease `epoch` from now on (0: unfenced); a resent observation
        gets the same answer under the new epoch."""
        with self.lock:
            if (owner, epoch) != (self.owner, self.epoch):
                self.owner, self.epoch = owner, epoch
                if self._last_action is not None:
                    self._last_action = replace(self._last_action, owner=owner, epoch=epoch)

    def pause(self) -> None:
        """Answer nothing until `resume` (the world vanished)."""
        self.state = "paused"

    def resume(self, spec: WorldSpec) -> None:
        """Answer again after a pause; a new session of the world restarts the program's episode."""
        with self.lock:
            self._failures = 0
            if spec.session != self.session:
                self.session = spec.session
                self._last_step = -1
                self._last_action = None
                self.program.world_restarted()
            self.spec = spec
            self.state = "attached"

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.inbox.get(0.2)
            if msg is not None:
                self.handle(msg.payload)

    # one observation ---------------------------------------------------------------------------
    def _may_event(self) -> bool:
        """A token bucket: at most EVENT_RATE bad-input/error events (and log lines) per second."""
        now = time.monotonic()
        self._event_budget = min(self.EVENT_RATE, self._event_budget + (now - self._event_clock) * self.EVENT_RATE)
        self._event_clock = now
        if self._event_budget >= 1.0:
            self._event_budget -= 1.0
            return True
        return False

    def reject(self, kind: str, detail: str, step: int = 0) -> None:
        """Count one rejected input of `kind` and report it (rate-limited)."""
        c = self.counters.rejected
        c[kind] = c.get(kind, 0) + 1
        if self._may_event():
            log.warning("world %s: rejected input (%s): %s", self.world_id, kind, clip(detail))
            self.event(EventKind.BAD_INPUT, detail, step, {"count": float(c[kind])}, reason=kind)

    def event(
        self,
        kind: str,
        detail: str,
        step: int = 0,
        values: dict[str, float] | None = None,
        *,
        reason: str = "",
        config: AttachConfig | None = None,
    ) -> None:
        """Publish an AgentEvent about this world."""
        ev = AgentEvent(
            self.agent_id, self.world_id, kind, detail, step, time.time(), dict(values or {}), reason, config
        )
        self._output(lambda: self.publish("event", ev))

    def world_event(self, ev: WorldEvent) -> None:
        """A WorldEvent from this world: counted, and passed on as an agent event (rate-limited)."""
        c = self.counters.world_events
        c[ev.kind] = c.get(ev.kind, 0) + 1
        if self._may_event():
            log.info("world %s reports %s (%s): %s", self.world_id, ev.kind, ev.reason, ev.detail)
            self.event(EventKind.WORLD_EVENT, ev.detail, ev.step, {"count": float(c[ev.kind])}, reason=ev.kind)

    def handle(self, payload: bytes) -> Action | None:
        """Decode, check and answer one observation payload; returns the action sent (if any).
        A paused link answers nothing until `resume`."""
        try:
            obs = codec.decode(Observation, payload)
            if obs.world_id != self.world_id:
                raise SpecMismatch(f"observation for world {obs.world_id!r} arrived on {self.world_id!r}'s key")
            check_against_spec(obs, self.spec)
        except ProtocolError as e:
            self.reject(e.kind, str(e))
            return None
        with self.lock:
            return self.answer(obs)

    def answer(self, obs: Observation) -> Action | None:
        """Run the program on one checked observation and publish its answer and outputs. A paused
        link answers nothing until `resume`."""
        if self.state != "attached":
            return None
        if obs.session != self.session:
            self.session = obs.session
            self._last_step = -1
            self._last_action = None
            self.program.world_restarted()
        if obs.step == self._last_step and self._last_action is not None:
            self.counters.duplicates += 1  # a resend: answer again, learn nothing twice
            self.publish("act", self._last_action)
            return self._last_action
        if obs.step < self._last_step:
            self.counters.stale += 1
            return None
        if self._last_step >= 0 and obs.step > self._last_step + 1:
            # A lockstep world publishes k+1 only after our answer to k: the steps in between never
            # reached us (a world that does not wait, its publisher dropping under congestion) or were
            # dropped from the bounded inbox. Memory stays bounded either way; count what was lost.
            self.counters.dropped += obs.step - self._last_step - 1
        try:
            dec = self.program.act(obs)
            self._failures = 0
        except ProtocolError as e:
            self.reject(e.kind, str(e), obs.step)
            return None
        except Exception as e:  # a program bug must not kill the link or lose what it learned
            fallback = self._program_failed(e, obs.step)
            if fallback is None:
                return None
            dec = fallback
        act = Action(
            self.world_id,
            obs.step,
            tuple(float(v) for v in dec.values),
            dec.reset,
            dec.start,
            time.time(),
            self.owner,
            self.epoch,
        )
        self._last_step, self._last_action = obs.step, act
        self.publish("act", act)
        c = self.counters
        c.steps += 1
        if obs.t == 0:
            c.episodes += 1
        c.reward_mean += self.REWARD_EMA * (obs.reward - c.reward_mean)
        detector = self.detector
        if detector is not None and self.program.take_rebase():
            detector.reset()
        perf = self.program.performance(obs) if detector is not None else None
        if detector is not None and perf is not None:
            ref = detector.reference
            if detector.update(perf):
                c.drops += 1
                self.event(
                    EventKind.DROP_DETECTED,
                    f"{detector.name} saw the reward drop (now {perf:.4g}, {detector.reference_label} {ref:.4g})",
                    obs.step,
                    {"reward": perf, "reference": ref},
                    reason=detector.name,
                )
                self.program.on_drop(obs.step)
        for item in self.program.drain():
            self._emit(item)
        return act

    def _program_failed(self, e: Exception, step: int) -> Decision | None:
        """Count a program failure, report it (rate-limited) and answer with a reset; after
        MAX_PROGRAM_FAILURES in a row, pause the link instead of failing forever (it resumes when the
        world returns)."""
        self.counters.program_errors += 1
        self._failures += 1
        if self._may_event():
            log.error("program %s failed on world %s step %d", self.program.name, self.world_id, step, exc_info=e)
            self.event(
                EventKind.PROGRAM_ERROR,
                f"{type(e).__name__}: {e}",
                step,
                {"count": float(self.counters.program_errors)},
                reason=type(e).__name__,
            )
        if self._failures >= self.MAX_PROGRAM_FAILURES:
            self.state = "paused"
            log.error(
                "world %s: program %s failed %d times in a row; link paused",
                self.world_id,
                self.program.name,
                self._failures,
            )
            self.event(
                EventKind.PAUSED,
                f"program {self.program.name} failed {self._failures} times in a row; "
                "the link waits for the world to return",
                step,
                reason="program_errors",
            )
            return None
        return Decision(reset=True, start=-1)

    def _emit(self, item: Any) -> None:
        if isinstance(item, EmbeddingOutput):
            scores = evaluate_embedding(item, self.truth)
            err = scores.pop("procrustes_error", None)
            truth = self.truth
            self.version += 1
            version = self.version
            self.counters.embeddings += 1
            if err is not None:
                self.counters.last_error = err

            def publish_embedding() -> None:
                field = embedding_scores(item, truth) if err is not None else None
                emb = Embedding(
                    self.agent_id,
                    self.world_id,
                    version,
                    item.trigger,
                    item.ids,
                    np.asarray(item.coordinates, dtype=np.float64),
                    item.eigenvalues,
                    err,
                    item.step,
                    time.time(),
                    {**item.metrics, **scores},
                    item.iteration,
                    item.drop_step,
                    item.labels,
                    field,
                )
                log.info(
                    "world %s: embedding v%d (%s) n=%d error=%s",
                    self.world_id,
                    version,
                    item.trigger,
                    len(item.ids),
                    "n/a" if err is None else f"{err:.4f}",
                )
                self.publish("embedding", emb)

            self._output(publish_embedding)
        elif isinstance(item, EventOutput):
            self.event(item.kind, item.detail, item.step, item.values, reason=item.reason)

    @property
    def dropped(self) -> int:
        """Observation steps of this world never answered (see LinkCounters.dropped)."""
        return self.counters.dropped

    def status(self) -> LinkStatus:
        """The link's `LinkStatus` for the agent's status queryable."""
        c = self.counters
        stat = float(self.detector.statistic) if self.detector is not None else 0.0
        return LinkStatus(
            self.world_id,
            self.spec.kind,
            self.program.name,
            self.state,
            c.steps,
            c.episodes,
            self.version,
            c.reward_mean,
            dict(c.rejected),
            c.last_error,
            stat,
            c.drops,
            c.dropped,
        )
