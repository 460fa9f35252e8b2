"""`sme bench fuzz`: hostile messages on every key the agent listens to, beside a good world.

An agent daemon (`sme agent`) and a well-behaved gridworld (`sme world gridworld`) run as
subprocesses on a free loopback port (no multicast). This process then publishes N hostile
messages at a steady rate, spread over: the good world's observation, truth and event keys
(malformed bytes, wrong schema versions, bad dtypes, shapes that do not match their bytes,
oversized tensors, NaN/inf, another world's id, spec mismatches); the same keys of worlds that
have no link; and fake worlds whose liveliness token appears with a spec that cannot be attached
(garbage, wrong version or world id, NaN bounds, no sensor the program needs, huge state spaces,
an error reply, an id outside the id alphabet).

Each message is built to be counted by exactly one agent counter (checked against the local
validators before it is sent): observations of the good world by the link's `rejected[kind]`,
its bad truths by `bad_truth`, its bad world events by `bad_world_event`, messages for worlds
without a link by `unattached`, fake worlds by `attach_failed`. The result compares `sent` with
`counted` (the counters' increase, read from the status queryable), counts `crashes` (the agent
died, or a traceback in its log) and reports the good world's last Procrustes error, its step rate
while the hostile messages were sent against the same agent and world without them (a window as
long as the fuzz before it and one after the counters settled; `step_rate_ratio`), and every claim
change of the good world during the fuzz (`handoffs`: broken worlds must never move a healthy one).

It measures under load: a status query the agent does not answer in time is asked again and
counted (`status`), an answer that lacks the good world's link (the agent's view of a worker can lag
a poll) is asked again before it counts, and a link that really leaves is a counted loss with its
cause (`losses`). Whatever happens, the run ends with its figures (`error` says what stopped it).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO, Any

import numpy as np

from sensorimotor.agent.link import check_against_spec, check_truth
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol import sme_v1_pb2 as pb
from sensorimotor.protocol.bus import Bus, BusConfig, BusError
from sensorimotor.protocol.errors import ProtocolError, SpecMismatch
from sensorimotor.protocol.messages import (
    AgentEvent,
    AgentStatus,
    LinkStatus,
    Observation,
    Truth,
    WorldEvent,
    WorldSpec,
    clip,
)
from sensorimotor.tools.bench.procstat import busy_fraction, children, cores_used, cpu_ticks, machine_cpu
from sensorimotor.tools.common import free_port

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
GOOD = "good"
AGENT = "a0"

# category -> (weight, the agent counter expected to count it; "rejected" = the good link's rejections)
CATEGORIES: dict[str, tuple[float, str]] = {
    "obs_bytes": (8, "rejected"),
    "obs_version": (5, "rejected"),
    "obs_dtype": (5, "rejected"),
    "obs_shape": (5, "rejected"),
    "obs_oversize": (5, "rejected"),
    "obs_nonfinite": (6, "rejected"),
    "obs_spec": (6, "rejected"),
    "obs_wrong_world": (4, "rejected"),
    "obs_duplicate": (3, "rejected"),
    "truth_bad": (12, "bad_truth"),
    "event_bad": (12, "bad_world_event"),
    "unattached": (15, "unattached"),
    "attach": (8, "attach_failed"),
}
COUNTERS = ("rejected", "bad_truth", "bad_world_event", "unattached", "attach_failed")
OWNERSHIP = ("shed", "lost", "taken_over")  # the agent's hand-off counters (claim races on fake worlds count in `lost`)
# the sender sleeps only once it is this far ahead of the steady pace (a few messages at a time):
# a sleep per message was a wake-up per message, a fifth of a core spent by the fuzzer itself
PACE_SLACK = 0.005
BIG_EVERY = 1000  # every BIG_EVERY-th observation message is a real tensor over the 32 MiB limit
QUERY_TIMEOUT = 5.0  # seconds one status query waits for the agent's answer
QUERY_TRIES = 3  # a status query left unanswered is asked again, this many times in all
LINK_PATIENCE = 5.0  # seconds an answer without the good world's link is asked again (0.5 s apart) before it is a loss


@dataclass
class StatusReads:
    """How the bench's status queries went (under load an answer can be late, or lack a worker's links)."""

    queries: int = 0  # status queries sent
    timeouts: int = 0  # of those, not answered in QUERY_TIMEOUT s (or with an error): asked again
    unanswered: int = 0  # reads given up after QUERY_TRIES such queries in a row
    link_missing: int = 0  # answers without the good world's link attached: asked again
    slowest_s: float = 0.0  # the longest a status query took

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


class StatusReader:
    """Reads the agent's status for the bench: `query()` sends one status query (its payload, None
    when the agent did not answer in time; BusError for an error reply)."""

    def __init__(
        self,
        query: Callable[[], bytes | None],
        reads: StatusReads,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.query, self.reads, self.clock, self.sleep = query, reads, clock, sleep

    def status(self) -> AgentStatus | None:
        """The agent's status, asked up to QUERY_TRIES times (None: no answer to any of them)."""
        for _ in range(QUERY_TRIES):
            self.reads.queries += 1
            t0 = self.clock()
            try:
                payload = self.query()
                st = codec.decode(AgentStatus, payload) if payload is not None else None
            except (BusError, ProtocolError):
                st = None
            self.reads.slowest_s = round(max(self.reads.slowest_s, self.clock() - t0), 3)
            if st is not None:
                return st
            self.reads.timeouts += 1
        self.reads.unanswered += 1
        return None

    def good(self) -> tuple[AgentStatus | None, LinkStatus | None]:
        """The agent's status and the good world's attached link in it; an answer without that link
        is asked again for LINK_PATIENCE seconds (an agent's status holds its workers' links as of
        its last poll of them). (status, None): the link is not there; (None, None): no answer."""
        end = self.clock() + LINK_PATIENCE
        while True:
            st = self.status()
            ln = _good_link(st)
            if st is None or (ln is not None and ln.state == "attached") or self.clock() >= end:
                return st, ln
            self.reads.link_missing += 1
            self.sleep(0.5)


@dataclass
class Result:
    """What one fuzz run saw."""

    sent: int = 0
    counted: int = 0
    crashes: int = 0
    good_world_procrustes: float = float("nan")
    seconds: float = 0.0
    rate: float = 0.0
    categories: dict[str, int] = field(default_factory=dict)
    expected: dict[str, int] = field(default_factory=dict)
    counters: dict[str, int] = field(default_factory=dict)
    rejected_kinds: dict[str, int] = field(default_factory=dict)
    attach_variants: dict[str, int] = field(default_factory=dict)
    good_world: dict[str, Any] = field(default_factory=dict)
    agent_alive: bool = True
    tracebacks: int = 0
    baseline_steps_per_s: float = 0.0  # the good world's step rate without hostile messages: mean of before and after
    baseline_before: float = 0.0  # its step rate in a window as long as the fuzz, just before it
    baseline_after: float = 0.0  # and in one after the counters settled (the machine's load drifts)
    fuzz_steps_per_s: float = 0.0  # its step rate while the hostile messages were sent
    step_rate_ratio: float = 0.0  # fuzz / baseline (the bar: >= 0.8)
    settle_seconds: float = 0.0  # seconds after the last message until every one was counted (or the wait gave up)
    handoffs: int = 0  # claims of the good world declared or withdrawn during the fuzz (the bar: 0)
    ownership: dict[str, int] = field(default_factory=dict)  # the owners' shed/lost/taken_over increase
    # cores used per process group (agent = its router process, workers = its worker processes, world,
    # bench = this process, which publishes the hostile messages) and the machine's busy fraction, in
    # the window before the fuzz and during it: what the step-rate ratio was paid with
    cpu: dict[str, dict[str, float | None]] = field(default_factory=dict)
    status: StatusReads = field(default_factory=StatusReads)  # how the status queries went (see StatusReader)
    losses: list[dict[str, str]] = field(default_factory=list)  # the good world's link gone: when and why
    error: str | None = None  # what stopped the run before its end (its figures so far are kept)

    def as_dict(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d["good_world_procrustes"] = _num(self.good_world_procrustes)
        d["status"] = self.status.as_dict()
        return {"bench": "fuzz", **d}

    def ok(self) -> bool:
        """Every message counted, nothing crashed or lost, every status read answered, the good
        world learned (Procrustes < 0.05), kept 80 % of its step rate and was never handed off."""
        return (
            self.error is None
            and self.crashes == 0
            and self.counted == self.sent
            and not self.losses
            and self.status.unanswered == 0
            and self.good_world_procrustes < 0.05
            and self.step_rate_ratio >= 0.8
            and self.handoffs == 0
        )


def _num(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), 5)


# message generators ------------------------------------------------------------------------------


class Fuzzer:
    """Hostile payloads from a seeded generator; `spec` is the good world's spec."""

    def __init__(self, spec: WorldSpec, seed: int) -> None:
        self.spec = spec
        self.rng = np.random.default_rng(seed)
        self.n_obs = 0

    def _valid_obs(self, step: int | None = None) -> pb.Observation:
        rng = self.rng
        p = pb.Observation(
            schema_version=1,
            world_id=self.spec.world_id,
            episode=int(rng.integers(0, 1 << 40)),
            step=int(rng.integers(0, 1 << 62)) if step is None else step,
            t=int(rng.integers(0, 100)),
            reward=float(rng.normal()),
            session="fuzz",
        )
        for s in self.spec.sensors:
            a = np.zeros(s.shape, dtype=s.dtype)
            p.tensors.add(name=s.name, dtype=s.dtype, shape=list(s.shape), data=a.tobytes())
        return p

    def garbage(self) -> bytes:
        n = int(self.rng.integers(1, 300))
        raw = self.rng.bytes(n)
        return raw if self.rng.random() < 0.5 else b"\x07" + raw  # field 0: never a valid protobuf

    def observation(self, cat: str) -> bytes:
        rng, p = self.rng, self._valid_obs()
        self.n_obs += 1
        if cat == "obs_bytes":
            return self.garbage()
        if cat == "obs_version":
            p.schema_version = int(rng.choice([0, 2, 3, 99, 2**32 - 1]))
        elif cat == "obs_dtype":
            t = p.tensors[int(rng.integers(len(p.tensors)))] if p.tensors else p.tensors.add(name="x", shape=[1])
            t.dtype = str(rng.choice(["float16", "complex64", "object", "", "U8", "<i4", "int128"]))
        elif cat == "obs_shape":
            t = p.tensors.add(name="extra", dtype="float32", shape=[3, 4], data=b"\0" * int(rng.choice([0, 47, 49])))
            if rng.random() < 0.3:
                t.shape[:] = [1] * 9
                t.data = b"\0" * 4
        elif cat == "obs_oversize":
            if self.n_obs % BIG_EVERY == 0:  # a real one: 33 MiB of data
                n = codec.MAX_TENSOR_BYTES + (1 << 20)
                p.tensors.add(name="big", dtype="uint8", shape=[n], data=bytes(n))
            elif rng.random() < 0.5:
                p.tensors.add(name="big", dtype="float64", shape=[1 << 20, 1 << 20], data=b"")
            else:
                for i in range(codec.MAX_TENSORS + 1):
                    p.tensors.add(name=f"t{i}", dtype="uint8", shape=[1], data=b"\0")
        elif cat == "obs_nonfinite":
            bad = float(rng.choice([np.nan, np.inf, -np.inf]))
            if rng.random() < 0.5:
                p.reward = bad
            else:
                a = rng.normal(size=8)
                a[int(rng.integers(8))] = bad
                p.tensors.add(name="junk", dtype="float64", shape=[8], data=a.tobytes())
        elif cat == "obs_spec":
            s = self.spec.sensors[int(rng.integers(len(self.spec.sensors)))]
            t = next(t for t in p.tensors if t.name == s.name)
            how = rng.integers(3)
            if how == 0:
                p.tensors.remove(t)
            elif how == 1:  # another dtype, same shape
                dt = "float64" if s.dtype != "float64" else "int32"
                t.dtype, t.data = dt, np.zeros(s.shape, dtype=dt).tobytes()
            else:  # another shape
                shape = [*s.shape, 2]
                t.shape[:], t.data = shape, np.zeros(shape, dtype=s.dtype).tobytes()
        elif cat == "obs_wrong_world":
            p.world_id = str(rng.choice(["other", "", "good2", GOOD + "\n"]))
        elif cat == "obs_duplicate":
            t = p.tensors.add()
            t.CopyFrom(p.tensors[0])
        return p.SerializeToString()

    def truth(self) -> bytes:
        rng = self.rng
        p = pb.Truth(schema_version=1, world_id=GOOD, kind="start_states", step=int(rng.integers(1 << 30)))
        pos = rng.normal(size=(81, 2))
        how = int(rng.integers(8))
        if how == 0:
            return self.garbage()
        if how == 1:
            p.schema_version = int(rng.choice([0, 2, 99]))
        elif how == 2:
            pos[int(rng.integers(81)), int(rng.integers(2))] = float(rng.choice([np.nan, np.inf]))
        elif how == 3:
            p.world_id = str(rng.choice(["other", "", "good "]))
        elif how == 4:  # positions that the evaluation cannot use: 1-D, integer
            pos = pos[:, 0] if rng.random() < 0.5 else pos.astype(np.int64)
        elif how == 5:
            p.tensors.add(name="pixels", dtype="float64", shape=list(pos.shape), data=pos.tobytes())
            return p.SerializeToString()  # no positions at all
        elif how == 6:
            p.tensors.add(name="positions", dtype="float64", shape=[1 << 30, 2], data=b"")
            return p.SerializeToString()
        else:
            p.tensors.add(name="positions", dtype="float64", shape=list(pos.shape), data=pos.tobytes())
        p.tensors.add(name="positions", dtype=pos.dtype.name, shape=list(pos.shape), data=pos.tobytes())
        return p.SerializeToString()

    def world_event(self) -> bytes:
        rng = self.rng
        p = pb.WorldEvent(schema_version=1, world_id=GOOD, kind="action_refused", reason="bad_action", step=1)
        how = int(rng.integers(3))
        if how == 0:
            return self.garbage()
        if how == 1:
            p.schema_version = int(rng.choice([0, 2, 99]))
        else:
            p.world_id = str(rng.choice(["other", "", "g00d"]))
        return p.SerializeToString()

    def unattached(self, n: int) -> tuple[str, bytes]:
        """(key, payload) for a world with no link: anything goes, the agent must not even decode it."""
        rng = self.rng
        wid = f"ghost-{n % 7}"
        which = int(rng.integers(3))
        key = (keys.world_obs, keys.world_truth, keys.world_event)[which](wid)
        if rng.random() < 0.5:
            return key, self.garbage()
        if which == 0:
            p = self._valid_obs(step=n)
            p.world_id = wid
            return key, p.SerializeToString()
        if which == 1:
            return key, codec.encode(Truth(wid, "start_states", {"positions": np.zeros((3, 2))}))
        return key, codec.encode(WorldEvent(wid, "control_applied", "lesion"))

    ATTACH_VARIANTS = (
        "garbage",
        "version",
        "bad_dtype",
        "other_world",
        "nan_bound",
        "unknown_program",
        "no_state_sensor",
        "huge_states",
        "box_for_gridworld",
        "error_reply",
        "bad_id",
    )

    def fake_spec(self, wid: str, variant: str) -> bytes:
        """The spec a fake world answers with (the variant says how it is broken)."""
        rng = self.rng
        p = pb.WorldSpec(schema_version=1, world_id=wid, kind="gridworld", program="gridworld", n_starts=81)
        p.sensors.add(name="state", dtype="int32", shape=[1], low=0, high=80)
        p.action_space.discrete_n = 4
        if variant == "garbage":
            return self.garbage()
        if variant == "version":
            p.schema_version = int(rng.choice([0, 2, 99]))
        elif variant == "bad_dtype":
            p.sensors[0].dtype = "float16"
        elif variant == "other_world":
            p.world_id = GOOD  # claims to be the good world
        elif variant == "nan_bound":
            p.reward_max = float("nan")
        elif variant == "unknown_program":
            # an unknown program falls back to the generic one, which needs at least one sensor
            p.program = p.kind = f"nosuch{int(rng.integers(100))}"
            del p.sensors[:]
        elif variant == "no_state_sensor":
            p.sensors[0].name = "pixels"
        elif variant == "huge_states":
            p.sensors[0].high = float(rng.choice([1e12, 1e300]))
        elif variant == "box_for_gridworld":
            p.action_space.discrete_n = 0
            p.action_space.low.append(-1.0)
            p.action_space.high.append(1.0)
        return p.SerializeToString()


def _refused(check: Callable[[], Any]) -> bool:
    try:
        check()
    except ProtocolError:
        return True
    return False


def _obs_kind(payload: bytes, spec: WorldSpec) -> str | None:
    """The rejection kind the agent's link will count for this payload (None: it would be accepted)."""
    try:
        obs = codec.decode(Observation, payload)
        if obs.world_id != spec.world_id:
            raise SpecMismatch("wrong world")
        check_against_spec(obs, spec)
    except ProtocolError as e:
        return e.kind
    return None


def _truth_refused(payload: bytes) -> bool:
    return _refused(lambda: check_truth(codec.decode(Truth, payload), GOOD))


def _event_refused(payload: bytes) -> bool:
    def check() -> None:
        if codec.decode(WorldEvent, payload).world_id != GOOD:
            raise SpecMismatch("wrong world")

    return _refused(check)


# processes and status --------------------------------------------------------------------------------


class _Tail:
    """Reads a child's stderr on a thread (so its pipe never fills); counts tracebacks."""

    def __init__(self, stream: IO[str] | None) -> None:
        if stream is None:
            raise ValueError("the child's stderr must be a pipe")
        self.tracebacks = 0
        self.last: list[str] = []
        threading.Thread(target=self._read, args=(stream,), daemon=True).start()

    def _read(self, stream: IO[str]) -> None:
        try:
            for line in stream:
                if line.startswith("Traceback"):
                    self.tracebacks += 1
                    self.last.append(line)
                elif self.last and len(self.last) < 200:
                    self.last.append(line)
        except (ValueError, OSError):
            pass


def _start(*args: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", "sensorimotor.tools.cli", *args],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def _stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        p.send_signal(2)
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _query_status(bus: Bus, timeout: float = QUERY_TIMEOUT) -> bytes | None:
    """One status query: the agent's answer, None when none came in `timeout` s (BusError: an error reply)."""
    r = bus.get(keys.agent_status(AGENT), timeout=timeout)
    return r[0].payload if r else None


def _status(bus: Bus) -> AgentStatus | None:
    """One status query, uncounted (None: no agent answers yet)."""
    try:
        payload = _query_status(bus)
        return codec.decode(AgentStatus, payload) if payload is not None else None
    except (BusError, ProtocolError):
        return None


def _counts(st: AgentStatus) -> dict[str, int]:
    """The counters the fuzz messages should land in, plus the good link's rejections by kind."""
    link = _good_link(st)
    rejected = dict(link.rejected) if link is not None else {}
    out = {c: int(st.counters.get(c, 0)) for c in (*COUNTERS, *OWNERSHIP) if c != "rejected"}
    out["rejected"] = sum(rejected.values())
    out.update({f"rejected.{k}": v for k, v in rejected.items()})
    return out


def _good_link(st: AgentStatus | None) -> LinkStatus | None:
    return None if st is None else next((ln for ln in st.links if ln.world_id == GOOD), None)


def _wait(pred: Callable[[], Any], timeout: float, every: float = 0.25) -> Any:
    end = time.monotonic() + timeout
    while True:
        v = pred()
        if v or time.monotonic() >= end:
            return v
        time.sleep(every)


def loss_cause(
    link: LinkStatus | None,
    agent_exit: int | None,
    world_exit: int | None,
    world_token: bool | None,
    events: list[AgentEvent],
) -> str:
    """Why the good world's link is not (or no longer attached) in the agent's status, from what the
    bench can see: the processes, the world's liveliness token and the agent's last events about it."""
    if agent_exit is not None:
        return f"the agent exited (code {agent_exit})"
    if world_exit is not None:
        return f"the world process exited (code {world_exit})"
    what = "the agent's status lists no link for it" if link is None else f"its link is {link.state}"
    if world_token is False:
        what += "; the world's liveliness token is gone"
    if events:
        ev = events[-1]
        what += f"; the agent's last event about it: {ev.kind} ({ev.reason or '-'}): {clip(ev.detail, 200)}"
    else:
        what += "; the agent published no event about it"
    return what


class _Stop(Exception):
    """The run cannot go on (the message says why); the figures so far are reported."""


# the run ------------------------------------------------------------------------------------------------


def run(
    messages: int,
    seed: int = 0,
    rate: float = 1000.0,
    settle: float = 60.0,
    converge: float = 120.0,
    workers: int | None = None,
    categories: tuple[str, ...] | None = None,
) -> Result:
    """Fuzz an agent with `messages` hostile messages at `rate` per second beside a good gridworld.

    Parameters
    ----------
    messages : int
        How many hostile messages to send.
    seed : int
        Seed of the message generator (the same seed sends the same messages).
    rate : float
        Messages per second (a steady pace).
    settle : float
        Seconds to wait, after the last message, for the counters to reach `sent`.
    converge : float
        Seconds to wait, after that, for the good world's embedding error to drop under 0.05.
    workers : int or None
        The agent's `--workers` (None: its default, the number of cores).
    categories : tuple of str or None
        Only these categories of hostile message (None: every one, in their usual proportions);
        to see which kind of traffic costs the good world most.

    Returns
    -------
    Result
        Sent, counted, crashes, the good world's last Procrustes error and the breakdowns; always
        returned once the processes started (`error` says what cut a run short).
    """
    cats = list(CATEGORIES) if not categories else list(categories)
    unknown = sorted(set(cats) - set(CATEGORIES))
    if unknown:
        raise ValueError(f"unknown categories {unknown}; choose from {', '.join(CATEGORIES)}")
    ep = f"tcp/127.0.0.1:{free_port()}"
    res = Result()
    agent = _start("agent", "--listen", ep, "-q", *(() if workers is None else ("--workers", str(workers))))
    agent_log = _Tail(agent.stderr)
    world = _start("world", "gridworld", "--id", GOOD, "--connect", ep, "-q")
    _Tail(world.stderr)
    handles: list[Any] = []  # the fake worlds' queryables and tokens: they go with the session
    try:
        with Bus(BusConfig(mode="client", connect=(ep,), retry=True), wait_limit=60) as bus:
            _fuzz(bus, res, agent, world, handles, messages, seed, rate, settle, converge, cats)
    except _Stop as e:
        res.error = str(e)
    except Exception as e:  # noqa: BLE001 - the bench reports what stopped it, with its figures so far
        res.error = f"{type(e).__name__}: {e}"
    finally:
        res.agent_alive = agent.poll() is None
        _stop(world)
        _stop(agent)
    res.tracebacks = agent_log.tracebacks
    res.crashes = (0 if res.agent_alive else 1) + res.tracebacks
    if agent_log.last:
        sys.stderr.write("".join(agent_log.last[:200]))
    return res


def _fuzz(
    bus: Bus,
    res: Result,
    agent: subprocess.Popen,
    world: subprocess.Popen,
    handles: list[Any],
    messages: int,
    seed: int,
    rate: float,
    settle: float,
    converge: float,
    cats: list[str],
) -> None:
    """The run's measurements into `res` (see `run`)."""
    link = _wait(lambda: (ln := _good_link(_status(bus))) is not None and ln.steps > 100 and ln, 120)
    if not link:
        raise _Stop("the good world did not attach to the agent within 120 s")
    spec = codec.decode(WorldSpec, bus.get(keys.world_spec(GOOD), timeout=5.0)[0].payload)
    reader = StatusReader(lambda: _query_status(bus), res.status)

    def read(phase: str) -> tuple[AgentStatus, LinkStatus | None]:
        """The agent's status and the good link (see StatusReader.good); an agent that answers none
        of the status queries of one read ends the run (its figures so far are reported)."""
        st, ln = reader.good()
        if st is None:
            raise _Stop(
                f"the agent answered none of {QUERY_TRIES} status queries ({QUERY_TIMEOUT:g} s each) in the {phase}"
            )
        return st, ln

    events: list[AgentEvent] = []  # the agent's events about the good world (the cause of a loss)

    def on_event(m: Any) -> None:
        try:
            events.append(codec.decode(AgentEvent, m.payload))
        except ProtocolError:
            pass
        del events[:-20]

    handles.append(bus.subscribe(keys.agent_event(AGENT, GOOD), on_event))

    def world_token() -> bool | None:
        try:
            return bool(bus.alive(keys.alive_world(GOOD), timeout=2.0))
        except BusError:
            return None

    def good_steps(phase: str) -> tuple[float, int] | None:
        """(when, the good link's steps), or None: the link is gone (a loss, with its cause, in
        `losses`)."""
        ln = None
        if agent.poll() is None:
            ln = read(phase)[1]
            if ln is not None and ln.state == "attached":
                return time.perf_counter(), int(ln.steps)
        cause = loss_cause(ln, agent.poll(), world.poll(), world_token(), list(events))
        res.losses.append({"phase": phase, "cause": cause})
        return None

    def steps_per_s(a: tuple[float, int] | None, b: tuple[float, int] | None) -> float | None:
        if a is None or b is None:
            return None  # not measured: see `losses` and `status`
        return round((b[1] - a[1]) / (b[0] - a[0]), 1) if b[0] > a[0] else 0.0

    fz = Fuzzer(spec, seed)
    pubs: dict[str, Any] = {}

    def put(key: str, payload: bytes) -> None:
        pub = pubs.get(key)
        if pub is None:
            pub = pubs[key] = bus.publisher(key, None, block=True)
        pub.put(payload)

    weights = np.array([CATEGORIES[c][0] for c in cats], dtype=float)
    plan = fz.rng.choice(len(cats), size=messages, p=weights / weights.sum())
    sent: Counter[str] = Counter()
    variants: Counter[str] = Counter()
    expected_kinds: Counter[str] = Counter()
    # every message is built and checked before the clock starts, so that the generator's own
    # work does not take the cores from the agent and the world while the step rate is measured
    todo: list[tuple[str, str, bytes | None]] = []  # (category, key or fake world id, payload)
    for i, ci in enumerate(plan):
        cat = cats[int(ci)]
        if cat.startswith("obs_"):
            built = fz.observation(cat)
            kind = _obs_kind(built, spec)
            assert kind is not None, f"generated an observation the agent would accept ({cat})"
            expected_kinds[kind] += 1
            todo.append((cat, keys.world_obs(GOOD), built))
        elif cat == "truth_bad":
            built = fz.truth()
            assert _truth_refused(built), "generated a truth the agent would accept"
            todo.append((cat, keys.world_truth(GOOD), built))
        elif cat == "event_bad":
            built = fz.world_event()
            assert _event_refused(built), "generated a world event the agent would accept"
            todo.append((cat, keys.world_event(GOOD), built))
        elif cat == "unattached":
            todo.append((cat, *fz.unattached(i)))
        else:
            variant = Fuzzer.ATTACH_VARIANTS[int(fz.rng.integers(len(Fuzzer.ATTACH_VARIANTS)))]
            variants[variant] += 1
            if variant == "bad_id":  # a legal key chunk, not a legal world id
                wid = str(fz.rng.choice([f"fz~{i}", f"fz {i}", "f" * 65 + str(i), f"fz@{i}"]))
                todo.append((cat, wid, None))
            else:  # an empty spec: the fake world answers with an error reply
                todo.append((cat, f"fz-{i}", b"" if variant == "error_reply" else fz.fake_spec(f"fz-{i}", variant)))

    groups = {
        "agent": [agent.pid],
        "workers": children(agent.pid),
        "world": [world.pid],
        "bench": [os.getpid()],
    }

    def window_cpu(t0: float, ticks: dict[str, int], busy: tuple[float, float] | None) -> dict[str, float | None]:
        used: dict[str, float | None] = dict(cores_used(ticks, cpu_ticks(groups), time.perf_counter() - t0))
        used["machine_busy"] = busy_fraction(busy, machine_cpu())
        return used

    # the baseline: the same agent and world, as long as the fuzz is meant to last, no hostile message
    b0 = good_steps("baseline")
    w0, c0, m0 = time.perf_counter(), cpu_ticks(groups), machine_cpu()
    time.sleep(messages / rate)
    res.baseline_before = steps_per_s(b0, good_steps("baseline")) or 0.0
    res.cpu["baseline"] = window_cpu(w0, c0, m0)
    before = _counts(read("baseline")[0])
    version_before = link.embedding_version
    good_claims: list[tuple[str, bool]] = []  # claim tokens of the good world seen during the fuzz
    handles.append(bus.watch_alive(keys.alive_claim(GOOD, "*"), lambda k, a: good_claims.append((k, a)), False))
    f0 = good_steps("fuzz")
    w0, c0, m0 = time.perf_counter(), cpu_ticks(groups), machine_cpu()
    t0 = time.perf_counter()
    for i, (cat, where, body) in enumerate(todo):
        if cat != "attach":
            assert body is not None
            put(where, body)
        else:
            if body is not None:

                def answer(k: str, p: bytes | None, data: bytes = body) -> bytes:
                    if not data:
                        raise LookupError("this fake world has no spec")  # an error reply
                    return data

                handles.append(bus.queryable(keys.world_spec(where), answer, codec.schema_name(WorldSpec)))
            handles.append(bus.token(keys.alive_world(where)))
        sent[cat] += 1
        ahead = (i + 1) / rate - (time.perf_counter() - t0)
        if ahead > PACE_SLACK:
            time.sleep(ahead)
    res.seconds = round(time.perf_counter() - t0, 3)
    res.sent = sum(sent.values())
    res.fuzz_steps_per_s = steps_per_s(f0, good_steps("fuzz")) or 0.0
    res.cpu["fuzz"] = window_cpu(w0, c0, m0)
    res.rate = round(messages / res.seconds, 1) if res.seconds else 0.0
    res.categories = dict(sorted(sent.items()))
    res.attach_variants = dict(sorted(variants.items()))
    expected: Counter[str] = Counter()
    for cat, n in sent.items():
        expected[CATEGORIES[cat][1]] += n
    res.expected = {c: expected.get(c, 0) for c in COUNTERS}
    res.expected.update({f"rejected.{k}": v for k, v in sorted(expected_kinds.items())})

    def delta() -> dict[str, int]:
        st, ln = read("settling")  # the good link's rejections are part of the count: not without it
        if ln is None:
            return {}
        now = _counts(st)
        return {k: now.get(k, 0) - before.get(k, 0) for k in set(now) | set(before)}

    def settled() -> dict[str, int] | None:
        d = delta()
        return d if sum(d.get(c, 0) for c in COUNTERS) >= res.sent else None

    s0 = time.perf_counter()
    d = _wait(settled, settle) or delta()
    res.settle_seconds = round(time.perf_counter() - s0, 1)
    res.counters = {c: d.get(c, 0) for c in COUNTERS}
    res.rejected_kinds = {k.split(".", 1)[1]: v for k, v in sorted(d.items()) if k.startswith("rejected.") and v}
    res.counted = sum(res.counters.values())
    res.handoffs = len(good_claims)
    res.ownership = {c: d.get(c, 0) for c in OWNERSHIP}
    a0 = good_steps("after")
    time.sleep(messages / rate)
    res.baseline_after = steps_per_s(a0, good_steps("after")) or 0.0
    quiet = [r for r in (res.baseline_before, res.baseline_after) if r > 0]
    res.baseline_steps_per_s = round(sum(quiet) / len(quiet), 1) if quiet else 0.0
    if res.baseline_steps_per_s > 0:
        res.step_rate_ratio = round(res.fuzz_steps_per_s / res.baseline_steps_per_s, 3)

    def converged() -> LinkStatus | None:
        ln = read("convergence")[1]
        return ln if ln is not None and ln.last_procrustes_error < 0.05 else None

    good = _wait(converged, converge, every=1.0) or read("convergence")[1]
    if good is None:
        good_steps("converge")  # counts the loss, with its cause
        return
    res.good_world_procrustes = good.last_procrustes_error
    res.good_world = {
        "state": good.state,
        "steps": good.steps,
        "embedding_version": good.embedding_version,
        "embeddings_since_fuzz_start": good.embedding_version - version_before,
        "alive": world.poll() is None,
    }


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fuzz",
        help="hostile messages on every agent key beside a good world: all counted, no crash",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--messages", type=int, default=10000, help="hostile messages to send (default 10000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the message generator (default 0)")
    p.add_argument("--rate", type=float, default=1000.0, help="messages per second (default 1000)")
    p.add_argument(
        "--categories",
        default="",
        help=f"only these kinds of hostile message, comma-separated (default every one: {','.join(CATEGORIES)})",
    )
    p.add_argument("--json", action="store_true", help="one JSON object on one line")
    p.set_defaults(func=main_args)


def main(
    messages: int, seed: int = 0, rate: float = 1000.0, as_json: bool = False, categories: tuple[str, ...] = ()
) -> int:
    """Run the fuzz and print its figures (always, also when the run was cut short); exit 0 when
    `Result.ok` (every message counted, no crash, no link lost, every status read answered, the good
    world's embedding error under 0.05, 80 % of its step rate kept, no hand-off), else 1."""
    r = run(messages, seed, rate, categories=categories or None)
    if as_json:
        print(json.dumps(r.as_dict()))
    else:
        print(
            f"sent {r.sent} in {r.seconds} s ({r.rate}/s), counted {r.counted}, crashes {r.crashes}, "
            f"good world Procrustes {_num(r.good_world_procrustes)}, its step rate {r.fuzz_steps_per_s}/s "
            f"against {r.baseline_steps_per_s}/s without fuzz (ratio {r.step_rate_ratio}), hand-offs {r.handoffs}, "
            f"links lost {len(r.losses)}"
        )
        for c in COUNTERS:
            print(f"  {c:<16} expected {r.expected.get(c, 0):>6}  counted {r.counters.get(c, 0):>6}")
        print(f"  rejected by kind: {r.rejected_kinds}")
        for window, used in r.cpu.items():
            print(f"  cores used {window:<9} " + ", ".join(f"{k} {v}" for k, v in used.items()))
        st = r.status
        print(
            f"  status queries {st.queries}: {st.timeouts} unanswered in {QUERY_TIMEOUT:g} s and asked again, "
            f"{st.unanswered} reads given up, {st.link_missing} answers without the good link asked again, "
            f"slowest {st.slowest_s} s"
        )
        for loss in r.losses:
            print(f"  link lost ({loss['phase']}): {loss['cause']}")
        if r.error:
            print(f"  stopped early: {r.error}")
    return 0 if r.ok() else 1


def main_args(args: argparse.Namespace) -> int:
    cats = tuple(c.strip() for c in args.categories.split(",") if c.strip())
    unknown = sorted(set(cats) - set(CATEGORIES))
    if unknown:
        print(f"sme bench fuzz: unknown categories {unknown}; choose from {', '.join(CATEGORIES)}", file=sys.stderr)
        return 2
    return main(args.messages, args.seed, args.rate, args.json, cats)
