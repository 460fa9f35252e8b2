"""`sme watch`: print embedding versions and agent events as they arrive; a body change is marked
three times: when the world applied it (its own report), when the agent noticed (a drop detected)
and when the relearned map came (`change_mark`)."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
import time

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusError, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import AgentEvent, Embedding, EventKind, WorldEvent, WorldEventKind
from sensorimotor.tools.common import (
    EMBEDDING_COLUMNS,
    EXIT_INTERRUPTED,
    embedding_dict,
    event_dict,
    format_embedding,
    format_event,
    output_closed,
    print_json,
)

log = logging.getLogger("sme.watch")

#: the marks of a body change: applied by the world, noticed by the agent, relearned
MARKS: dict[str, str] = {
    WorldEventKind.CONTROL_APPLIED: "change",
    WorldEventKind.CONTROL_REFUSED: "change refused",
    EventKind.DROP_DETECTED: "noticed",
    EventKind.RELEARNED: "relearned",
}


def change_mark(kind: str, reason: str = "") -> str | None:
    """Which mark of a body change an event is (a world's `control_applied`/`control_refused`, or the
    agent's passing-on of one as `world_event`; `drop_detected`; `relearned`), else None."""
    if kind == EventKind.WORLD_EVENT:
        kind = reason
    return MARKS.get(kind)


def format_change(ev: WorldEvent) -> str:
    """A world's report of a control as one marked line."""
    mark = change_mark(ev.kind) or ev.kind
    at = f" (step {ev.step})" if ev.step else ""
    return f">> [{ev.world_id}] {mark}{at}: {ev.reason}: {ev.detail}"


def world_event_dict(ev: WorldEvent) -> dict[str, object]:
    """A world's report of a control as a JSON-ready dict (`type` world_event, with its `mark`)."""
    return {
        "type": "world_event",
        "world": ev.world_id,
        "kind": ev.kind,
        "reason": ev.reason,
        "detail": ev.detail,
        "step": ev.step,
        "timestamp": ev.timestamp,
        "mark": change_mark(ev.kind),
    }


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "watch",
        help="print embedding versions and agent events as they arrive",
        description="Subscribe to the agent's embeddings and events and print them, one line each. Waits for "
        "the agent if it is not up yet. A body change is marked (lines beginning '>>', or a 'mark' in --json): "
        "when the world applied it, when the agent noticed, when the map was relearned. Exit status 1 if --timeout passes before --count "
        "embeddings arrived (130 if Ctrl-C comes first). Each embedding line: " + EMBEDDING_COLUMNS + ".",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="one JSON object per line: embeddings carry world, version, trigger, n_points, dims, "
        "eigenvalues, procrustes_error, scores (trustworthiness, continuity, metric and topological "
        "dissimilarity, n_neighbors, n_points; null without truth), step, metrics; events carry kind and detail",
    )
    p.add_argument("--coords", action="store_true", help="include ids and coordinates in --json output")
    p.add_argument("--count", type=int, default=None, metavar="N", help="exit after N embeddings")
    p.add_argument("--timeout", type=float, default=None, metavar="S", help="exit after S seconds")
    p.add_argument("--agent", default="*", help="agent id to watch (default: all)")
    p.add_argument("--world", default="*", help="world id to watch (default: all)")
    p.add_argument("--no-events", action="store_true", help="embeddings only")
    add_bus_arguments(p, "reader")
    p.set_defaults(func=main_args)


def main_args(args: argparse.Namespace) -> int:
    try:
        bus = Bus(bus_config_from_args(args, "reader"), wait_limit=args.timeout)
    except BusError as e:
        print(f"sme watch: {e}", file=sys.stderr)
        return 2
    done = threading.Event()
    interrupted = threading.Event()
    broken_pipe = threading.Event()  # the reader of our stdout went away (`sme watch --json | head -1`)
    seen = [0]
    lock = threading.Lock()

    def receiver(cls, show, counts: bool):
        def on(msg):
            try:
                m = codec.decode(cls, msg.payload)
            except ProtocolError as err:
                print(f"sme watch: skipped a bad {cls.__name__} message on {msg.key}: {err}", file=sys.stderr)
                return
            with lock:
                if done.is_set():
                    return
                try:
                    show(m)
                except BrokenPipeError:  # raised on zenoh's thread: hand it to the main thread
                    broken_pipe.set()
                    done.set()
                    return
                if counts:
                    seen[0] += 1
                    if args.count is not None and seen[0] >= args.count:
                        done.set()

        return on

    def show_event(e: AgentEvent) -> None:
        mark = change_mark(e.kind, e.reason)
        if e.kind == EventKind.WORLD_EVENT and mark is not None:
            return  # the world's own report of a control is shown (the agent passes it on, rate-limited)
        if args.json:
            print_json(event_dict(e) | ({"mark": mark} if mark else {}))
        else:
            print((">> " if mark else "") + format_event(e), flush=True)

    def show_world_event(ev: WorldEvent) -> None:
        if change_mark(ev.kind) is None:
            return
        if args.json:
            print_json(world_event_dict(ev))
        else:
            print(format_change(ev), flush=True)

    if args.json:
        on_embedding = receiver(Embedding, lambda e: print_json(embedding_dict(e, args.coords)), True)
    else:
        on_embedding = receiver(Embedding, lambda e: print(format_embedding(e), flush=True), True)
    on_event = receiver(AgentEvent, show_event, False)
    on_world_event = receiver(WorldEvent, show_world_event, False)

    def on_signal(*_: object) -> None:
        interrupted.set()
        done.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    with bus:
        embeddings = f"{keys.PREFIX}/agent/{args.agent}/embedding/{args.world}"
        bus.subscribe(embeddings, on_embedding)
        if not args.no_events:
            bus.subscribe(f"{keys.PREFIX}/agent/{args.agent}/event/{args.world}", on_event)
            bus.subscribe(keys.world_event(args.world), on_world_event)
        log.info("watching %s%s", embeddings, "" if args.no_events else " and events")
        deadline = None if args.timeout is None else time.monotonic() + args.timeout
        while not done.is_set():
            if deadline is not None and time.monotonic() >= deadline:
                break
            if output_closed():
                broken_pipe.set()
                break
            done.wait(0.1)
        done.set()
    if broken_pipe.is_set():
        raise BrokenPipeError("stdout closed by its reader")  # cli.main turns it into a quiet exit
    if args.count is not None and seen[0] < args.count:
        if interrupted.is_set():
            return EXIT_INTERRUPTED
        print(f"sme watch: timed out after {args.timeout} s with {seen[0]} of {args.count} embeddings", file=sys.stderr)
        return 1
    return 0
