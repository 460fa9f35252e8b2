"""`sme bench world`: a world's steps/s in one process, rendering included, against the cost of a
single raw PyBullet TinyRenderer frame of the retina's size measured in the same process."""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from sensorimotor.worlds.registry import WORLDS, make_world


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("world", help="world steps/s per process (rendering included)", description=__doc__)
    p.add_argument("--world", default="retina", help="world to measure: " + ", ".join(sorted(WORLDS)))
    p.add_argument("--steps", type=int, default=2000, help="steps per measurement")
    p.add_argument("--param", action="append", metavar="K=V", help="world parameter (e.g. supersample=1)")
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.set_defaults(func=main_args)


def measure(name: str, steps: int, params: dict[str, str]) -> dict:
    with make_world(name, None, 0, params) as w:
        spec = w.spec()
        rng = np.random.default_rng(0)
        res = w.reset()
        t0 = time.perf_counter()
        for _ in range(steps):
            if res.done:
                res = w.reset()
            elif spec.action_space.discrete:
                res = w.step(np.array([rng.integers(spec.action_space.n)]))
            else:
                res = w.step(rng.uniform(spec.action_space.low, spec.action_space.high))
        sec = time.perf_counter() - t0
    return {
        "bench": "world",
        "world": name,
        "params": params,
        "steps": steps,
        "seconds": round(sec, 3),
        "steps_per_s": round(steps / sec, 1),
    }


def raw_frame(px: int = 128, frames: int = 200) -> dict:
    import pybullet as p
    from pybullet_utils.bullet_client import BulletClient

    c = BulletClient(connection_mode=p.DIRECT)
    try:
        vis = c.createVisualShape(p.GEOM_BOX, halfExtents=[0.01, 7, 7], rgbaColor=[0, 0, 0, 1])
        c.createMultiBody(0, baseVisualShapeIndex=vis, basePosition=[5, 0, 0])
        view = c.computeViewMatrix([0, 0, 0], [5, 0, 0], [0, 0, 1])
        proj = c.computeProjectionMatrixFOV(30, 1, 0.1, 10)
        t0 = time.perf_counter()
        for _ in range(frames):
            c.getCameraImage(px, px, view, proj, renderer=p.ER_TINY_RENDERER, shadow=0)
        sec = time.perf_counter() - t0
    finally:
        c.disconnect()
    return {
        "bench": "world",
        "world": f"raw TinyRenderer {px}x{px} frame",
        "steps": frames,
        "seconds": round(sec, 3),
        "steps_per_s": round(frames / sec, 1),
    }


def main_args(args: argparse.Namespace) -> int:
    from sensorimotor.tools.common import parse_params

    base = raw_frame()
    rows = [base]
    variants = (
        [parse_params(args.param)] if args.param else ([{}, {"supersample": "1"}] if args.world == "retina" else [{}])
    )
    for params in variants:
        r = measure(args.world, args.steps, params)
        r["ratio_to_raw_frame"] = round(r["steps_per_s"] / base["steps_per_s"], 3)
        rows.append(r)
    for r in rows:
        if args.json:
            print(json.dumps(r))
        else:
            extra = f"  ({r['ratio_to_raw_frame']}x a raw 128x128 frame)" if "ratio_to_raw_frame" in r else ""
            print(f"{r['world']:<36} {str(r.get('params', '')):<22} {r['steps_per_s']:>9,.1f} steps/s{extra}")
    return 0
