"""The generic program on a `gym:ENV_ID` world, in-process and seeded: the Procrustes error of each
embedding against the world's truth (the figure for `sme world gym:...` in the README).

    python -m sensorimotor.tools.experiments.gym_embed gym:MountainCar-v0 --steps 60000 \\
        --program-param max_trace=200
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol.params import ParamError, assignments
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.registry import make_world


def main(
    world: str,
    steps: int,
    seed: int = 0,
    params: Mapping[str, Any] | None = None,
    program_params: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Run the generic program on `world` for `steps` steps; the errors of its embeddings."""
    with make_world(world, None, seed, params) as w:
        program = make_program(w.spec(), seed, **dict(program_params or {}))
        t0 = time.perf_counter()
        run = run_inprocess(w, program, steps)
        seconds = time.perf_counter() - t0
    errors = [e for e in run.errors if e is not None]
    return {
        "world": world,
        "program": program.name,
        "steps": run.steps,
        "seconds": round(seconds, 1),
        "n_starts": w.spec().n_starts,
        "embeddings": len(run.embeddings),
        "errors": [round(e, 4) for e in errors],
        "final_error": round(errors[-1], 4) if errors else None,
        "best_error": round(min(errors), 4) if errors else None,
        "goal_reached_fraction": [round(e.metrics.get("goal_reached_fraction", 0.0), 3) for e in run.embeddings],
        "mean_trace_length": [round(e.metrics.get("mean_trace_length", 0.0), 1) for e in run.embeddings],
    }


def cli(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("world", help="a world kind or gym:ENV_ID")
    p.add_argument("--steps", type=int, default=20_000, help="steps to run (default 20000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--param", action="append", metavar="K=V", help="world parameter, repeatable")
    p.add_argument("--program-param", action="append", metavar="K=V", help="program parameter, repeatable")
    a = p.parse_args(argv)
    try:
        out = main(a.world, a.steps, a.seed, assignments(a.param), assignments(a.program_param, "--program-param"))
    except ParamError as e:
        print(f"gym_embed: {e}", file=sys.stderr)
        return 2
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(cli())
