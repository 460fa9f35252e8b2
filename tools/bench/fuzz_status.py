"""`sme bench fuzz`: the agent and world processes it runs, how it reads the agent's status under
load (`StatusReader`: late answers asked again and counted, a missing link given time), what it
counts, and what one run saw (`Result`)."""

import math
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO, Any

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusError
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import AgentEvent, AgentStatus, LinkStatus, clip

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
GOOD = "good"
AGENT = "a0"
COUNTERS = ("rejected", "bad_truth", "bad_world_event", "unattached", "attach_failed")
OWNERSHIP = ("shed", "lost", "taken_over")  # the agent's hand-off counters (claim races on fake worlds count in `lost`)
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
