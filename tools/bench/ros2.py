"""`sme bench ros2`: a ROS 2 robot over rmw_zenoh, with the stand-in arm (worlds/ros2/standin.py).

``throughput``: the stand-in at its rate, followed by the ROS 2 world stepped as fast as it is
answered: steps, commands sent, commands the stand-in never heard or refused (per 1,000 ticks),
observations taken without fresh samples; then the stand-in's camera at 640x480 rgb8 30 Hz and the
CPU that costs the world's process (cores: CPU seconds per wall second).

``learn``: the same seed learned by a stock `sme agent` through `sme world arm` and through the
stand-in + `sme world ros2`: the step of the first embedding within 0.1 (Procrustes, joint angles),
its error, then a body change (`sme perturb`) and the steps to its detection and relearned map.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from sensorimotor.tools.common import free_port

ROBOT_FILE = Path(__file__).resolve().parents[2] / "tests" / "data" / "standin_arm_ros2.toml"


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ros2", help="ROS 2 over rmw_zenoh with the stand-in arm: throughput, camera CPU, learning")
    p.add_argument(
        "what",
        nargs="?",
        default="throughput",
        choices=("throughput", "learn"),
        help="which figures (default throughput)",
    )
    p.add_argument("--ticks", type=int, default=2000, help="throughput: world steps (default 2000)")
    p.add_argument("--rate", type=float, default=50.0, help="throughput: the stand-in's rate, Hz (default 50)")
    p.add_argument("--camera-seconds", type=float, default=15.0, help="throughput: seconds of 640x480 camera")
    p.add_argument("--seed", type=int, default=0, help="learn: the seed of both runs")
    p.add_argument("--timeout", type=float, default=600.0, help="learn: seconds per phase")
    p.add_argument(
        "--change", choices=sorted(CHANGES), default="reverse", help="learn: the body change made once learned"
    )
    p.add_argument("--learn-rate", type=float, default=50.0, help="learn: the stand-in's rate, Hz (default 50)")
    p.add_argument("--change-at", type=int, default=3000, help="learn: make the change once this many steps are taken")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures as JSON")
    p.set_defaults(func=main_args)


def _py(*args: str, stdout: Any = subprocess.DEVNULL) -> subprocess.Popen:
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, *args], stdout=stdout, stderr=subprocess.DEVNULL, text=True, env=env)


def _stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def robot_file(folder: str, rate: float, connect: str) -> str:
    """The stand-in's robot file with another rate and endpoint."""
    text = ROBOT_FILE.read_text()
    text = text.replace('connect = "tcp/127.0.0.1:7447"', f'connect = "{connect}"').replace(
        "rate = 50.0", f"rate = {rate}"
    )
    path = os.path.join(folder, f"robot-{rate:g}.toml")
    Path(path).write_text(text)
    return path


def _standin(ep: str, stats: str, *extra: str) -> subprocess.Popen:
    return _py("-m", "sensorimotor.worlds.ros2.standin", "--listen", ep, "-q", "--stats-json", stats, *extra)


def throughput(ticks: int, rate: float, camera_seconds: float) -> dict[str, Any]:
    """Command and camera figures (see the module's docstring)."""
    from sensorimotor.worlds.ros2.world import Ros2World

    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        ep = f"tcp/127.0.0.1:{free_port()}"
        stats = os.path.join(tmp, "standin.json")
        proc = _standin(ep, stats, "--rate", str(rate))
        try:
            w = Ros2World("ros2", 0, robot=robot_file(tmp, rate, ep), connect=ep)
            rng = np.random.default_rng(0)
            w.reset(start=24)
            t0, steps = time.monotonic(), 0
            while steps < ticks:
                r = w.step(np.array([rng.integers(4)]))
                steps += 1
                if r.done:
                    w.reset(start=int(rng.integers(49)))
            wall = time.monotonic() - t0
            sent, stale = w.commands, w.stale
            w.close()
        finally:
            _stop(proc)
        s = json.loads(Path(stats).read_text())
        missed = sent - s["commands"]  # never heard (the sequence gaps are among these)
        out["commands"] = {
            "rate_hz": rate,
            "steps": steps,
            "steps_per_s": round(steps / wall, 1),
            "standin_ticks": s["ticks"],
            "standin_late_ticks": s["late_ticks"],
            "commands_sent": sent,
            "commands_heard": s["commands"],
            "sequence_gaps": s["dropped"],
            "commands_later_than_one_period": s["late_commands"],
            "command_latency_ms_p50": s["command_latency_ms_p50"],
            "command_latency_ms_p99": s["command_latency_ms_p99"],
            "never_heard_per_1000_ticks": round(1000 * missed / max(1, s["ticks"]), 3),
            "refused_out_of_range": s["refused"],
            "observations_without_fresh_samples": stale,
        }
        ep = f"tcp/127.0.0.1:{free_port()}"
        stats = os.path.join(tmp, "camera.json")
        proc = _standin(ep, stats, "--rate", "30", "--camera", "640x480", "--encoding", "rgb8")
        try:
            w = Ros2World("ros2", 0, robot=robot_file(tmp, 30.0, ep), connect=ep)
            shape = w.spec().sensors[0].shape
            w.reset(start=24)
            rng = np.random.default_rng(1)
            t0, c0, steps = time.monotonic(), time.process_time(), 0
            while time.monotonic() - t0 < camera_seconds:
                r = w.step(np.array([rng.integers(4)]))
                steps += 1
                if r.done:
                    w.reset(start=int(rng.integers(49)))
            wall, cpu = time.monotonic() - t0, time.process_time() - c0
            w.close()
        finally:
            _stop(proc)
        s = json.loads(Path(stats).read_text())
        out["camera"] = {
            "image": f"{shape[1]}x{shape[0]} rgb8",
            "rate_hz": 30.0,
            "seconds": round(wall, 1),
            "steps": steps,
            "world_process_cores": round(cpu / wall, 3),
            "standin_cores": round(s["cpu_seconds"] / max(1e-9, s["seconds"]), 3),
        }
    return out


def _watch(ep: str, seconds: float) -> tuple[subprocess.Popen, list[dict]]:
    rows: list[dict] = []
    p = _py(
        "-m",
        "sensorimotor.tools.cli",
        "watch",
        "--json",
        "--timeout",
        str(int(seconds)),
        "--connect",
        ep,
        stdout=subprocess.PIPE,
    )

    def read() -> None:
        assert p.stdout is not None
        for line in p.stdout:
            try:
                rows.append(json.loads(line))
            except ValueError:
                pass

    threading.Thread(target=read, daemon=True).start()
    return p, rows


def _until(pred: Any, timeout: float) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(0.5)
    return None


#: the body change made once learned: native (`sme perturb` on the arm world), through `sme world ros2`
#: (the generic kinds of our node), and on the stand-in robot itself (its ``body_change`` topic)
CHANGES: dict[str, tuple[list[str], list[str] | None, str | None]] = {
    "reverse": (["reverse", "--param", "joint=lbr_iiwa_joint_4"], ["reverse", "--param", "pairs=2:3"], None),
    "lesion": (
        ["lesion", "--param", "joint=lbr_iiwa_joint_2", "--param", "at=-0.2"],
        None,
        "lesion joint=lbr_iiwa_joint_2 at=-0.2",
    ),
}


def _tell_robot(endpoint: str, text: str) -> None:
    """Publish `text` on the stand-in's ``/arm/body_change`` as a ROS 2 node would."""
    from sensorimotor.protocol.bus import BusConfig
    from sensorimotor.worlds.ros2.cdr import Codec
    from sensorimotor.worlds.ros2.names import Entity
    from sensorimotor.worlds.ros2.rosbus import RosBus

    c = Codec()
    t = "std_msgs/msg/String"
    with RosBus(BusConfig(mode="client", connect=(endpoint,))) as bus:
        pub = bus.ros_publisher(
            Entity(0, bus.zid, 0, 1, "MP", "bench", "/", "/", "/arm/body_change", t, c.type_hash(t))
        )
        time.sleep(0.5)  # the stand-in's subscription reaches this session
        pub.put(c.serialize(c.new(t, data=text), t))
        time.sleep(0.5)


def _world_steps(ep: str, wid: str) -> int:
    """Steps the agent has taken in world `wid` (0 while it does not answer)."""
    from sensorimotor.protocol import codec, keys
    from sensorimotor.protocol.bus import Bus, BusConfig, BusError
    from sensorimotor.protocol.messages import AgentStatus

    try:
        with Bus(BusConfig.for_role("tool", ep)) as bus:
            r = bus.get(keys.agent_status("a0"), timeout=2.0)
    except BusError:
        return 0
    if not r:
        return 0
    st = codec.decode(AgentStatus, r[0].payload)
    return next((ln.steps for ln in st.links if ln.world_id == wid), 0)


def learn_one(
    kind: str, seed: int, timeout: float, rate: float = 50.0, change: str = "reverse", change_at: int = 3000
) -> dict[str, Any]:
    """One seeded run through `sme world arm` (kind ``native``) or the stand-in + `sme world ros2`."""
    procs: list[subprocess.Popen] = []
    out: dict[str, Any] = {"world": kind, "seed": seed}
    with tempfile.TemporaryDirectory() as tmp:
        ep = f"tcp/127.0.0.1:{free_port()}"
        try:
            procs.append(_py("-m", "sensorimotor.tools.cli", "agent", "--listen", ep, "-q"))
            watch, rows = _watch(ep, 3 * timeout)
            procs.append(watch)
            if kind == "native":
                wid = "arm"
                procs.append(
                    _py("-m", "sensorimotor.tools.cli", "world", "arm", "--seed", str(seed), "--connect", ep, "-q")
                )
                perturb: list[str] | None = CHANGES[change][0]
                robot_change: str | None = None
            else:
                wid = "ros2"
                rob = f"tcp/127.0.0.1:{free_port()}"
                procs.append(_standin(rob, os.path.join(tmp, "s.json"), "--rate", str(rate)))
                out["standin_rate_hz"] = rate
                args = [
                    "world",
                    "ros2",
                    "--robot",
                    robot_file(tmp, rate, rob),
                    "--seed",
                    str(seed),
                    "--connect",
                    ep,
                    "-q",
                ]
                procs.append(_py("-m", "sensorimotor.tools.cli", *args))
                perturb, robot_change = CHANGES[change][1], CHANGES[change][2]
            t0 = time.monotonic()

            def good() -> dict | None:
                return next((r for r in rows if r.get("version") and (r.get("procrustes_error") or 1) < 0.1), None)

            first = _until(good, timeout)
            out["seconds_to_learn"] = round(time.monotonic() - t0, 1)
            out["steps_to_error_below_0_1"] = first["step"] if first else None
            out["error"] = first["procrustes_error"] if first else None
            if first is None:
                return out
            _until(lambda: _world_steps(ep, wid) >= change_at, timeout)  # the same step in both runs
            out["change_at_step"] = _world_steps(ep, wid)
            n0 = len(rows)
            if perturb is not None:
                pert = _py("-m", "sensorimotor.tools.cli", "perturb", *perturb, "--world", wid, "--connect", ep)
                out["perturb_exit"] = pert.wait(30)
                out["change"] = "sme perturb " + " ".join(perturb)
            else:
                _tell_robot(rob, str(robot_change))
                out["change"] = f"on the robot: {robot_change}"
            relearned = _until(lambda: next((r for r in rows[n0:] if r.get("trigger") == "relearned"), None), timeout)
            drop = next((r for r in rows[n0:] if r.get("kind") == "drop_detected"), None)
            out["drop_step"] = drop["step"] if drop else (relearned or {}).get("drop_step")
            out["relearned_step"] = relearned["step"] if relearned else None
            out["relearned_error"] = relearned["procrustes_error"] if relearned else None
        finally:
            for p in reversed(procs):
                _stop(p)
        stats = Path(tmp, "s.json")
        if stats.exists():  # the stand-in's own counts
            s = json.loads(stats.read_text())
            out["standin"] = {
                k: s[k] for k in ("ticks", "commands", "dropped", "late_commands", "command_latency_ms_p99")
            }
    return out


def main_args(args: argparse.Namespace) -> int:
    if args.what == "throughput":
        res: Any = throughput(args.ticks, args.rate, args.camera_seconds)
    else:
        res = [
            learn_one(k, args.seed, args.timeout, args.learn_rate, args.change, args.change_at)
            for k in ("native", "ros2")
        ]
    text = json.dumps(res, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")
    return 0
