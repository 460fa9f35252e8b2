"""Small helpers shared by the commands: logging, --param parsing, free ports, JSON views."""

from __future__ import annotations

import argparse
import json
import logging
import math
import socket
import sys
from typing import Any

from sensorimotor.protocol.messages import AgentEvent, AgentStatus, Embedding


def setup_logging(verbosity: int = 0) -> None:
    level = logging.WARNING if verbosity < 0 else logging.INFO if verbosity == 0 else logging.DEBUG
    logging.basicConfig(level=level, stream=sys.stderr, format="%(asctime)s %(name)s %(levelname)s %(message)s",
                        datefmt="%H:%M:%S")


def add_verbosity(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    parser.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")


def verbosity(args: argparse.Namespace) -> int:
    return -1 if getattr(args, "quiet", False) else getattr(args, "verbose", 0)


def parse_params(items: list[str] | None) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items or []:
        if "=" not in item:
            raise SystemExit(f"--param expects key=value, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _num(x: float | None) -> float | None:
    return None if x is None or (isinstance(x, float) and math.isnan(x)) else round(float(x), 6)


def embedding_dict(e: Embedding, coordinates: bool = False) -> dict[str, Any]:
    d = {"type": "embedding", "agent": e.agent_id, "world": e.world_id, "version": e.version,
         "trigger": e.trigger, "n_points": int(e.coordinates.shape[0]),
         "dims": int(e.coordinates.shape[1]) if e.coordinates.ndim == 2 else 1,
         "eigenvalues": [round(v, 6) for v in e.eigenvalues], "procrustes_error": _num(e.procrustes_error),
         "step": e.step, "timestamp": e.timestamp, "metrics": {k: _num(v) for k, v in e.metrics.items()},
         "iteration": e.iteration, "drop_step": e.drop_step}
    if coordinates:
        d["ids"] = list(e.ids)
        d["coordinates"] = e.coordinates.tolist()
    return d


def event_dict(e: AgentEvent) -> dict[str, Any]:
    d = {"type": "event", "agent": e.agent_id, "world": e.world_id, "kind": e.kind, "reason": e.reason,
         "detail": e.detail, "step": e.step, "timestamp": e.timestamp,
         "values": {k: _num(v) for k, v in e.values.items()}}
    if e.config is not None:
        d["config"] = {"seed": e.config.seed, "detector": e.config.detector, "program": e.config.program,
                       "program_params": dict(e.config.program_params)}
    return d


def describe_trigger(e: Embedding) -> str:
    """The trigger with its typed specifics, for people: `policy_iteration 3`, `relearned @1200`."""
    if e.drop_step is not None:
        return f"{e.trigger} @{e.drop_step}"
    return f"{e.trigger} {e.iteration}" if e.iteration else str(e.trigger)


def status_dict(s: AgentStatus) -> dict[str, Any]:
    return {"agent": s.agent_id, "uptime": round(s.uptime, 3), "counters": dict(s.counters),
            "links": [{"world": ln.world_id, "kind": ln.kind, "program": ln.program, "state": ln.state,
                       "steps": ln.steps, "episodes": ln.episodes, "embedding_version": ln.embedding_version,
                       "reward_mean": round(ln.reward_mean, 6), "rejected": dict(ln.rejected),
                       "last_procrustes_error": _num(ln.last_procrustes_error),
                       "detector_statistic": _num(ln.detector_statistic), "drops": ln.drops} for ln in s.links]}


def format_embedding(e: Embedding) -> str:
    err = "n/a" if e.procrustes_error is None else f"{e.procrustes_error:.4f}"
    eig = " ".join(f"{v:.3g}" for v in e.eigenvalues[:4])
    return (f"[{e.world_id}] embedding v{e.version:<3} {describe_trigger(e):<22} n={e.coordinates.shape[0]:<4} "
            f"procrustes={err:<7} eig=[{eig}] step={e.step}")


def format_event(e: AgentEvent) -> str:
    return f"[{e.world_id}] event {e.kind}: {e.detail}"


def print_json(d: dict[str, Any]) -> None:
    print(json.dumps(d), flush=True)
