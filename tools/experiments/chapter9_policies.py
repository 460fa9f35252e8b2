"""Chapter 9's policy experiments (9.6): option discovery in a gridworld (Fig 9.3: steps to a level
with no, random or discovered options) and policy maps of the mountain car (Fig 9.2: traces of the
learned policy clustered into failure, direct and rocking). Each `*_job` is one seeded run."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.worlds.gridworld import GridWorld

# --- option discovery (9.6, Fig 9.3) ----------------------------------------------------------


@dataclass(frozen=True)
class GridTable:
    """A deterministic gridworld as tables: next cell of (cell, move), the goal cell, BFS distances."""

    next: np.ndarray  # [n_cells, n_moves]
    goal: int
    dist: np.ndarray  # [n_cells] shortest path length to the goal

    @staticmethod
    def of(world: GridWorld) -> GridTable:
        n, m = len(world.cells), len(world.moves)
        nxt = np.empty((n, m), dtype=np.int64)
        for i, (x, y) in enumerate(world.cells):
            for a, (dx, dy) in enumerate(world.moves):
                c = (x + dx, y + dy)
                nxt[i, a] = world.index.get(c, i)
        goal = world.index[world.goal]
        dist = np.full(n, -1, dtype=np.int64)
        dist[goal], frontier = 0, [goal]
        while frontier:  # BFS backwards (moves are reversible in a gridworld)
            new = []
            for cell in frontier:
                for nb in nxt[cell]:
                    if dist[nb] < 0:
                        dist[nb] = dist[cell] + 1
                        new.append(int(nb))
            frontier = new
        return GridTable(nxt, goal, dist)


def greedy_steps(table: GridTable, agent: Any, starts: np.ndarray, cap: int = 200) -> float:
    """Mean primitive steps to the goal of the agent's greedy choices from each start (cap if never)."""
    total = 0
    for s0 in starts:
        s, t = int(s0), 0
        while s != table.goal and t < cap:
            for a in agent.actions_of(agent.greedy(s)):
                s, t = int(table.next[s, a]), t + 1
                if s == table.goal or t >= cap:
                    break
        total += t
    return total / len(starts)


@dataclass(frozen=True)
class OptionCurve:
    """Greedy steps to goal after every `every` training steps, and the first training step at
    which it reached `level` (None: never within the budget)."""

    steps: list[int]
    mean_steps: list[float]
    steps_to_level: int | None


def train_options_agent(
    table: GridTable,
    options: list[tuple[int, ...]],
    seed: int,
    budget: int,
    level: float,
    every: int = 500,
    n_eval: int = 40,
    max_episode: int = 300,
) -> tuple[OptionCurve, Any]:
    """SMDP Q-learning with `options` (none: primitives only) from random starts, each step of an
    option also updating its primitive action (intra-option); training steps count primitive world steps. Stops at the budget or once greedy steps to goal <= `level`."""
    from sensorimotor.agent.learners.smdp_q import OptionQLearner

    n = table.next.shape[0]
    agent = OptionQLearner(n, table.next.shape[1], options, alpha=0.5, gamma=0.95, epsilon=0.1, seed=seed)
    rng = np.random.default_rng(seed)
    free = np.flatnonzero(np.arange(n) != table.goal)
    evals = np.random.default_rng(9_000).choice(free, size=min(n_eval, free.size), replace=False)
    steps: list[int] = []
    means: list[float] = []
    t, hit = 0, None
    while t < budget and hit is None:
        s, ep = int(rng.choice(free)), 0
        while s != table.goal and ep < max_episode and hit is None:
            c = agent.choose(s)
            s0, R, k = s, 0.0, 0
            for a in agent.actions_of(c):
                prev, s = s, int(table.next[s, a])
                k += 1
                t += 1
                ep += 1
                if c >= agent.n_actions:  # intra-option learning: each step also teaches its primitive
                    agent.update(prev, a, float(s == table.goal), 1, s, s == table.goal)
                if s == table.goal:
                    R += agent.gamma ** (k - 1)
                    break
                if t % every == 0:
                    steps.append(t)
                    means.append(greedy_steps(table, agent, evals))
                    if means[-1] <= level:
                        hit = t
            agent.update(s0, c, R, k, s, s == table.goal)
    return OptionCurve(steps, means, hit), agent


def option_world(size: int = 15) -> GridWorld:
    """The options world: a `size` x `size` gridworld with the goal in a far corner."""
    return GridWorld(seed=0, size=size, goal=(size - 1, size - 1), max_episode_steps=10**6)


def options_job(seed: int, budget: int, n_options: int = 4, size: int = 15, level_factor: float = 1.25) -> dict:
    """One seed of Fig 9.3: a primitives-only agent trained (source seed) gives traces from every
    start; options discovered from them; new agents with none / random / discovered options, same seed."""
    from sensorimotor.agent.embedding.options import discover_options, random_options

    table = GridTable.of(option_world(size))
    free = np.flatnonzero(np.arange(table.next.shape[0]) != table.goal)
    level = level_factor * float(table.dist[np.random.default_rng(9_000).choice(free, size=40, replace=False)].mean())
    # the trained policy: a primitives-only agent trained to the level, its greedy traces from every start
    _, source = train_options_agent(table, [], 10_000 + seed, 10 * budget, level)
    traces = []
    for s0 in free:
        s, tr = int(s0), list[int]()
        while s != table.goal and len(tr) < 200:
            a = source.greedy(s)
            tr.append(a)
            s = int(table.next[s, a])
        traces.append(tr)
    found = discover_options(traces, n_options=n_options, seed=seed)
    rand = random_options(table.next.shape[1], len(found.options), seed=seed)
    out: dict[str, Any] = {"seed": seed, "level": level, "discovered_options": found.options, "random_options": rand}
    for name, opts in (("none", []), ("random", rand), ("discovered", found.options)):
        curve, _ = train_options_agent(table, opts, seed, budget, level)
        out[name] = {"steps": curve.steps, "mean_steps": curve.mean_steps, "steps_to_level": curve.steps_to_level}
    return out


# --- policy maps (9.6, Fig 9.2) -----------------------------------------------------------------

OUTCOMES = ("failure", "direct", "rocking")


def train_mountaincar(seed: int, train_steps: int, tiles: int = 10, n_tilings: int = 8, gamma: float = 0.99) -> Any:
    """Sarsa(lambda) with tile coding on the true (x, v) for `train_steps` car steps (ch. 8's
    true-state agent, with the dissertation's discount of 0.99: after 30,000 steps its policy still
    fails from some starts, climbs directly from others and rocks from the rest, the three kinds of
    behaviour Fig 9.2's map separates; undiscounted, as ch. 8 now drives, it fails from few): the
    trained policy whose behaviour a policy map shows."""
    from sensorimotor.tools.experiments.mountaincar import true_state_agent, true_state_episode
    from sensorimotor.worlds.mountaincar_dynamics import MountainCarParams

    prm = MountainCarParams()
    rng = np.random.default_rng(seed)
    agent = true_state_agent(seed, prm, tiles, n_tilings, gamma=gamma)
    n = 0
    while n < train_steps:
        n += true_state_episode(agent, rng, prm, 1000)
    return agent


def mountaincar_traces(agent: Any, n: int, seed: int, cap: int = 300) -> tuple[list[list[int]], list[str]]:
    """Greedy traces of `agent` from `n` random (x, v) starts and each start's true outcome:
    ``failure`` (no goal within `cap` car steps), ``direct`` (goal without the car ever moving
    backwards after its start) or ``rocking`` (goal after at least one backward swing)."""
    from sensorimotor.worlds.mountaincar_dynamics import MountainCarParams, random_state
    from sensorimotor.worlds.mountaincar_dynamics import step as car_step

    prm = MountainCarParams()
    rng = np.random.default_rng(seed)
    traces, outcomes = [], []
    for _ in range(n):
        x, v = random_state(rng, prm)
        tr: list[int] = []
        backward, done = False, False
        while not done and len(tr) < cap:
            a = agent.greedy(np.array([x, v]))
            tr.append(a)
            x, v, done = car_step(x, v, a - 1, prm)
            backward |= v < 0 and len(tr) > 1
        traces.append(tr)
        outcomes.append("failure" if not done else ("rocking" if backward else "direct"))
    return traces, outcomes


def policy_map_job(seed: int, train_steps: int, n_starts: int, n_clusters: int | None = 3) -> dict:
    """Fig 9.2 on one seed: train, trace from `n_starts` random starts, map, and score the clusters
    against the true outcomes (each cluster's majority outcome and its purity)."""
    from sensorimotor.agent.embedding.policy_map import policy_map

    agent = train_mountaincar(seed, train_steps)
    traces, outcomes = mountaincar_traces(agent, n_starts, seed + 1)
    pm = policy_map(traces, n_clusters=n_clusters, seed=seed)
    clusters = []
    out = np.array(outcomes)
    for c in range(pm.n_clusters):
        members = out[pm.labels == c]
        counts = {o: int((members == o).sum()) for o in OUTCOMES}
        major = max(counts, key=lambda o: counts[o])
        clusters.append(
            {
                "cluster": c,
                "size": int(members.size),
                "majority": major,
                "purity": counts[major] / max(1, members.size),
                "outcomes": counts,
            }
        )
    return {
        "seed": seed,
        "coordinates": pm.coordinates.tolist(),
        "labels": pm.labels.tolist(),
        "outcomes": outcomes,
        "clusters": clusters,
        "silhouette": pm.silhouette,
        "mean_length": float(np.mean([len(t) for t in traces])),
    }
