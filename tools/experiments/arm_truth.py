"""Which truth a redundant arm's trace map recovers (docs/arm.md, "Which truth the map recovers"):
forward kinematics alone, no camera and no learning. The arm world's drawn starts and lattice; the
shortest traces from each start, one joint after another, to (a) the goal pose, (b) the nearest
configuration that puts the hand within `radius` of the goal pose's hand; edit distance, classical
MDS, Procrustes error against the joint angles (as many dimensions as joints) and against the hand
position (3).

    python -m sensorimotor.tools.experiments.arm_truth --n-joints 7 --poses 200000
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, procrustes_error, trace_distances
from sensorimotor.worlds.arm import ArmWorld


def _trace(delta: np.ndarray) -> list[int]:
    """The moves of offset `delta` (in steps), one joint after another: 2j is +, 2j+1 is -."""
    out: list[int] = []
    for j, d in enumerate(np.rint(delta).astype(int)):
        out += [2 * j + (0 if d > 0 else 1)] * abs(int(d))
    return out


def _errors(traces: list[list[int]], joints: np.ndarray, hands: np.ndarray) -> dict[str, float]:
    D = trace_distances(traces, kind="edit", substitution_cost=2)
    return {
        "vs_joints": procrustes_error(joints, classical_mds(D, joints.shape[1]).coordinates),
        "vs_hand": procrustes_error(hands, classical_mds(D, 3).coordinates),
    }


def measure(
    urdf: str = "kuka_iiwa/model.urdf", n_joints: int = 7, poses: int = 200_000, radii: tuple[float, ...] = (0.05, 0.08)
) -> dict[str, Any]:
    """The errors of both goals' maps (see the module docstring); `poses` lattice poses drawn to find
    the configurations that put the hand near the goal's."""
    w = ArmWorld(seed=0, urdf=urdf, n_joints=n_joints, image=16, goal_image=32)
    with w:
        grid = np.array(w._grid)
        k = np.arange(len(grid))
        idx = np.array([[int(np.argmin(np.abs(grid[j] - a))) for j, a in enumerate(q)] for q in w.poses])
        hands = np.array([w.tip_position(q) for q in w.poses])
        goal = idx[int(np.argmin(np.linalg.norm(hands - hands.mean(axis=0), axis=1)))]  # a central hand
        drawn = np.random.default_rng(1).integers(0, grid.shape[1], (poses, len(grid)))
        tips = np.array([w.tip_position(grid[k, i]) for i in drawn])
        goal_tip = w.tip_position(grid[k, goal])
    out: dict[str, Any] = {"urdf": urdf, "n_joints": n_joints, "starts": len(idx), "poses": poses}
    out["pose_goal"] = _errors([_trace(goal - s) for s in idx], w.poses, hands)
    for r in radii:
        near = drawn[np.linalg.norm(tips - goal_tip, axis=1) < r]
        traces = [_trace(near[int(np.argmin(np.abs(near - s).sum(axis=1)))] - s) for s in idx]
        out[f"hand_goal_{r:g}m"] = {"configurations": len(near), **_errors(traces, w.poses, hands)}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--urdf", default="kuka_iiwa/model.urdf")
    ap.add_argument("--n-joints", type=int, default=7)
    ap.add_argument("--poses", type=int, default=200_000)
    ap.add_argument("--json", action="store_true", help="the figures as one JSON object, not a table")
    a = ap.parse_args(argv)
    m = measure(a.urdf, a.n_joints, a.poses)
    if a.json:
        print(json.dumps(m))
        return 0
    n = m["n_joints"]
    print(f"| goal | traces to | map vs joint angles ({n}-D) | map vs hand position (3-D) |")
    print("|---|---|---|---|")
    pg = m["pose_goal"]
    print(f"| one pose | that pose | {pg['vs_joints']:.3f} | {pg['vs_hand']:.3f} |")
    for key, v in m.items():
        if key.startswith("hand_goal_"):
            r = key[len("hand_goal_") : -1]
            print(
                f"| hand within {float(r) * 100:g} cm of the goal pose's | the nearest of {v['configurations']:,} "
                f"configurations that put it there | {v['vs_joints']:.3f} | {v['vs_hand']:.3f} |"
            )
    print(
        f"\n{m['starts']} starts of `sme world arm --param urdf={m['urdf']} --param n_joints={n}` (seed 0), {m['poses']:,} poses drawn"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
