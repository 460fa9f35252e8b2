"""The method's ceiling on a toy-text world: the optimal policy (value iteration on the
environment's own transition table ``P``, for evaluation only) swept from the world's start states
as the program sweeps its own - the same number of traces per start, the same estimator, the same
trace limit - and embedded the same way. Its goal fraction and its map's Procrustes error are what
a learner that found the best policy would give; `sme bench zoo` reports them beside the learned
policy's."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import procrustes_error
from sensorimotor.agent.programs.generic_jobs import embed_job


@dataclass(frozen=True)
class Ceiling:
    """The optimal policy's sweep: its goal fraction and its map's error against the truth."""

    goal_reached_fraction: float
    error: float
    samples_per_start: int


def optimal_q(P: Any, n_states: int, n_actions: int, gamma: float, goal_reward: bool) -> np.ndarray:
    """Q of the discounted chance of reaching the goal (the model learner's values, on the true
    table): a transition into the goal is worth 1, a termination that is not the goal 0."""
    V = np.zeros(n_states)
    Q = np.zeros((n_states, n_actions))
    for _ in range(100_000):
        for s in range(n_states):
            for a in range(n_actions):
                q = 0.0
                for p, s2, r, term in P[s][a]:
                    goal = (r > 0) if goal_reward else bool(term)
                    q += p * (1.0 if goal else 0.0 if term else gamma * V[int(s2)])
                Q[s, a] = q
        V_new = Q.max(axis=1)
        if np.abs(V_new - V).max() < 1e-10:
            break
        V = V_new
    return Q


def toy_text_ceiling(world: Any, program: Any) -> Ceiling | None:
    """The ceiling of `world` (a served Gymnasium toy-text environment with a table ``P`` and state
    ids) for `program` (a generic program after its run: its traces per start, estimator, trace
    limit and discount); None for any other world."""
    u = getattr(world, "u", None)
    truth = world.truth()
    if u is None or not hasattr(u, "P") or truth is None or not getattr(program, "discrete", False):
        return None
    spec = world.spec()
    n_states, n_actions = int(u.observation_space.n), int(u.action_space.n)
    gamma = float(getattr(program.params, "model_gamma", 0.99))
    goal_reward = str(spec.goal) == "reward"
    Q = optimal_q(u.P, n_states, n_actions, gamma, goal_reward)
    k = int(program.samples) if program.stochastic else 1
    traces: list[list[list[int]]] = []
    reached: list[list[bool]] = []
    for i in range(spec.n_starts):
        per, ok = [], []
        for _ in range(k):
            res = world.reset(start=i)
            s = int(np.asarray(res.tensors[spec.sensors[0].name]).reshape(-1)[0]) - int(spec.sensors[0].low)
            trace: list[int] = []
            hit = False
            for _ in range(int(program.max_trace)):
                a = int(Q[s].argmax())
                trace.append(a)
                res = world.step(np.array([a], dtype=np.float64))
                term = bool(res.info.get("terminated", res.done))
                if res.done:
                    hit = res.reward > 0 if goal_reward else term and not res.truncated
                    break
                s = int(np.asarray(res.tensors[spec.sensors[0].name]).reshape(-1)[0]) - int(spec.sensors[0].low)
            per.append(trace)
            ok.append(hit)
        traces.append(per)
        reached.append(ok)
    prm = program.params
    out = embed_job(
        traces,
        None,
        program.dims,
        estimator=program.estimator,
        n_actions=n_actions,
        reached=reached,
        discrete_distance=prm.discrete_distance,
        embedding=prm.embedding,
    )
    pos = np.asarray(truth.tensors["positions"], dtype=np.float64)
    frac = float(np.mean([r for per in reached for r in per]))
    return Ceiling(frac, float(procrustes_error(pos, np.asarray(out["coordinates"]))), k)


__all__ = ["Ceiling", "optimal_q", "toy_text_ceiling"]
