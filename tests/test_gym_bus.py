"""A live world process driven from a plain Gymnasium loop over loopback Zenoh (`BusEnv`), with an
agent on the same bus that leaves the world alone because it was started with `--external`."""

from __future__ import annotations

import pytest

from sensorimotor.worlds.gym_bus import BusEnv
from tests.conftest import Lines, agent_status, wait_for, world_link

pytestmark = pytest.mark.integration


def test_a_plain_gymnasium_loop_steps_a_live_world_while_the_agent_stays_away(procs, endpoint):
    agent = procs.start("agent", "--listen", endpoint)
    assert wait_for(lambda: agent_status(endpoint) is not None, 60)
    world = procs.start("world", "gridworld", "--id", "g5", "--param", "size=5", "--external", "--connect", endpoint)
    log = Lines(agent.stderr)
    env = BusEnv("g5", connect=endpoint, timeout=30)
    try:
        assert env.world_spec.program == "external" and env.world_spec.params["program_hint"] == "gridworld"
        assert env.observation_space.n == 25 and env.action_space.n == 4
        # start state 7 is the cell (x=2, y=1), just below the goal (2, 2): start states go row by row
        obs, info = env.reset(options={"start": 7})
        assert info["t"] == 0 and info["start"] == 7 and obs in env.observation_space
        obs, reward, terminated, truncated, info = env.step(0)  # up, onto the goal
        assert (reward, terminated, truncated) == (1.0, True, False)
        steps, episodes, rewards = 0, 0, 0.0
        env.reset(seed=0)
        env.action_space.seed(0)
        while steps < 200:
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            assert obs in env.observation_space
            steps, rewards = steps + 1, rewards + reward
            if terminated or truncated:
                episodes += 1
                env.reset()
        assert episodes >= 2 and rewards >= 1.0, (episodes, rewards)
        assert wait_for(lambda: log.has("driven by an outside controller"), 10), log.lines
        st = agent_status(endpoint)
        assert st is not None and not [ln for ln in st.links if ln.world_id == "g5"]
    finally:
        env.close()
    assert world.poll() is None  # the world waits for its next controller


def test_a_world_an_agent_may_answer_is_refused(procs, endpoint):
    procs.start("world", "gridworld", "--id", "g6", "--param", "size=3", "--connect", endpoint)
    with pytest.raises(RuntimeError, match="sme world ... --external"):
        BusEnv("g6", listen=endpoint, timeout=30)  # the router: the world connects to it
    env = BusEnv("g6", listen=endpoint, timeout=30, force=True)
    try:
        obs, _ = env.reset(options={"start": 0})
        assert obs in env.observation_space and env.step(1)[0] in env.observation_space
    finally:
        env.close()


def test_sme_world_gym_frozenlake_is_learned_over_the_bus(procs, endpoint, monkeypatch):
    """The done-when figure, live: `sme world gym:FrozenLake-v1 --param map_name=8x8 --param
    is_slippery=false` with a stock agent; the reachable cells' embedding reaches Procrustes < 0.1."""
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")  # LSPI's small solves: threads only slow them
    procs.start("agent", "--listen", endpoint, "-q", "--program-param", "generic.samples_per_iteration=400")
    args = ["gym:FrozenLake-v1", "--param", "map_name=8x8", "--param", "is_slippery=false", "--connect", endpoint]
    procs.start("world", *args, "-q")
    seen: list[tuple[str, int, float]] = []

    def learned() -> bool:
        link = world_link(agent_status(endpoint), "FrozenLake-v1")
        if link is None or not link.embedding_version:
            return False
        seen.append((link.program, link.embedding_version, link.last_procrustes_error))
        return link.last_procrustes_error < 0.1

    assert wait_for(learned, 90, every=0.5), seen[-5:]
    assert seen[-1][0] == "generic", seen


def test_a_script_that_never_closes_its_busenv_still_exits(procs, endpoint):
    """The README's BusEnv loop without `env.close()`: the interpreter exits at the end of the script
    (a zenoh session with callbacks used to keep it alive until killed)."""
    import subprocess
    import sys

    procs.start("world", "gridworld", "--id", "g9", "--param", "size=3", "--external", "--connect", endpoint)
    script = (
        "from sensorimotor.worlds.gym_bus import BusEnv\n"
        f"env = BusEnv('g9', listen={endpoint!r}, timeout=30)\n"
        "obs, info = env.reset()\n"
        "for _ in range(20):\n"
        "    obs, r, term, trunc, info = env.step(env.action_space.sample())\n"
        "    if term: obs, info = env.reset()\n"
        "print('done', flush=True)\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "done" in out.stdout, out.stderr


@pytest.mark.parametrize(
    ("world", "wid", "bar"),
    [
        # toy text whose goal is a terminal state (-1 a step): in-process 0.0004 (`sme bench zoo
        # --defaults`; the moves distance and weighted MDS), a bar of 0.001
        ("gym:CliffWalking-v1", "CliffWalking-v1", 0.001),
        # Dict observations (two sensors over the wire), a table of distinct views, traces in the
        # start's frame: in-process 0.000 (`sme bench zoo --defaults --world MiniGrid`), a bar of 0.001
        ("gym:MiniGrid-Empty-8x8-v0", "MiniGrid-Empty-8x8-v0", 0.001),
    ],
)
def test_zoo_worlds_reach_their_in_process_figures_over_the_bus(procs, endpoint, monkeypatch, world, wid, bar):
    if "MiniGrid" in world:
        pytest.importorskip("minigrid")
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    procs.start("agent", "--listen", endpoint, "-q")
    procs.start("world", world, "--connect", endpoint, "-q")
    seen: list[float] = []

    def learned() -> bool:
        link = world_link(agent_status(endpoint), wid)
        if link is None or not link.embedding_version:
            return False
        seen.append(link.last_procrustes_error)
        return link.last_procrustes_error <= bar

    assert wait_for(learned, 120, every=0.5), seen[-5:]


def test_a_world_seen_through_a_camera_is_learned_over_the_bus(procs, endpoint, monkeypatch):
    """Camera frames (uint8 16 x 16 over the wire) and box moves: the agent fits motor coordinates
    and plans over them live. In-process, seed 0: 0.0061 at step 9,603, the one version in 21,000
    steps (`python -m sensorimotor.tools.experiments.gym_embed gym:tests.spot_env:zoo-test/Spot-v0
    --program-param distance=net --steps 21000`); the bar is that + 10 %."""
    import os
    from pathlib import Path

    root = str(Path(__file__).resolve().parents[1])  # where `tests.spot_env` is found by the world process
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
    procs.start("agent", "--listen", endpoint, "-q", "--program-param", "generic.distance=net")
    procs.start("world", "gym:tests.spot_env:zoo-test/Spot-v0", "--connect", endpoint, "-q")
    seen: list[float] = []

    def learned() -> bool:
        link = world_link(agent_status(endpoint), "zoo-test-Spot-v0")
        if link is None or not link.embedding_version:
            return False
        seen.append(link.last_procrustes_error)
        return link.last_procrustes_error <= 0.0067

    assert wait_for(learned, 120, every=0.5), seen[-5:]


def _embeddings_of(procs, endpoint: str, seconds: float) -> list[dict]:
    """Every embedding `sme watch --json` prints over the next `seconds`, collected as they arrive."""
    import json
    import threading

    watch = procs.start("watch", "--json", "--no-events", "--timeout", str(seconds), "--connect", endpoint)
    rows: list[dict] = []

    def follow() -> None:
        for line in watch.stdout:
            rows.append(json.loads(line))

    threading.Thread(target=follow, daemon=True).start()
    return rows


def test_mountaincar_reaches_its_goal_from_the_declared_starts_over_the_bus(procs, endpoint, monkeypatch):
    """Classic control, live: in-process the goal is reached from all 81 declared starts by step
    28,642 (`sme bench zoo --quick --seeds 1 --world gym:MountainCar-v0`; 100 % in every seed of
    the full bench); over the bus the done-when figure, >= 90 %, with the embedding's Procrustes
    error and trustworthiness reported beside it."""
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    procs.start("agent", "--listen", endpoint, "-q")
    rows = _embeddings_of(procs, endpoint, 150)
    procs.start("world", "gym:MountainCar-v0", "--connect", endpoint, "-q")

    def reached() -> bool:
        return any((r.get("metrics") or {}).get("goal_reached_fraction", 0.0) >= 0.9 for r in rows)

    assert wait_for(reached, 150, every=0.5), [(r["step"], r["metrics"]) for r in rows]
    good = next(r for r in rows if r["metrics"]["goal_reached_fraction"] >= 0.9)
    assert good["world"] == "MountainCar-v0" and good["n_points"] == 81
    assert 0.0 <= good["procrustes_error"] <= 1.0 and good["scores"]["trustworthiness"] > 0.5, good


def test_panda_gym_reach_is_learned_over_the_bus(procs, endpoint, monkeypatch):
    """panda-gym, live (shortened: a 3 x 3 x 3 lattice of hand positions, 27 starts): in-process,
    seed 0, the embedding of the hand positions is 0.0283 from its second version on, the goal
    reached from every start (`python -m sensorimotor.tools.experiments.gym_embed
    gym:panda_gym:PandaReach-v3 --param start_grid=3 --program-param distance=net --program-param
    action_scale=0.5 --steps 20000`); over the bus the same within 10 %."""
    pytest.importorskip("panda_gym")
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    agent_args = ["--program-param", "generic.distance=net", "--program-param", "generic.action_scale=0.5"]
    procs.start("agent", "--listen", endpoint, "-q", *agent_args)
    rows = _embeddings_of(procs, endpoint, 300)
    procs.start("world", "gym:panda_gym:PandaReach-v3", "--param", "start_grid=3", "--connect", endpoint, "-q")

    def learned() -> bool:
        return any(r["procrustes_error"] is not None and r["procrustes_error"] <= 0.0283 * 1.1 for r in rows)

    assert wait_for(learned, 300, every=0.5), [(r["step"], r["procrustes_error"], r["metrics"]) for r in rows]
    good = next(r for r in rows if r["procrustes_error"] <= 0.0283 * 1.1)
    assert good["world"] == "PandaReach-v3" and good["n_points"] == 27 and good["dims"] == 3
    assert good["metrics"]["goal_reached_fraction"] == 1.0
