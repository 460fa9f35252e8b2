"""`sme demo`: the agent daemon and one world in one command, with progress and an honest summary.

Unbounded (no --seconds, no --steps) it runs 15 s and then on until the world's map holds (the
last versions near the best, or one the program holds, at an error that is a map:
`tools.summary.settled`; a world without truth: its first embedding), at most 180 s; stopped at that bound it says what the map would need
at the run's pace. The summary says the first, best and final Procrustes error, whether the last
versions are near the best, from how many start states the greedy policy reached the goal and,
when the world was not embedded or cannot be scored, why and what to do (`tools.summary`).
`--plot DIR` writes the final map in the truth's units beside the error and goal fraction per
step as a PNG (`tools.plot`). `--perturb KIND@STEP` changes the body once the world has taken STEP
steps (the agent is not told); the summary says when the change was noticed and how well the map
came back."""

from __future__ import annotations

import argparse
import signal
import sys
import textwrap
import threading
import time
from typing import Any

from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig, BusError, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.messages import AgentEvent, Control, Embedding, EventKind, Trigger
from sensorimotor.protocol.params import assignments
from sensorimotor.tools.common import EMBEDDING_COLUMNS, format_embedding, format_event, output_closed
from sensorimotor.tools.summary import settled, still_to_go, verdict
from sensorimotor.worlds.node import WorldNode
from sensorimotor.worlds.registry import WORLDS, make_world

DEFAULT_SECONDS = 15.0  # an unbounded demo runs this long at least ...
MAX_SECONDS = 180.0  # ... and, while the world's map has not held yet, at most this long


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="agent + a world in one command, with progress and a summary",
        description="Start the agent daemon (a zenoh router, loopback by default) and a world node connected to "
        "it, show each embedding version as it arrives, and print a summary: first, best and final error and "
        "whether the map held, or why the world was not embedded. Without --seconds or --steps it runs "
        f"{DEFAULT_SECONDS:g} s, and longer (at most {MAX_SECONDS:g} s) until the world's map holds; "
        "Ctrl-C stops it. Each embedding line: " + EMBEDDING_COLUMNS + ".",
    )
    p.add_argument("--world", default="gridworld", help="world to run: " + ", ".join(sorted(WORLDS)) + ", gym:ENV_ID")
    p.add_argument(
        "--param",
        action="append",
        metavar="K=V",
        help="world parameter, repeatable (e.g. barrier=true; see `sme world NAME --list-params`)",
    )
    p.add_argument(
        "--seconds",
        type=float,
        default=None,
        metavar="S",
        help=f"run exactly this long (default: {DEFAULT_SECONDS:g} s, and on until the map holds, at most "
        f"{MAX_SECONDS:g} s)",
    )
    p.add_argument(
        "--steps", type=int, default=None, metavar="N", help="stop after this many world steps (and at most --seconds)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of world and agent")
    p.add_argument(
        "--plot",
        default=None,
        metavar="DIR",
        help="write the final embedding as DIR/<world>.png: truth, the map aligned onto it in its units and "
        "coloured by true position, the error and goal fraction per step, the eigenvalue spectrum",
    )
    p.add_argument(
        "--perturb",
        default=None,
        metavar="KIND@STEP",
        help="change the body once the world has taken STEP steps: KIND[:K=V,...]@STEP, e.g. reverse@5000 or "
        "lesion:what=sensor@8000 (the kinds: `sme perturb --list --world ID`); the summary says when it was "
        "noticed and how well the map came back",
    )
    add_bus_arguments(p, "agent")
    p.set_defaults(func=main_args, log_default=-1)  # quiet logs unless -v: the demo prints its own progress


def parse_perturb(text: str) -> tuple[str, dict[str, str], int]:
    """``KIND[:K=V,...]@STEP`` as (kind, params, step); a ValueError that shows the form."""
    form = "KIND[:K=V,...]@STEP, e.g. reverse@5000 or lesion:what=sensor@8000"
    what, at, step = text.rpartition("@")
    if not at or not what or not step.strip().isdigit():
        raise ValueError(f"--perturb {text!r}: expected {form}")
    kind, _, rest = what.partition(":")
    params: dict[str, str] = {}
    for item in filter(None, rest.split(",")):
        k, eq, v = item.partition("=")
        if not eq or not k:
            raise ValueError(f"--perturb {text!r}: parameter {item!r} is not K=V; expected {form}")
        params[k.strip()] = v.strip()
    return kind.strip(), params, int(step)


def change_summary(
    kind: str, at: int | None, seconds: float | None, embeddings: list[Embedding], events: list[AgentEvent]
) -> list[str]:
    """The summary's lines on a scripted body change: when it came, when the agent noticed and how
    well the relearned map came back (error before and after, against the changed body's truth)."""
    if at is None:
        return [f"  body change {kind}: not applied (the run ended first; --steps or --seconds runs longer)"]
    applied = [e for e in events if e.kind == EventKind.WORLD_EVENT and e.reason == "control_applied"]
    refused = [e for e in events if e.kind == EventKind.WORLD_EVENT and e.reason == "control_refused"]
    if refused and not applied:
        return [f"  body change {kind} at step {at:,}: refused by the world ({refused[0].detail})"]
    if applied and applied[0].step > 0:
        at = applied[0].step  # the world's own word: the first observation of the changed body
    lines = [f"  body change {kind} at step {at:,}" + (f" ({applied[0].detail})" if applied else "")]
    drop = next((e for e in events if e.kind == EventKind.DROP_DETECTED and e.step >= at), None)
    if drop is None:
        lines.append("  not noticed within the run (no reward drop detected after it)")
        return lines
    when = ""
    if seconds is not None and drop.timestamp:
        dt = max(0.0, drop.timestamp - seconds)
        when = f", {dt * 1000:.0f} ms" if dt < 1 else f", {dt:.1f} s"
    lines.append(f"  noticed at step {drop.step:,}: {drop.step - at:,} steps{when} after the change ({drop.detail})")
    before = [e for e in embeddings if e.step <= at and e.procrustes_error is not None]
    again = next((e for e in embeddings if e.trigger == Trigger.RELEARNED and e.step >= drop.step), None)
    if again is None:
        lines.append("  not relearned within the run (--seconds S runs longer)")
        return lines
    err = "" if again.procrustes_error is None else f", error {again.procrustes_error:.4f}"
    if before and again.procrustes_error is not None:
        b = float(before[-1].procrustes_error or 0.0)
        err += f" (before the change {b:.4f}, {again.procrustes_error / max(b, 1e-9):.2f}x)"
    lines.append(
        f"  relearned: v{again.version} at step {again.step:,}, {again.step - at:,} steps after the change{err}"
    )
    return lines


def main_args(args: argparse.Namespace) -> int:
    scripted: tuple[str, dict[str, str], int] | None = None
    if args.perturb is not None:
        try:
            scripted = parse_perturb(args.perturb)
        except ValueError as e:
            print(f"sme demo: {e}", file=sys.stderr)
            return 2
    if args.steps is not None and args.steps < 1:
        print("sme demo: --steps must be >= 1", file=sys.stderr)
        return 2
    if args.seconds is not None and not args.seconds > 0:
        print("sme demo: --seconds must be > 0", file=sys.stderr)
        return 2
    try:
        world = make_world(args.world, None, args.seed, assignments(args.param))
    except ValueError as e:
        print(f"sme demo: {e}", file=sys.stderr)
        return 2
    wid = world.world_id
    embeddings: list[Embedding] = []
    events: list[AgentEvent] = []
    t0 = time.monotonic()
    # bounded: exactly as asked; unbounded: DEFAULT_SECONDS, then on until the first embedding
    bounded = args.seconds is not None or args.steps is not None
    seconds = args.seconds if args.seconds is not None else (MAX_SECONDS if args.steps else DEFAULT_SECONDS)

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
            if not embeddings:
                legend = f"(columns: {EMBEDDING_COLUMNS})"
                say("\n".join(textwrap.wrap(legend, 100, initial_indent=" " * 8, subsequent_indent=" " * 9)))
            embeddings.append(msg)
            say(stamp + format_embedding(msg))
        elif isinstance(msg, AgentEvent):
            events.append(msg)
            if msg.kind not in ("policy_iteration", "paused") or msg.reason == "no_start_states":
                say(stamp + format_event(msg))

    try:
        agent_cfg = bus_config_from_args(args, "agent")
    except BusError as e:
        print(f"sme demo: {e}", file=sys.stderr)
        return 2
    endpoint = (agent_cfg.listen or agent_cfg.connect or ("",))[0]
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
    length = f"{seconds:g} s" if bounded else f"{seconds:g} s (longer until its map holds, at most {MAX_SECONDS:g} s)"
    say(
        f"sme demo: agent on {endpoint}{' (mutual TLS + access control)' if args.secure else ''}, world {wid!r} ({world.kind}), {length}; Ctrl-C stops"
    )
    spec = world.spec()
    told_wait = False
    at_bound = False
    change_at: int | None = None
    change_t: float | None = None
    with agent_bus, world:
        daemon = AgentDaemon(agent_bus, seed=args.seed, on_output=on_output)
        daemon.start()
        dthread = threading.Thread(target=daemon.run, daemon=True)
        dthread.start()
        try:
            world_bus = Bus(BusConfig.for_role("world", endpoint, args.secure))
        except BusError as e:
            print(f"sme demo: {e}", file=sys.stderr)
            daemon.stop()
            daemon.close()
            return 2
        with world_bus:
            node = WorldNode(world, world_bus, wid, max_steps=args.steps)
            ctl = None
            if scripted is not None:
                from sensorimotor.tools.commands.perturb import refuse_locally

                ctl = Control(wid, scripted[0], scripted[1], 1, time.time())
                why = refuse_locally(node.body.spec(), ctl)
                if why is not None:
                    print(f"sme demo: --perturb: {why}", file=sys.stderr)
                    daemon.stop()
                    daemon.close()
                    return 2
            nthread = threading.Thread(target=node.run, daemon=True)
            nthread.start()
            next_tick = 5.0
            while not stop.is_set() and nthread.is_alive():
                stop.wait(0.1)
                if output_closed():
                    broken_pipe.set()
                    break
                el = time.monotonic() - t0
                if ctl is not None and change_at is None and scripted is not None and node.stats.steps >= scripted[2]:
                    change_at, change_t = node.stats.steps, time.time()
                    world_bus.put(keys.world_ctl(wid), codec.encode(ctl), codec.schema_name(Control))
                    say(
                        f"{el:6.1f}s [{wid}] >> body change {ctl.kind} sent at step {change_at:,} (the agent is not told)"
                    )
                waiting = ctl is not None and (
                    change_at is None
                    or not any(e.trigger == Trigger.RELEARNED and e.step >= change_at for e in embeddings)
                )
                if el >= seconds:
                    can_embed = not any(
                        e.reason == "no_start_states" for e in events
                    )  # the retina embeds fields, not starts
                    if bounded or not can_embed or (settled(embeddings, events) and not waiting):
                        break
                    if el >= MAX_SECONDS:
                        at_bound = True
                        break
                    if not told_wait:
                        told_wait = True
                        what = "its map to hold" if embeddings else "the first embedding"
                        say(
                            f"{el:6.1f}s [{wid}] going on until {what} "
                            f"(at most {MAX_SECONDS:g} s; --seconds S bounds the run)"
                        )
                if el >= next_tick:
                    next_tick += 5.0
                    say(
                        f"{el:6.1f}s [{wid}] {node.stats.steps} steps ({node.stats.steps / el:,.0f}/s), "
                        f"{node.stats.episodes} episodes"
                    )
            node.stop()
            nthread.join(timeout=5)
        final_truth = world.truth()  # (after a perturbation it may differ from the first)
        daemon.stop()
        dthread.join(timeout=5)
        daemon.close()
        status = daemon.status()
    if broken_pipe.is_set():
        raise BrokenPipeError("stdout closed by its reader")  # cli.main turns it into a quiet exit
    el = time.monotonic() - t0
    print("\nsummary")
    print(
        f"  world {wid} ({world.kind}): {node.stats.steps:,} lockstep steps in {el:.1f} s "
        f"({node.stats.steps / max(el, 1e-9):,.0f} steps/s), {node.stats.episodes:,} episodes"
    )
    for ln in status.links:
        rejected = ", ".join(f"{k} {v}" for k, v in sorted(ln.rejected.items())) or "none"
        print(f"  link: {ln.embedding_version} embedding versions, rejected inputs: {rejected}")
    result = verdict(embeddings, events, has_truth=final_truth is not None, n_starts=spec.n_starts, seconds=el)
    for line in result.lines:
        print(line)
    if scripted is not None:
        for line in change_summary(scripted[0], change_at, change_t, embeddings, events):
            print(line)
    if at_bound:
        pace = node.stats.steps / max(el, 1e-9)
        print(
            f"  stopped at the demo's {MAX_SECONDS:g} s bound before the map held: "
            f"{still_to_go(embeddings, pace)}; `--seconds S` runs longer"
        )
    if args.plot and embeddings:
        from sensorimotor.tools.plot import plot_embedding

        maps = [e for e in embeddings if e.trigger != "policy_map"]
        drawn = plot_embedding(maps[-1], final_truth, args.plot, history=maps)
        how = "coloured by true position" if drawn.coloured_by_truth else "no truth to colour by"
        print(f"  wrote {drawn.path}: embedding v{maps[-1].version}, {drawn.n_points} points, {how}")
    return 0 if result.embedded else 1
