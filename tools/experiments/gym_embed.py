"""The generic program on a `gym:ENV_ID` world, in-process and seeded: the Procrustes error of each
embedding against the world's truth (the figure for `sme world gym:...` in the README).

    python -m sensorimotor.tools.experiments.gym_embed gym:MountainCar-v0 --steps 60000 \\
        --program-param max_trace=200

`--gain` (box actions, a world whose first sensor is where the body is, e.g. panda-gym's hand
position): after the run, the accepted policy's traces are replayed from every start and the net
move commanded is compared with the displacement sensed: the least-squares gain between them (how
far a unit command along each axis moved the body), and the Procrustes errors of the net moves
against the displacements and of the displacements against the truth - what a trace embedding in
units of the commands can reach on that body - and `step_gain`: how faithfully a single step
follows its command (mean and spread, per action value, of each step's move over the move the
gain predicts; a spread well above 0 is a body whose response depends on where it is).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import procrustes_error
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
    gain: bool = False,
) -> dict[str, Any]:
    """Run the generic program on `world` for `steps` steps; the errors of its embeddings (and
    with `gain`, `net_gain` of its accepted traces)."""
    with make_world(world, None, seed, params) as w:
        program = make_program(w.spec(), seed, **dict(program_params or {}))
        t0 = time.perf_counter()
        run = run_inprocess(w, program, steps)
        seconds = time.perf_counter() - t0
        extra = {"gain": net_gain(w, program)} if gain else {}
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
        **extra,
    }


def net_gain(world: Any, program: Any) -> dict[str, Any]:
    """Replay the accepted policy's trace from every start of `world` (deterministic worlds) and
    compare each trace's net commanded move with the displacement of the world's first sensor."""
    traces = program._accepted_traces
    truth = world.truth()
    if traces is None or truth is None or program.discrete:
        return {"error": "needs box actions, start states with truth, and an accepted policy"}
    name = world.spec().sensors[0].name
    net, disp, sent, moved = [], [], [], []
    for k, t in enumerate(traces):
        x0 = np.asarray(world.reset(start=k).tensors[name], dtype=np.float64).reshape(-1)
        x = x0
        for a in t:
            before = x
            x = np.asarray(world.step(program.actions[a]).tensors[name], dtype=np.float64).reshape(-1)
            sent.append(program.actions[a])
            moved.append(x - before)
        net.append(
            program.actions[np.asarray(t, dtype=np.int64)].sum(axis=0) if t else np.zeros(program.actions.shape[1])
        )
        disp.append(x - x0)
    N, D = np.array(net), np.array(disp)
    G = np.linalg.lstsq(np.c_[N, np.ones(len(N))], D, rcond=None)[0][:-1]
    pos = np.asarray(truth.tensors["positions"], dtype=np.float64)
    return {
        "sensor": name,
        "gain": np.round(G, 4).tolist(),
        "step_gain": step_gain(np.array(sent), np.array(moved), G),
        "procrustes_net_vs_displacement": round(procrustes_error(D, N), 4),
        "procrustes_truth_vs_displacement": round(procrustes_error(pos, D), 4),
        "procrustes_truth_vs_net": round(procrustes_error(pos, N), 4),
    }


def step_gain(sent: np.ndarray, moved: np.ndarray, gain: np.ndarray) -> dict[str, list[float | None]]:
    """How faithfully one step follows its command, per action value: the step's move along the
    value's axis of `gain`, over the move the whole-trace gain predicts (1 on a body whose steps
    all move alike), its mean and spread over the steps that command it (None: never commanded)."""
    if sent.size == 0 or moved.ndim != 2 or gain.shape != (sent.shape[1], moved.shape[1]):
        return {"mean": [], "sd": []}
    mean: list[float | None] = []
    sd: list[float | None] = []
    for i in range(sent.shape[1]):
        norm = max(float(np.linalg.norm(gain[i])), 1e-12)
        on = sent[:, i] != 0
        r = (moved[on] @ (gain[i] / norm)) / (sent[on, i] * norm)
        mean.append(round(float(r.mean()), 3) if r.size else None)
        sd.append(round(float(r.std()), 3) if r.size else None)
    return {"mean": mean, "sd": sd}


def cli(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])  # the whole first paragraph
    p.add_argument("world", help="a world kind or gym:ENV_ID")
    p.add_argument("--steps", type=int, default=20_000, help="steps to run (default 20000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--param", action="append", metavar="K=V", help="world parameter, repeatable")
    p.add_argument("--program-param", action="append", metavar="K=V", help="program parameter, repeatable")
    p.add_argument("--gain", action="store_true", help="replay the accepted traces: net move commanded vs sensed")
    a = p.parse_args(argv)
    try:
        out = main(
            a.world,
            a.steps,
            a.seed,
            assignments(a.param),
            assignments(a.program_param, "--program-param"),
            gain=a.gain,
        )
    except ParamError as e:
        print(f"gym_embed: {e}", file=sys.stderr)
        return 2
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(cli())
