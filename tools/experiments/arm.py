"""`sme reproduce arm`: robot arms from URDFs learned by the generic program (no arm code in the
agent), against the sensor-only peers, and the body changes it notices by itself.

- bodies: pybullet_data's Kuka iiwa (2 moving joints), Franka Panda (3), xArm6 (2), and a 3-link
  planar arm whose URDF is written here (`planar_urdf`). Per body and seed: the generic program
  until `embeddings` embeddings; the last one scored by Procrustes against the joint angles and
  against the hand's 3-D position, beside PCA and Isomap of the same start images (the better
  peer's ratio reported).
- changes (Kuka): once learned, `morph` (link 4 x 1.3), `lesion` (joint 2 locked at the lattice's
  lowest angle), `reverse` (joint 4): steps from the change to the agent's own drop detection, to
  the `relearned` embedding, and that embedding's error against the changed body's truth.
- false alarms: drops detected in a long run with no change.
Pictures: per change, the learned map before and after, coloured by the true hand position.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from sensorimotor.agent.detectors import make_detector
from sensorimotor.agent.embedding import procrustes_error
from sensorimotor.agent.programs.generic import GenericProgram
from sensorimotor.protocol.messages import Control, Embedding
from sensorimotor.tools.experiments import scoring
from sensorimotor.tools.experiments.objectpose import peers
from sensorimotor.tools.experiments.shared import pool_map
from sensorimotor.tools.inprocess import InProcessRun, run_inprocess
from sensorimotor.worlds.arm import ArmWorld

_PLANAR = """<?xml version="1.0"?>
<robot name="planar{n}">
  <material name="grey"><color rgba="0.5 0.5 0.5 1"/></material>
  <link name="base">
    <inertial><mass value="1"/><inertia ixx="1e-2" iyy="1e-2" izz="1e-2" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><geometry><box size="0.1 0.1 0.1"/></geometry><material name="grey"/></visual>
  </link>
{links}</robot>
"""
_SEGMENT = """  <link name="l{k}">
    <inertial><mass value="0.1"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><origin xyz="0 0 {half}"/><geometry><box size="0.04 0.04 {length}"/></geometry><material name="grey"/></visual>
  </link>
  <joint name="j{k}" type="revolute">
    <parent link="{parent}"/><child link="l{k}"/>
    <origin xyz="0 0 {z}"/><axis xyz="0 1 0"/>
    <limit lower="-2.5" upper="2.5" effort="1" velocity="1"/>
  </joint>
"""


def planar_urdf(directory: str | os.PathLike[str], n: int = 3, length: float = 0.3) -> str:
    """Write an `n`-link planar arm (joints j0.. about y, links `length` m, grey boxes) into
    `directory`; its path. A robot that ships with nothing of ours."""
    links = "".join(
        _SEGMENT.format(
            k=k, parent="base" if k == 0 else f"l{k - 1}", z=0.05 if k == 0 else length, half=length / 2, length=length
        )
        for k in range(n)
    )
    path = Path(directory) / f"planar{n}.urdf"
    path.write_text(_PLANAR.format(n=n, links=links))
    return str(path)


#: body -> world parameters (`urdf` "planar" is written into the output folder)
BODIES: dict[str, dict[str, Any]] = {
    "kuka_iiwa": {"urdf": "kuka_iiwa/model.urdf", "n_joints": 2},
    "franka_panda": {"urdf": "franka_panda/panda.urdf", "n_joints": 3},  # 5^3 starts: 3 x the embeddings
    "xarm6": {"urdf": "xarm/xarm6_robot.urdf", "n_joints": 2},
    "planar3": {"urdf": "planar", "n_joints": 2, "bend": 0.3},
}
#: change -> its Control parameters on the Kuka
CHANGES: dict[str, tuple[str, dict[str, str]]] = {
    "morph": ("morph", {"link": "lbr_iiwa_link_4", "scale": "1.3"}),
    "lesion": ("lesion", {"joint": "lbr_iiwa_joint_2", "at": "lowest"}),
    "reverse": ("reverse", {"joint": "lbr_iiwa_joint_4"}),
}


def learn(
    world: ArmWorld, seed: int, steps: int, perturb: Any = None, stop_when: Any = None
) -> tuple[InProcessRun, float]:
    """The generic program with the agent's default detector on `world`; the run and its seconds."""
    program = GenericProgram(world.spec(), seed=seed)
    detector = make_detector("cusum", **program.detector_params)
    t0 = time.perf_counter()
    run = run_inprocess(world, program, steps, detector=detector, perturb=perturb, stop_when=stop_when)
    return run, time.perf_counter() - t0


def _error(e: Embedding) -> float:
    return float("nan") if e.procrustes_error is None else float(e.procrustes_error)


def _world(body: str, seed: int, lattice: int, out: str) -> ArmWorld:
    prm = dict(BODIES[body])
    if prm["urdf"] == "planar":
        prm["urdf"] = planar_urdf(out)
    if body == "franka_panda":
        lattice = min(lattice, 5)  # 3 joints: 125 start poses
    return ArmWorld(f"arm-{body}", seed, lattice=lattice, **prm)


def body_job(body: str, seed: int, lattice: int, embeddings: int, steps: int, out: str) -> dict[str, Any]:
    """One body, one seed: the learned embedding against both truths, beside the peers."""
    from threadpoolctl import threadpool_limits

    w = _world(body, seed, lattice, out)
    with w, threadpool_limits(1):
        if body == "franka_panda":
            embeddings, steps = 3 * embeddings, 3 * steps
        run, sec = learn(w, seed, steps, stop_when=lambda r: len(r.embeddings) >= embeddings)
        if not run.embeddings:
            raise RuntimeError(f"{body}: no embedding in {run.steps} steps")
        truth = w.truth().tensors
        last = run.embeddings[-1]
        xy = np.asarray(last.coordinates, dtype=np.float64)
        images = np.array([w.observe(q) for q in w.poses])
        pe = peers(images, truth["positions"])
        return {
            "body": body,
            "seed": seed,
            "joints": w.spec().params["joints"],
            "n_starts": len(w.poses),
            "errors": [_error(e) for e in run.embeddings],
            "steps_to_first_below_0.1": next((int(e.step) for e in run.embeddings if _error(e) < 0.1), None),
            "final_error": _error(last),
            "hand_error": procrustes_error(truth["hand"], xy),
            "goal_reached": float(last.metrics["goal_reached_fraction"]),
            "scores": scoring.scores_of(last),
            "pca_error": pe.pca_error,
            "isomap_error": pe.isomap_error,
            "pca_hand_error": procrustes_error(truth["hand"], pe.pca_coordinates),
            "isomap_hand_error": procrustes_error(truth["hand"], pe.isomap_coordinates),
            "world_steps": run.steps,
            "seconds": sec,
        }


def change_job(change: str, seed: int, lattice: int, at: int, steps: int, out: str) -> dict[str, Any]:
    """The Kuka learned, then `change` at step `at`: detection, relearning, the new map's error.
    `change` "none" is the false-alarm run: `steps` steps and no change."""
    from threadpoolctl import threadpool_limits

    w = _world("kuka_iiwa", seed, lattice, out)
    with w, threadpool_limits(1):
        ctl = None
        if change != "none":
            kind, params = CHANGES[change]
            params = dict(params)
            if params.get("at") == "lowest":
                params["at"] = repr(float(w.poses[:, 0].min()))
            ctl = Control(w.world_id, kind, params)
        hand0 = w.truth().tensors["hand"]
        run, sec = learn(
            w,
            seed,
            steps,
            perturb=lambda k: ctl if k == at else None,
            stop_when=None if ctl is None else (lambda r: bool(r.events("relearned"))),
        )
        truth = w.truth().tensors
        drops = [int(e.step) for e in run.events("drop_detected")]
        before = [e for e in run.embeddings if e.step < at]
        relearned = [e for e in run.embeddings if e.trigger == "relearned"]
        res: dict[str, Any] = {"change": change, "seed": seed, "world_steps": run.steps, "seconds": sec, "drops": drops}
        if ctl is None:
            res["false_alarms"] = len(drops)
            return res
        res.update(
            before_error=_error(before[-1]) if before else None,
            before_coordinates=np.asarray(before[-1].coordinates).tolist() if before else None,
            hand_before=hand0.tolist(),
            detected_after=drops[0] - at if drops else None,
            relearned_after=int(relearned[0].step) - at if relearned else None,
            relearned_error=procrustes_error(truth["positions"], np.asarray(relearned[0].coordinates))
            if relearned
            else None,
            after_coordinates=np.asarray(relearned[0].coordinates).tolist() if relearned else None,
            hand_after=truth["hand"].tolist(),
        )
        return res


def _plot_changes(out: str, res: list[dict[str, Any]]) -> None:
    """Per change (first seed): the learned map before and after, coloured by the true hand height."""
    from sensorimotor.tools.common import require

    matplotlib = require("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [next(r for r in res if r["change"] == c) for c in CHANGES if any(r["change"] == c for r in res)]
    rows = [r for r in rows if r["before_coordinates"] and r["after_coordinates"]]
    if not rows:
        return
    fig, axs = plt.subplots(len(rows), 2, figsize=(8, 3.6 * len(rows)), squeeze=False)
    for (a, b), r in zip(axs, rows, strict=True):
        for ax, key, hand, title in (
            (a, "before_coordinates", "hand_before", "before"),
            (b, "after_coordinates", "hand_after", f"relearned after {r['change']}"),
        ):
            xy, h = np.asarray(r[key]), np.asarray(r[hand])
            sc = ax.scatter(
                xy[:, 0], xy[:, 1] if xy.shape[1] > 1 else np.zeros(len(xy)), c=h[:, 2], cmap="viridis", s=22
            )
            ax.set_title(f"{title} (seed {r['seed']})", fontsize=9)
            ax.set_aspect("equal", adjustable="datalim")
        fig.colorbar(sc, ax=b, label="true hand height, m")
    fig.suptitle("Kuka iiwa: the learned map before and after each body change")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "arm_changes.png"), dpi=110)
    plt.close(fig)


def chapter(runs: int, quick: bool, workers: int, out: str) -> dict[str, Any]:
    """`sme reproduce arm`: per body the embedding against both truths beside the peers; per change
    the steps to detection and to the relearned map and its error; false alarms; 95 % CIs."""

    os.makedirs(out, exist_ok=True)
    lattice, embeddings, steps, at, quiet = (5, 4, 8_000, 2_000, 10_000) if quick else (7, 8, 30_000, 6_000, 50_000)
    bodies = pool_map(body_job, [(b, s, lattice, embeddings, steps, out) for b in BODIES for s in range(runs)], workers)
    jobs = [(c, s, lattice, at, at + 10_000, out) for c in CHANGES for s in range(runs)]
    jobs += [("none", s, lattice, 0, quiet, out) for s in range(max(1, runs // 2))]
    changes = pool_map(change_job, jobs, workers)
    ci = scoring.ci95

    def f(v: list[float], d: int = 4) -> str:
        m, h = ci(v)
        return f"{m:.{d}f} ± {h:.{d}f}"

    lines = [
        f"Robot arms from URDFs (`worlds/arm.py`), the generic program, {runs} seeded runs; lattice {lattice} "
        f"angles per moving joint (Franka Panda ≤ 5), {embeddings} embeddings (Panda {3 * embeddings}); "
        "mean ± 95 % CI over seeds. Peers: PCA and Isomap (best of 4, 6, 8, 12 neighbours) of the start images.",
        "",
        "| body (moving joints) | starts | Procrustes vs joint angles | vs hand position | PCA / Isomap vs joints "
        "| PCA / Isomap vs hand | ours / better peer (joints) | goal reached | steps to < 0.1 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    summary: dict[str, Any] = {}
    for b in BODIES:
        rs = [r for r in bodies if r["body"] == b]
        se, pca, iso = (
            ci([r["final_error"] for r in rs]),
            ci([r["pca_error"] for r in rs]),
            ci([r["isomap_error"] for r in rs]),
        )
        ratio = se[0] / max(min(pca[0], iso[0]), 1e-12)
        first = [r["steps_to_first_below_0.1"] for r in rs]
        summary[b] = {
            "se_error": se,
            "hand_error": ci([r["hand_error"] for r in rs]),
            "pca": pca,
            "isomap": iso,
            "ratio": ratio,
        }
        lines.append(
            f"| {b} ({rs[0]['joints']}) | {rs[0]['n_starts']} | {f([r['final_error'] for r in rs])} "
            f"| {f([r['hand_error'] for r in rs])} | {pca[0]:.3f} / {iso[0]:.3f} "
            f"| {np.mean([r['pca_hand_error'] for r in rs]):.3f} / {np.mean([r['isomap_hand_error'] for r in rs]):.3f} "
            f"| {ratio:.3f} "
            f"| {np.mean([r['goal_reached'] for r in rs]):.2f} | {first} |"
        )
    lines += [
        "",
        f"Body changes on the Kuka, at step {at} (learned by then), the agent's own drop detector:",
        "",
        "| change | detected after (steps) | relearned after (steps) | relearned map vs the changed body's joints | drops |",
        "|---|---|---|---|---|",
    ]
    for c in CHANGES:
        rs = [r for r in changes if r["change"] == c]
        det = [r["detected_after"] for r in rs if r["detected_after"] is not None]
        rel = [r["relearned_after"] for r in rs if r["relearned_after"] is not None]
        err = [r["relearned_error"] for r in rs if r["relearned_error"] is not None]
        summary[c] = {"detected_after": det, "relearned_after": rel, "relearned_error": ci(err) if err else None}
        lines.append(
            f"| {c} {CHANGES[c][1]} | {f(det, 0) if det else 'never'} ({len(det)}/{len(rs)}) "
            f"| {f(rel, 0) if rel else 'never'} | {f(err) if err else '-'} | {[len(r['drops']) for r in rs]} |"
        )
    quiet_runs = [r for r in changes if r["change"] == "none"]
    alarms = [r["false_alarms"] for r in quiet_runs]
    summary["false_alarms"] = alarms
    lines += ["", f"False alarms with no change, {quiet} steps per run: {alarms} ({len(quiet_runs)} runs)."]
    _plot_changes(out, [r for r in changes if r["change"] != "none"])
    return {"results": {"bodies": bodies, "changes": changes}, "summary": summary, "markdown": "\n".join(lines)}


__all__ = ["BODIES", "CHANGES", "body_job", "change_job", "chapter", "learn", "planar_urdf"]
