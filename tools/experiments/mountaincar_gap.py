"""Where the visual mountain car's driver loses to the true-state agent, state by state (ch. 8).

Both agents are trained on the same seed and evaluated on the same fixed random states; the gap of
the mean steps to the goal at the end of training (the last three evaluations, as `sme reproduce
mountaincar` scores it) is split over three kinds of evaluation state:

- holds: states the embedding agent took `hold` car steps or more from in one of those evaluations
  (it stayed in the valley, mostly a car started almost at rest);
- starts at speed: the other states whose start velocity is at least `fast` (the agent reads its
  position only, so its velocity is unknown at an episode's first reading);
- the rest.

The three parts add up to the gap. Run: ``python -m sensorimotor.tools.experiments.mountaincar_gap
[--seeds 0-5] [--train 100000] [--workers 2] [--out FILE.json]``; it prints the table and, with
``--out``, writes the command, the table and every state's steps.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from sensorimotor.tools.experiments.shared import pool_map


@dataclass(frozen=True)
class Gap:
    """One seed's gap (embedding agent minus true-state agent, mean steps to the goal) and its parts."""

    seed: int
    embedding: float
    true_state: float
    holds: float
    hold_states: int
    fast_starts: float
    fast_states: int
    rest: float

    @property
    def gap(self) -> float:
        return self.embedding - self.true_state


def split_gap(
    seed: int,
    embedding: np.ndarray,
    true_state: np.ndarray,
    states: np.ndarray,
    hold: int = 400,
    fast: float = 0.03,
) -> Gap:
    """Split the gap of the mean steps between `embedding` and `true_state` (each evaluations x
    states, the same states in the same order) over holds, starts at speed and the rest."""
    e, t = np.asarray(embedding, dtype=np.float64), np.asarray(true_state, dtype=np.float64)
    if e.ndim != 2 or e.shape[1] != t.shape[1] or e.shape[1] != len(states):
        raise ValueError(f"need evaluations x states for both agents over {len(states)} states")
    per_state = e.mean(axis=0) - t.mean(axis=0)
    held = (e >= hold).any(axis=0)
    at_speed = ~held & (np.abs(np.asarray(states)[:, 1]) >= fast)
    n = len(states)
    return Gap(
        seed,
        float(e.mean()),
        float(t.mean()),
        float(per_state[held].sum() / n),
        int(held.sum()),
        float(per_state[at_speed].sum() / n),
        int(at_speed.sum()),
        float(per_state[~held & ~at_speed].sum() / n),
    )


def job(kind: str, seed: int, train: int, every: int, n_eval: int) -> list[list[int]]:
    """Per-state car steps of every evaluation of one seeded run of `kind` (visual or true)."""
    from sensorimotor.tools.experiments import mountaincar as mc

    r = mc.visual(seed, train, every, n_eval) if kind == "visual" else mc.true_state(seed, train, every, n_eval)
    return r.per_state


def table(gaps: list[Gap]) -> str:
    """Markdown: per seed and the mean, the two agents, the gap and its three parts."""
    lines = [
        "| seed | embedding agent | true-state agent | gap | holds (states) | starts at speed (states) | the rest |",
        "|---|---|---|---|---|---|---|",
    ]
    for g in gaps:
        lines.append(
            f"| {g.seed} | {g.embedding:.1f} | {g.true_state:.1f} | {g.gap:.1f} | {g.holds:.1f} ({g.hold_states}) "
            f"| {g.fast_starts:.1f} ({g.fast_states}) | {g.rest:.1f} |"
        )

    def m(f: str) -> float:
        return float(np.mean([getattr(g, f) if f != "gap" else g.gap for g in gaps]))

    lines.append(
        f"| mean | {m('embedding'):.1f} | {m('true_state'):.1f} | {m('gap'):.1f} | {m('holds'):.1f} "
        f"| {m('fast_starts'):.1f} | {m('rest'):.1f} |"
    )
    return "\n".join(lines)


def main(
    seeds: list[int], train: int = 100_000, every: int = 10_000, n_eval: int = 100, workers: int = 2, out: str = ""
) -> list[Gap]:
    """Run both agents on every seed, print the split of the gap and (with `out`) write it as JSON."""
    from sensorimotor.worlds.mountaincar_dynamics import evaluation_states

    if train < every:
        raise ValueError(f"--train ({train}) must be at least one evaluation interval ({every})")
    t0 = time.time()
    jobs = [(k, s, train, every, n_eval) for s in seeds for k in ("visual", "true")]
    print(f"mountaincar gap: {len(seeds)} seeds x 2 agents, {train} training car steps each ...", flush=True)
    res = pool_map(job, jobs, workers)
    states = evaluation_states(n_eval)
    gaps = [split_gap(s, np.array(res[2 * i][-3:]), np.array(res[2 * i + 1][-3:]), states) for i, s in enumerate(seeds)]
    md = table(gaps)
    print(md)
    print(f"({time.time() - t0:.0f} s)")
    if out:
        with open(out, "w") as f:
            json.dump(
                {
                    "command": " ".join(["python -m sensorimotor.tools.experiments.mountaincar_gap", *sys.argv[1:]]),
                    "table": md,
                    "gaps": [asdict(g) for g in gaps],
                    "states": states.tolist(),
                    "per_state": {f"{k} {s}": res[i] for i, (k, s, *_rest) in enumerate(jobs)},
                },
                f,
            )
    return gaps


def _seeds(text: str) -> list[int]:
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


def cli(argv: list[str] | None = None) -> Any:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    ap.add_argument("--seeds", type=_seeds, default=_seeds("0-5"), help="seeds, as 0-5 or 0,3,7 (default 0-5)")
    ap.add_argument("--train", type=int, default=100_000, help="training car steps per run (default 100000)")
    ap.add_argument("--every", type=int, default=10_000, help="training car steps between evaluations")
    ap.add_argument("--n-eval", type=int, default=100, help="evaluation states (default 100, as the chapter)")
    ap.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    ap.add_argument("--out", default="", help="write the command, the table and every state's steps here (JSON)")
    a = ap.parse_args(argv)
    return main(a.seeds, a.train, a.every, a.n_eval, a.workers, a.out)


if __name__ == "__main__":
    cli()
