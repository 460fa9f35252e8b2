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

import argparse
import json
import os
import subprocess
import sys
import time
from collections import Counter
from typing import Any

import numpy as np

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig, BusError
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import AgentEvent, AgentStatus, LinkStatus, WorldSpec
from sensorimotor.tools.bench.fuzz_messages import (
    BIG_EVERY,
    CATEGORIES,
    Fuzzer,
    _event_refused,
    _obs_kind,
    _truth_refused,
)
from sensorimotor.tools.bench.fuzz_status import (
    AGENT,
    COUNTERS,
    GOOD,
    LINK_PATIENCE,
    OWNERSHIP,
    QUERY_TIMEOUT,
    QUERY_TRIES,
    ROOT,
    Result,
    StatusReader,
    StatusReads,
    _counts,
    _good_link,
    _num,
    _query_status,
    _start,
    _status,
    _Stop,
    _stop,
    _Tail,
    _wait,
    loss_cause,
)
from sensorimotor.tools.bench.procstat import busy_fraction, children, cores_used, cpu_ticks, machine_cpu
from sensorimotor.tools.common import free_port

__all__ = [
    "AGENT",
    "BIG_EVERY",
    "CATEGORIES",
    "COUNTERS",
    "GOOD",
    "LINK_PATIENCE",
    "OWNERSHIP",
    "QUERY_TIMEOUT",
    "QUERY_TRIES",
    "ROOT",
    "Fuzzer",
    "Result",
    "StatusReader",
    "StatusReads",
    "add_parser",
    "loss_cause",
    "main",
    "main_args",
    "run",
]

# the sender sleeps only once it is this far ahead of the steady pace (a few messages at a time):
# a sleep per message was a wake-up per message, a fifth of a core spent by the fuzzer itself
PACE_SLACK = 0.005


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
