"""Is a world repeatable to the bit? From every `every`-th start the same seeded random moves are
sent twice, with episodes from other starts between the two runs; the starts whose observations
differ, and the first step at which they did.

    python -m sensorimotor.tools.experiments.repeatable gym:panda_gym:PandaReach-v3

Why it matters: the generic program calls a world stochastic when one observation and action led
to different observations back and forth; a world that differs only now and then (a simulator's
contacts) reads as deterministic, and there a start's goal can be missed once by a hair. The
program runs such a start once more before the miss counts (`retried_traces`, docs/zoo.md).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from sensorimotor.protocol.params import ParamError, assignments
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.registry import make_world


@dataclass(frozen=True)
class Repeat:
    """One start, run twice with the same moves: the steps of each run, the largest difference of
    any observation value between them, and the first step at which they differed (None: identical)."""

    start: int
    steps: tuple[int, int]
    max_difference: float
    first_step: int | None


def _values(r: StepResult) -> np.ndarray:
    return np.concatenate([np.asarray(v, dtype=np.float64).ravel() for v in r.tensors.values()])


def _moves(world: World, n: int, rng: np.random.Generator) -> np.ndarray:
    """`n` random actions: a discrete action's index, or each box dimension at its low, middle or high."""
    a = world.spec().action_space
    if a.discrete:
        return rng.integers(a.n, size=(n, 1)).astype(np.float64)
    lo, hi = np.asarray(a.low, dtype=np.float64), np.asarray(a.high, dtype=np.float64)
    return lo + (hi - lo) / 2 * rng.integers(3, size=(n, len(lo)))


def _episode(world: World, start: int, moves: np.ndarray) -> np.ndarray:
    r = world.reset(start=start)
    seen = [_values(r)]
    for a in moves:
        if r.done:
            break
        r = world.step(a)
        seen.append(_values(r))
    return np.array(seen)


def check(world: World, seed: int = 0, moves: int = 40, every: int = 1, between: int = 2) -> list[Repeat]:
    """Run every `every`-th start twice with the same `moves` random actions (seeded), `between`
    episodes from other starts in between; one `Repeat` per start checked."""
    if moves < 1 or every < 1 or between < 0:
        raise ValueError(f"moves >= 1, every >= 1 and between >= 0 (got {moves}, {every}, {between})")
    rng = np.random.default_rng(seed)
    n = world.spec().n_starts
    if n < 1:
        raise ValueError(f"{world.spec().kind}: declares no start states to repeat")
    plan = _moves(world, moves, rng)
    out = []
    for s in range(0, n, every):
        first = _episode(world, s, plan)
        for _ in range(between):
            _episode(world, int(rng.integers(n)), plan)
        second = _episode(world, s, plan)
        m = min(len(first), len(second))
        d = np.max(np.abs(first[:m] - second[:m]), axis=1)
        differ = np.flatnonzero(d > 0)
        at = int(differ[0]) if differ.size else (m if len(first) != len(second) else None)
        out.append(Repeat(s, (len(first) - 1, len(second) - 1), float(d.max()), at))
    return out


def main(
    world: str, seed: int = 0, params: Mapping[str, Any] | None = None, moves: int = 40, every: int = 1
) -> dict[str, Any]:
    """`check` on a world made by name; the per-start rows and how many starts differed."""
    with make_world(world, None, seed, params) as w:
        rows = check(w, seed, moves, every)
    differ = [r for r in rows if r.first_step is not None]
    return {
        "world": world,
        "starts_checked": len(rows),
        "starts_not_repeated": len(differ),
        "first_steps": [r.first_step for r in differ],
        "max_difference": max((r.max_difference for r in rows), default=0.0),
        "rows": [asdict(r) for r in rows],
    }


def cli(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])  # the whole first paragraph
    p.add_argument("world", help="a world kind or gym:ENV_ID")
    p.add_argument("--seed", type=int, default=0, help="seeds the world and the moves (default 0)")
    p.add_argument("--param", action="append", metavar="K=V", help="world parameter, repeatable")
    p.add_argument("--moves", type=int, default=40, help="random moves per episode (default 40)")
    p.add_argument("--every", type=int, default=1, help="check every N-th start (default 1: all)")
    p.add_argument("--json", action="store_true", help="one JSON object instead of lines")
    a = p.parse_args(argv)
    try:
        out = main(a.world, a.seed, assignments(a.param), a.moves, a.every)
    except (ParamError, ValueError) as e:
        print(f"repeatable: {e}", file=sys.stderr)
        return 2
    if a.json:
        print(json.dumps(out))
        return 0
    for r in out["rows"]:
        at = "identical" if r["first_step"] is None else f"first differs at step {r['first_step']}"
        print(
            f"start {r['start']:4d}: {r['steps'][0]} and {r['steps'][1]} steps, {at}, max |diff| {r['max_difference']:.3g}"
        )
    print(
        f"{out['world']}: {out['starts_not_repeated']} of {out['starts_checked']} starts not repeated to the bit"
        f" (largest difference {out['max_difference']:.3g})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(cli())
