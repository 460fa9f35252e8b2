"""`sme bench world`: a world's steps/s in one process, rendering included, against the cost of a
single raw PyBullet TinyRenderer frame of the retina's size measured in the same process.

With `--bus` (the default for `arm`), also the same world served by `sme world` in its own process
and stepped over loopback Zenoh from a Gymnasium loop (`BusEnv`): one round trip per step. For
`arm`, also the simulator's own limits with the same URDF: raw `stepSimulation` with the joints
moved, and a raw TinyRenderer frame of the robot at the world's image size."""

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
    p.add_argument(
        "--bus",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="also measure the world served in its own process over loopback Zenoh (default: on for arm)",
    )
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

    from sensorimotor.worlds.bullet import direct_client

    c = direct_client()
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


def raw_urdf(params: dict[str, str], steps: int) -> list[dict]:
    """The simulator's own limits for the arm's URDF: physics steps with the moving joints set,
    and TinyRenderer frames of the robot at the world's image size (no marker, no caching)."""
    import pybullet as p

    from sensorimotor.worlds.arm import ArmWorld
    from sensorimotor.worlds.bullet import direct_client

    with make_world("arm", None, 0, params) as w:
        assert isinstance(w, ArmWorld)
        urdf, moving, size, view, proj = w.urdf, list(w.moving), w.params.image, w._view, w._proj
        poses = w.poses
    c = direct_client()
    rows = []
    try:
        body = c.loadURDF(urdf, useFixedBase=True)
        t0 = time.perf_counter()
        for k in range(steps):
            for j, a in zip(moving, poses[k % len(poses)], strict=True):
                c.resetJointState(body, j, float(a))
            c.stepSimulation()
        sec = time.perf_counter() - t0
        rows.append(_row(f"raw PyBullet stepSimulation ({urdf.rsplit('/', 1)[-1]})", steps, sec))
        frames = max(50, steps // 10)
        t0 = time.perf_counter()
        for k in range(frames):
            for j, a in zip(moving, poses[k % len(poses)], strict=True):
                c.resetJointState(body, j, float(a))
            c.getCameraImage(size, size, view, proj, renderer=p.ER_TINY_RENDERER, shadow=0)
        sec = time.perf_counter() - t0
        rows.append(_row(f"raw TinyRenderer {size}x{size} frame of it", frames, sec))
    finally:
        c.disconnect()
    return rows


def _row(name: str, steps: int, sec: float, **extra: object) -> dict:
    return {
        "bench": "world",
        "world": name,
        "steps": steps,
        "seconds": round(sec, 3),
        "steps_per_s": round(steps / sec, 1),
        **extra,
    }


def over_bus(name: str, steps: int, params: dict[str, str]) -> dict:
    """The world served by `sme world` in its own process, stepped over loopback Zenoh by `BusEnv`."""
    import subprocess
    import sys

    from sensorimotor.tools.common import free_port
    from sensorimotor.worlds.gym_bus import BusEnv

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    cmd = [sys.executable, "-m", "sensorimotor.tools.cli", "world", name, "--id", "benchw", "--external", "-q"]
    cmd += [a for k, v in params.items() for a in ("--param", f"{k}={v}")]
    cmd += ["--connect", endpoint, "--no-multicast-scouting"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        env = BusEnv("benchw", listen=endpoint, timeout=60)
        try:
            env.action_space.seed(0)
            env.reset(seed=0)
            t0 = time.perf_counter()
            for _ in range(steps):
                _, _, terminated, truncated, _ = env.step(env.action_space.sample())
                if terminated or truncated:
                    env.reset()
            sec = time.perf_counter() - t0
        finally:
            env.close()
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return _row(name, steps, sec, params=params, where="over the bus (loopback, its own process)")


def main_args(args: argparse.Namespace) -> int:
    from sensorimotor.tools.common import parse_params

    base = raw_frame()
    rows = [base]
    if args.world == "arm":
        rows += raw_urdf(parse_params(args.param) if args.param else {}, args.steps)
    variants = (
        [parse_params(args.param)] if args.param else ([{}, {"supersample": "1"}] if args.world == "retina" else [{}])
    )
    bus = args.world == "arm" if args.bus is None else args.bus
    for params in variants:
        r = measure(args.world, args.steps, params)
        r["where"] = "in-process"
        r["ratio_to_raw_frame"] = round(r["steps_per_s"] / base["steps_per_s"], 3)
        rows.append(r)
        if bus:
            b = over_bus(args.world, args.steps, params)
            b["ratio_to_raw_frame"] = round(b["steps_per_s"] / base["steps_per_s"], 3)
            b["ratio_to_in_process"] = round(b["steps_per_s"] / r["steps_per_s"], 3)
            rows.append(b)
    for r in rows:
        if args.json:
            print(json.dumps(r))
        else:
            extra = f"  ({r['ratio_to_raw_frame']}x a raw 128x128 frame)" if "ratio_to_raw_frame" in r else ""
            where = f"  {r['where']}" if "where" in r else ""
            print(f"{r['world']:<44} {str(r.get('params', '')):<22} {r['steps_per_s']:>9,.1f} steps/s{extra}{where}")
    return 0
