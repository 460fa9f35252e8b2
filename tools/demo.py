"""`sme demo`: the agent daemon and one world in one command, with progress and a summary."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from typing import Any

from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.protocol import keys
from sensorimotor.protocol.bus import Bus, BusConfig, BusError
from sensorimotor.protocol.messages import AgentEvent, Embedding
from sensorimotor.protocol.params import assignments
from sensorimotor.tools.common import format_embedding, format_event, output_closed
from sensorimotor.worlds.node import WorldNode
from sensorimotor.worlds.registry import WORLDS, make_world


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="agent + a world in one command, with progress and a summary",
        description="Start the agent daemon (zenoh router on --listen, loopback) and a world "
        "node connected to it, show each embedding version as it arrives, and print a summary. "
        "Stops after --seconds, --steps or Ctrl-C.",
    )
    p.add_argument("--world", default="gridworld", help="world to run: " + ", ".join(sorted(WORLDS)))
    p.add_argument(
        "--param",
        action="append",
        metavar="K=V",
        help="world parameter, repeatable (e.g. barrier=true; see `sme world NAME --list-params`)",
    )
    p.add_argument("--seconds", type=float, default=15.0, help="run time in seconds (default 15)")
    p.add_argument("--steps", type=int, default=None, help="stop after this many world steps (and at most --seconds)")
    p.add_argument("--seed", type=int, default=0, help="seed of world and agent")
    p.add_argument(
        "--listen",
        default=None,
        metavar="ENDPOINT",
        help=f"where the daemon listens (default {keys.DEFAULT_ENDPOINT}, with --secure {keys.DEFAULT_SECURE_ENDPOINT})",
    )
    p.add_argument(
        "--secure",
        default=None,
        metavar="DIR",
        help="run on a locked-down bus with the credentials of `sme secure init DIR`: the agent listens "
        "with mutual TLS and access control (agent credential), the world connects with the world credential",
    )
    p.set_defaults(func=main_args, log_default=-1)  # quiet logs unless -v: the demo prints its own progress


def main_args(args: argparse.Namespace) -> int:
    if args.steps is not None and args.steps < 1:
        print("sme demo: --steps must be >= 1", file=sys.stderr)
        return 2
    try:
        world = make_world(args.world, None, args.seed, assignments(args.param))
    except ValueError as e:
        print(f"sme demo: {e}", file=sys.stderr)
        return 2
    wid = world.world_id
    last: dict[str, Any] = {}
    errors: list[float] = []
    t0 = time.monotonic()

    stop = threading.Event()
    broken_pipe = threading.Event()

    def say(line: str) -> None:
        """Print a progress line; if the reader closed stdout, stop the demo (from any thread)."""
        if broken_pipe.is_set():
            return
        try:
            print(line, flush=True)
        except BrokenPipeError:
            broken_pipe.set()
            stop.set()

    def on_output(channel: str, msg: Any) -> None:
        stamp = f"{time.monotonic() - t0:6.1f}s "
        if isinstance(msg, Embedding):
            last["embedding"] = msg
            say(stamp + format_embedding(msg))
            if msg.procrustes_error is not None:
                errors.append(msg.procrustes_error)
        elif isinstance(msg, AgentEvent) and msg.kind not in ("policy_iteration", "paused"):
            say(stamp + format_event(msg))

    agent_cfg = BusConfig.for_role("agent", args.listen, args.secure)
    endpoint = agent_cfg.listen[0]
    warning = agent_cfg.exposure_warning()
    if warning:
        print(f"sme demo: WARNING: {warning}", file=sys.stderr, flush=True)
    try:
        agent_bus = Bus(agent_cfg)
    except BusError as e:
        print(f"sme demo: {e}", file=sys.stderr)
        return 2
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    say(
        f"sme demo: agent on {endpoint}{' (mutual TLS + access control)' if args.secure else ''}, world {wid!r} ({world.kind}), {args.seconds:g} s; Ctrl-C stops"
    )
    with agent_bus, world:
        daemon = AgentDaemon(agent_bus, seed=args.seed, on_output=on_output)
        daemon.start()
        dthread = threading.Thread(target=daemon.run, daemon=True)
        dthread.start()
        with Bus(BusConfig.for_role("world", endpoint, args.secure)) as world_bus:
            node = WorldNode(world, world_bus, wid, max_steps=args.steps)
            nthread = threading.Thread(target=node.run, daemon=True)
            nthread.start()
            next_tick = 5.0
            while not stop.is_set() and time.monotonic() - t0 < args.seconds and nthread.is_alive():
                stop.wait(0.1)
                if output_closed():
                    broken_pipe.set()
                    break
                el = time.monotonic() - t0
                if el >= next_tick:
                    next_tick += 5.0
                    say(
                        f"{el:6.1f}s [{wid}] {node.stats.steps} steps ({node.stats.steps / el:,.0f}/s), "
                        f"{node.stats.episodes} episodes"
                    )
            node.stop()
            nthread.join(timeout=5)
        daemon.stop()
        dthread.join(timeout=5)
        daemon.close()
        status = daemon.status()
    if broken_pipe.is_set():
        raise BrokenPipeError("stdout closed by its reader")  # cli.main turns it into a quiet exit
    el = time.monotonic() - t0
    print("\nsummary")
    print(
        f"  world {wid} ({world.kind}): {node.stats.steps} lockstep steps in {el:.1f} s "
        f"({node.stats.steps / max(el, 1e-9):,.0f} steps/s), {node.stats.episodes} episodes"
    )
    for ln in status.links:
        print(f"  link: {ln.embedding_version} embedding versions, rejected inputs {ln.rejected or 0}")
    emb = last.get("embedding")
    if emb is None:
        print("  no embedding yet: run longer (--seconds)")
        return 1
    err = "n/a" if emb.procrustes_error is None else f"{emb.procrustes_error:.4f}"
    print(
        f"  final embedding v{emb.version} ({emb.trigger}): {emb.coordinates.shape[0]} points in "
        f"{emb.coordinates.shape[1]}-D, Procrustes error against truth {err}"
    )
    if len(errors) > 1:
        print(f"  Procrustes error fell from {errors[0]:.4f} (v1) to {min(errors):.4f} (best) as the agent learned")
    return 0
