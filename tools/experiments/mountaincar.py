"""Chapter 8 experiments, in-process through the daemon's WorldLink: the visual mountain car on a
body, the same task for an agent given the true (x, v), a random agent, and a body changed while the
agent drives."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sensorimotor.agent.learners.sarsa_lambda import SarsaLambda, TileCoder
from sensorimotor.worlds.mountaincar_dynamics import MountainCarParams, evaluation_states, random_state
from sensorimotor.worlds.mountaincar_dynamics import step as car_step


@dataclass
class DriveResult:
    curve: list[tuple[int, float]]  # (training car steps, mean steps to goal)
    embeddings: list[dict[str, Any]] = field(default_factory=list)
    drops: list[int] = field(default_factory=list)  # training steps at which the agent saw a drop
    morph_at: int | None = None  # training steps when the body changed
    world_steps: int = 0
    seconds: float = 0.0


def visual(
    seed: int,
    train_steps: int,
    eval_every: int = 10_000,
    n_eval: int = 100,
    baseline: float = 1.0,
    vertical: bool = False,
    morph_at: int | None = None,
    morph: dict[str, str] | None = None,
    detector: str | None = None,
    **program_params: Any,
) -> DriveResult:
    """The staged program on the rendered robot; optionally the body changes (`morph`) after
    `morph_at` training car steps, with the agent's own detector watching (`detector`)."""
    from sensorimotor.agent.detectors import make_detector
    from sensorimotor.agent.programs.mountaincar import MountainCarProgram
    from sensorimotor.protocol.messages import Control, Embedding
    from sensorimotor.tools.experiments.scoring import scores_of
    from sensorimotor.tools.inprocess import run_inprocess
    from sensorimotor.worlds.mountaincar import MountainCarWorld

    world = MountainCarWorld(seed=seed, baseline=baseline, vertical=vertical, n_eval=n_eval)
    prog = MountainCarProgram(world.spec(), seed=seed, eval_every=eval_every, **program_params)
    res = DriveResult([])
    state = {"morphed": False}

    def on_output(msg: Any) -> None:
        if isinstance(msg, Embedding):
            res.embeddings.append(
                {
                    "version": msg.version,
                    "trigger": msg.trigger,
                    "training_steps": prog.training_steps,
                    "procrustes_error": msg.procrustes_error,
                    "scores": scores_of(msg),
                }
            )
        elif getattr(msg, "kind", None) == "drop_detected":
            res.drops.append(prog.training_steps)

    def perturb(k: int) -> Control | None:
        if morph and morph_at is not None and not state["morphed"] and prog.training_steps >= morph_at:
            state["morphed"] = True
            res.morph_at = prog.training_steps
            return Control(world.world_id, "morph", dict(morph))
        return None

    n_evals = train_steps // eval_every
    det = make_detector(detector, **prog.detector_params) if detector else None
    with world:
        run = run_inprocess(
            world,
            prog,
            10**9,
            detector=det,
            on_output=on_output,
            perturb=perturb,
            stop_when=lambda r: len(prog.curve) >= n_evals,
        )
    res.curve, res.world_steps, res.seconds = list(prog.curve), run.steps, run.seconds
    return res


def true_state_agent(
    seed: int,
    prm: MountainCarParams,
    tiles: int = 10,
    n_tilings: int = 8,
    alpha: float = 0.3,
    gamma: float = 0.99,
    lam: float = 0.9,
) -> SarsaLambda:
    """Sarsa(lambda) over a tile coding of the true (x, v): the agent given the state (ch. 8)."""
    coder = TileCoder(
        np.array([prm.x_min, -prm.v_max]), np.array([prm.x_max, prm.v_max]), tiles=tiles, n_tilings=n_tilings
    )
    return SarsaLambda(coder, 3, alpha=alpha, gamma=gamma, lam=lam, epsilon=0.0, seed=seed)


def true_state_episode(agent: SarsaLambda, rng: np.random.Generator, prm: MountainCarParams, max_car_steps: int) -> int:
    """One training episode of `agent` from a random state (reward -1 per step); the car steps taken."""
    x, v = random_state(rng, prm)
    s = np.array([x, v])
    agent.begin_episode()
    a = agent.act(s)
    for n in range(1, max_car_steps + 1):
        x, v, done = car_step(x, v, a - 1, prm)
        s2 = np.array([x, v])
        if done:
            agent.learn_one(s, a, -1.0, s2, None)
            return n
        a2 = agent.act(s2)
        agent.learn_one(s, a, -1.0, s2, a2)
        s, a = s2, a2
    return max_car_steps


def true_state(
    seed: int,
    train_steps: int,
    eval_every: int = 10_000,
    n_eval: int = 100,
    tiles: int = 10,
    n_tilings: int = 8,
    alpha: float = 0.3,
    gamma: float = 0.99,
    lam: float = 0.9,
    max_car_steps: int = 1000,
) -> DriveResult:
    """The same Sarsa(lambda) and tile coding, given the true position and velocity."""
    prm = MountainCarParams()
    rng = np.random.default_rng(seed)
    agent = true_state_agent(seed, prm, tiles, n_tilings, alpha, gamma, lam)
    evals = evaluation_states(n_eval)

    res = DriveResult([])
    n = 0
    while len(res.curve) < train_steps // eval_every:
        n += true_state_episode(agent, rng, prm, max_car_steps)
        if n // eval_every > len(res.curve):
            res.curve.append((n, steps_to_goal(agent.greedy, evals, max_car_steps)))
    return res


def steps_to_goal(policy, states: np.ndarray, cap: int = 1000) -> float:
    """Mean car steps to the goal from each (x, v) in `states` under `policy(s) -> 0|1|2`."""
    prm = MountainCarParams()
    total = 0
    for x, v in states:
        for t in range(1, cap + 1):  # noqa: B007 (t counts the steps taken, read after the loop)
            x, v, done = car_step(float(x), float(v), policy(np.array([x, v])) - 1, prm)
            if done:
                break
        total += t
    return total / len(states)


def random_agent(seed: int, n_eval: int = 100, cap: int = 1000) -> float:
    rng = np.random.default_rng(seed)
    return steps_to_goal(lambda s: int(rng.integers(3)), evaluation_states(n_eval), cap)
