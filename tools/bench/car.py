"""`sme bench car`: what a visual mountain-car run costs, and where a car step's time goes.

The same seeded run (`tools.experiments.mountaincar.visual`), in this process, twice: verging at
every car step (`recall_check=0`, the program before issue 38) and as the program ships (a car
step whose parallel-eye view was read before reuses that reading). Both must give the same
learning curve; the ratio of their times (wall and this process's CPU) is the speed-up. With
`--profile`, each run is also profiled (cProfile) and its time split into rendering, the vergence
policy, the embedding lookup, the learner (Sarsa and the velocity filter) and the rest (the
world's and the link's step loop).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import time
from typing import Any

#: where a car step's time goes: category -> the functions whose cumulative time it is (file, name)
CATEGORIES: dict[str, tuple[tuple[str, str], ...]] = {
    "rendering (PyBullet; the world's perceptual-goal search included)": (("worlds/vergence.py", "render"),),
    "vergence policy": (("agent/programs/vergence.py", "foveal_difference"), ("agent/learners/lspi.py", "greedy")),
    "embedding lookup": (
        ("agent/programs/vergence_reading.py", "position"),
        ("agent/programs/vergence_reading.py", "recalled"),
    ),
    "learner (Sarsa, velocity filter)": (
        ("agent/learners/sarsa_lambda.py", "act"),
        ("agent/learners/sarsa_lambda.py", "greedy"),
        ("agent/learners/sarsa_lambda.py", "learn_one"),
        ("agent/programs/mountaincar.py", "_car_state"),
    ),
}


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "car",
        help="visual mountain car: verging every car step vs recalling readings, same run, same process",
        description="Run the same seeded visual mountain-car run with recall off and on; report the times, "
        "their ratio, the world steps, and (--profile) where a car step's time goes.",
    )
    p.add_argument("--train", type=int, default=20_000, help="training car steps (default 20000)")
    p.add_argument("--every", type=int, default=10_000, help="training car steps between evaluations (default 10000)")
    p.add_argument("--n-eval", type=int, default=20, help="evaluation states (default 20)")
    p.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    p.add_argument("--profile", action="store_true", help="also profile each run and split its time by category")
    p.add_argument("--json", action="store_true", help="one JSON object per run")
    p.set_defaults(func=main_args)


def _split(prof: cProfile.Profile) -> dict[str, float]:
    """Seconds per category (cumulative time of its functions) and the total."""
    st = pstats.Stats(prof)
    out = dict.fromkeys(CATEGORIES, 0.0)
    total = 0.0
    for (path, _line, name), (_cc, _nc, _tt, ct, _callers) in st.stats.items():  # type: ignore[attr-defined]
        if name == "run_inprocess":
            total = max(total, ct)
        for cat, funcs in CATEGORIES.items():
            if any(path.endswith(f) and name == n for f, n in funcs):
                out[cat] += ct
    out["rest (world step, link, loop)"] = total - sum(out.values())
    out["total"] = total
    return out


def run(recall: bool, train: int, every: int, n_eval: int, seed: int, profile: bool) -> dict[str, Any]:
    """One run; its times, counts and curve (and the profile's split when asked)."""
    from sensorimotor.agent.programs.mountaincar import MountainCarProgramParams
    from sensorimotor.tools.experiments.mountaincar import visual

    prof = cProfile.Profile() if profile else None
    t, c = time.perf_counter(), time.process_time()
    if prof:
        prof.enable()
    r = visual(seed, train, every, n_eval, recall_check=MountainCarProgramParams().recall_check if recall else 0)
    if prof:
        prof.disable()
    row: dict[str, Any] = {
        "mode": "recall (as shipped)" if recall else "verge every car step",
        "wall_s": time.perf_counter() - t,
        "cpu_s": time.process_time() - c,
        "world_steps": r.world_steps,
        "curve": r.curve,
    }
    if prof:
        row["profile_s"] = _split(prof)
    return row


def main_args(args: argparse.Namespace) -> int:
    rows = [run(recall, args.train, args.every, args.n_eval, args.seed, args.profile) for recall in (False, True)]
    for r in rows:
        if args.json:
            print(json.dumps(r))
        else:
            print(
                f"{r['mode']}: {r['wall_s']:.1f} s wall, {r['cpu_s']:.1f} s CPU, {r['world_steps']} world steps, "
                f"curve {r['curve']}"
            )
            for k, v in r.get("profile_s", {}).items():
                print(f"    {k}: {v:.1f} s")
    same = rows[0]["curve"] == rows[1]["curve"]
    print(
        f"speed-up (CPU): {rows[0]['cpu_s'] / rows[1]['cpu_s']:.1f}x, (wall) {rows[0]['wall_s'] / rows[1]['wall_s']:.1f}x; "
        f"same learning curve: {same}"
    )
    return 0 if same else 1
