"""Small helpers shared by the commands: logging, verbosity flags, exit codes, optional extras,
--param parsing, free ports, JSON views."""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import logging
import math
import re
import select
import socket
import sys
import textwrap
from types import ModuleType
from typing import Any

from sensorimotor.protocol.messages import AgentEvent, AgentStatus, Embedding
from sensorimotor.protocol.params import ParamError, assignments

# Exit statuses of every `sme` command (shown in each command's --help, honoured by cli.main).
EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130
EXIT_CODES_EPILOG = (
    "exit status: 0 ok; 1 runtime failure (the work could not be done, a missing optional dependency, "
    "or the reader closed the output pipe); 2 usage error (bad arguments or parameters, or the bus "
    "could not be opened: wrong endpoint or config, no `sme agent` to connect to); 130 interrupted "
    "(Ctrl-C) before the command finished. Commands that run until stopped (agent, world, record, view, "
    "demo, replay, watch without --count) finish cleanly on Ctrl-C or SIGTERM and exit with their usual status."
)


class HelpFormatter(argparse.HelpFormatter):
    """The one layout of every `sme` help page: usage, the description, the options (the zenoh
    flags in their own group), the exit statuses. Each paragraph of a description or epilog (blank
    lines between them) is wrapped to the terminal's width; argparse's default joins them all."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        paragraphs = [p for p in re.split(r"\n\s*\n", text.strip()) if p.strip()]
        return "\n\n".join(
            textwrap.fill(" ".join(p.split()), width, initial_indent=indent, subsequent_indent=indent)
            for p in paragraphs
        )


class UsageError(ValueError):
    """Bad command-line input found after parsing (e.g. a malformed --param): exit status 2."""


class MissingExtra(RuntimeError):
    """An optional dependency is not installed; the message names the extra that provides it."""


def require(module: str, extra: str = "experiments", package: str | None = None) -> ModuleType:
    """Import `module`, or raise MissingExtra telling which extra of the distribution installs it.

    Packages needed only by benchmarks and `sme reproduce` live in the `experiments` extra so the
    agent and worlds install without them; the commands that need them call this at import time."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        name = package or module.split(".")[0]
        raise MissingExtra(
            f"this command needs {name!r}, which is not installed ({e}); install the optional dependencies "
            f"with: pip install 'sensorimotor-embedding[{extra}]'"
        ) from None


def output_closed(stream: Any = None) -> bool:
    """True when the reader of `stream` (default stdout) has gone away, e.g. `sme watch | head -1`
    after head exits. Lets a printer loop that is idle stop at once instead of at its next write.
    Pipes report POLLERR on the write end once the read end is closed; files and terminals never do."""
    stream = sys.stdout if stream is None else stream
    try:
        fd = stream.fileno()
        poller = select.poll()
    except (AttributeError, OSError, ValueError):  # no real file descriptor, or no poll() here
        return False
    poller.register(fd, 0)  # POLLERR / POLLHUP are always reported
    return any(ev & (select.POLLERR | select.POLLHUP) for _, ev in poller.poll(0))


def setup_logging(verbosity: int = 0) -> None:
    """Log to stderr: -1 warnings and errors only, 0 info, 1 or more debug."""
    level = logging.WARNING if verbosity < 0 else logging.INFO if verbosity == 0 else logging.DEBUG
    logging.basicConfig(
        level=level, stream=sys.stderr, format="%(asctime)s %(name)s %(levelname)s %(message)s", datefmt="%H:%M:%S"
    )


def add_verbosity(parser: argparse.ArgumentParser) -> None:
    """Add -v/--verbose and -q/--quiet (once; a parser that has them already is left alone).

    Defaults are suppressed so that a nested subcommand does not reset a flag given to its parent
    (`sme bench -q loop`); `verbosity()` supplies the defaults."""
    if "-v" in parser._option_string_actions or "-q" in parser._option_string_actions:
        return
    parser.add_argument(
        "-v", "--verbose", action="count", default=argparse.SUPPRESS, help="more log output (repeat for more)"
    )
    parser.add_argument(
        "-q", "--quiet", action="store_true", default=argparse.SUPPRESS, help="only warnings and errors"
    )


def verbosity(args: argparse.Namespace) -> int:
    """-1 with --quiet, the number of -v given, else the command's default (`log_default`, 0)."""
    if getattr(args, "quiet", False):
        return -1
    v = getattr(args, "verbose", 0)
    return v if v else getattr(args, "log_default", 0)


def parse_params(items: list[str] | None) -> dict[str, str]:
    """`--param k=v` items as a dict; a UsageError (exit 2) for an item without '='."""
    try:
        return assignments(items)
    except ParamError as e:
        raise UsageError(str(e)) from None


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (for tests and benchmarks that start their own agent)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _num(x: float | None) -> float | None:
    return None if x is None or (isinstance(x, float) and math.isnan(x)) else round(float(x), 6)


def embedding_dict(e: Embedding, coordinates: bool = False) -> dict[str, Any]:
    """An Embedding as a JSON-ready dict (NaN becomes None), as `sme watch --json` prints it.

    Parameters
    ----------
    e : Embedding
        The message.
    coordinates : bool, default=False
        Include the ids and coordinates (large).

    Returns
    -------
    dict
    """
    d = {
        "type": "embedding",
        "agent": e.agent_id,
        "world": e.world_id,
        "version": e.version,
        "trigger": e.trigger,
        "n_points": int(e.coordinates.shape[0]),
        "dims": int(e.coordinates.shape[1]) if e.coordinates.ndim == 2 else 1,
        "eigenvalues": [round(v, 6) for v in e.eigenvalues],
        "procrustes_error": _num(e.procrustes_error),
        "step": e.step,
        "timestamp": e.timestamp,
        "metrics": {k: _num(v) for k, v in e.metrics.items()},
        "iteration": e.iteration,
        "drop_step": e.drop_step,
        "scores": None if e.scores is None else dataclasses.asdict(e.scores),
    }
    if coordinates:
        d["ids"] = list(e.ids)
        d["coordinates"] = e.coordinates.tolist()
    return d


def event_dict(e: AgentEvent) -> dict[str, Any]:
    """An AgentEvent as a JSON-ready dict (with its AttachConfig, if any)."""
    d = {
        "type": "event",
        "agent": e.agent_id,
        "world": e.world_id,
        "kind": e.kind,
        "reason": e.reason,
        "detail": e.detail,
        "step": e.step,
        "timestamp": e.timestamp,
        "values": {k: _num(v) for k, v in e.values.items()},
    }
    if e.config is not None:
        d["config"] = {
            "seed": e.config.seed,
            "detector": e.config.detector,
            "program": e.config.program,
            "program_params": dict(e.config.program_params),
        }
    return d


def describe_trigger(e: Embedding) -> str:
    """The trigger with its typed specifics, for people: `policy_iteration 3`, `relearned @1200`."""
    if e.drop_step is not None:
        return f"{e.trigger} @{e.drop_step}"
    return f"{e.trigger} {e.iteration}" if e.iteration else str(e.trigger)


def status_dict(s: AgentStatus) -> dict[str, Any]:
    """An AgentStatus as a JSON-ready dict, one entry per link."""
    return {
        "agent": s.agent_id,
        "uptime": round(s.uptime, 3),
        "counters": dict(s.counters),
        "links": [
            {
                "world": ln.world_id,
                "kind": ln.kind,
                "program": ln.program,
                "state": ln.state,
                "steps": ln.steps,
                "episodes": ln.episodes,
                "embedding_version": ln.embedding_version,
                "reward_mean": round(ln.reward_mean, 6),
                "rejected": dict(ln.rejected),
                "last_procrustes_error": _num(ln.last_procrustes_error),
                "detector_statistic": _num(ln.detector_statistic),
                "drops": ln.drops,
                "dropped": ln.dropped,
            }
            for ln in s.links
        ],
    }


def format_embedding(e: Embedding) -> str:
    """An Embedding as one line for people."""
    err = "n/a" if e.procrustes_error is None else f"{e.procrustes_error:.4f}"
    eig = " ".join(f"{v:.3g}" for v in e.eigenvalues[:4])
    sc = e.scores
    field = (
        ""
        if sc is None
        else f"T={sc.trustworthiness:.3f} C={sc.continuity:.3f} "
        f"Dm={sc.metric_dissimilarity:.3f} Dt={sc.topological_dissimilarity:.4f} "
    )
    goal = e.metrics.get("goal_reached_fraction")
    reached = "" if goal is None else f"goal={goal:.2f} "
    return (
        f"[{e.world_id}] embedding v{e.version:<3} {describe_trigger(e):<22} n={e.coordinates.shape[0]:<4} "
        f"procrustes={err:<7} {field}{reached}eig=[{eig}] step={e.step}"
    )


#: what the columns of `format_embedding` mean, for the demo's first lines and `sme watch --help`
EMBEDDING_COLUMNS = (
    "procrustes = error of the map against the world's truth (0 perfect, about 1 random); "
    "T, C = trustworthiness, continuity of its neighbourhoods (1 best); Dm, Dt = metric and topological "
    "dissimilarity (0 best); goal = fraction of the start states from which the greedy policy reached the goal; "
    "eig = the largest MDS eigenvalues; step = the world step it was made at"
)


def format_event(e: AgentEvent) -> str:
    """An AgentEvent as one line for people."""
    return f"[{e.world_id}] event {e.kind}: {e.detail}"


def print_json(d: dict[str, Any]) -> None:
    """Print `d` as one JSON line and flush (line-oriented consumers read it at once)."""
    print(json.dumps(d), flush=True)
