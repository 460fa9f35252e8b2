"""The start states and truth of a Gymnasium world, by family: the environment's own hook, MiniGrid
(every free cell), panda-gym reach tasks (a lattice of hand positions by inverse kinematics),
classic control (`STATE_GRIDS`), toy-text tables (every reachable state); see `worlds.gym_world`."""

import itertools
import logging
from collections import deque
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from sensorimotor.protocol.params import ParamError
from sensorimotor.worlds.gym_hooks import _hooked
from sensorimotor.worlds.gym_setup import STATE_GRIDS, GymWorldParams, StateGrid

log = logging.getLogger("sme.world")


class GymStarts:
    """The start-state half of `GymWorld`: fills `_starts`, `_truth` (and `_raw`), `_set_start` and
    `_family` from what the environment offers."""

    env: Any
    u: Any
    env_id: str
    seed: int
    params: GymWorldParams
    _starts: list[Any]
    _truth: np.ndarray | None
    _raw: np.ndarray | None
    _set_start: Callable[[Any], Any] | None
    _family: str
    _full_view: Any
    _goal: np.ndarray
    _reset_info: dict[str, Any]

    def _declare_starts(self) -> str:
        """Fill the start states, their truth and the setter; return how (for the spec and logs)."""
        u: Any = self.u  # the environment's own attributes (P, s, state) are not typed
        _, self._reset_info = self.env.reset(seed=self.seed)
        starts = _hooked(self.env, "sme_start_states")
        if starts is not None and _hooked(self.env, "sme_reset_to") is not None:
            return self._hook_starts()
        if type(u).__module__.startswith("minigrid"):
            self._family = "minigrid"
            return self._minigrid_starts()
        if type(u).__module__.startswith("panda_gym") and hasattr(u, "robot") and hasattr(u, "task"):
            self._family = "panda"
            return self._panda_starts()
        grid = STATE_GRIDS.get(type(u).__name__)
        if grid is not None and hasattr(u, "state"):
            return self._grid_starts(grid)
        if hasattr(u, "P") and isinstance(self.env.observation_space, spaces.Discrete):
            return self._table_starts()
        return "its state cannot be set (add the hook: see EmbeddableEnv)"

    def _hook_starts(self) -> str:
        self._family = "hook"
        self._starts = list(_hooked(self.env, "sme_start_states")())
        truth = _hooked(self.env, "sme_truth")
        if truth is not None:
            t = np.asarray(truth(), dtype=np.float64)
            if t.ndim != 2 or t.shape[0] != len(self._starts):
                raise ParamError(f"gym:{self.env_id}: sme_truth() gives {t.shape} for {len(self._starts)} start states")
            self._truth = t
        reset_to = _hooked(self.env, "sme_reset_to")
        self._set_start = lambda start: reset_to(start)
        return f"{len(self._starts)} start states from the environment's own hook"

    def _wants_full_view(self) -> bool:
        """MiniGrid: serve the whole grid (`view`; auto: when the room inside the walls is longer than
        the agent sees ahead, `agent_view_size` - 1 cells: then cells far from every wall look alike).
        The whole grid costs a quarter of the world's step rate (it is encoded at every step)."""
        if self.params.view != "auto":
            return self.params.view == "full"
        u: Any = self.u
        ahead = int(getattr(u, "agent_view_size", 7)) - 1
        return max(int(getattr(u, "width", 0)), int(getattr(u, "height", 0))) - 2 > ahead

    def _minigrid_starts(self) -> str:
        u: Any = self.u
        cells = [
            (x, y)
            for y in range(1, u.height - 1)
            for x in range(1, u.width - 1)
            if u.grid.get(x, y) is None
            or u.grid.get(x, y).can_overlap()
            and u.grid.get(x, y).type != "goal"
            and u.grid.get(x, y).type != "lava"
        ]
        self._starts = [(c, d) for c in cells for d in range(self.params.headings)]
        self._truth = np.array([c for c, _ in self._starts], dtype=np.float64)

        def set_state(start: Any) -> Any:
            (x, y), d = start
            u.agent_pos, u.agent_dir = (int(x), int(y)), int(d)
            obs = u.gen_obs()
            return obs if self._full_view is None else self._full_view.observation(obs)

        self._set_start = set_state
        return (
            f"{len(self._starts)} starts: {len(cells)} free cells x {self.params.headings} heading(s), truth the cell"
        )

    def _panda_starts(self) -> str:
        """A cube lattice of hand positions as wide as the task's goal range, centred on the held
        target and lifted so that its lowest layer clears the table by the reach tolerance (a hand
        resting on the table moves by contact). Contacts are made repeatable: pybullet orders the
        overlapping pairs of its broadphase by the history of the simulation unless told to sort
        them, so the same moves from the same start pressed the hand on the table differently from
        one episode to the next (`sensorimotor.tools.experiments.repeatable` measures it)."""
        u: Any = self.u
        u.sim.physics_client.setPhysicsEngineParameter(deterministicOverlappingPairs=1)
        lo, hi = np.asarray(u.task.goal_range_low, float), np.asarray(u.task.goal_range_high, float)
        clearance = float(getattr(u.task, "distance_threshold", 0.05))
        side = hi - lo
        centre = (lo + hi) / 2
        centre[2] = lo[2] + clearance + side[2] / 2
        self._goal = centre
        n = min(self.params.start_grid, 4)
        axes = [np.linspace(c - s / 2, c + s / 2, n) for c, s in zip(centre, side, strict=True)]
        points = [np.array(p) for p in itertools.product(*axes)]
        down = np.array([1.0, 0.0, 0.0, 0.0])  # the hand orientation panda-gym's hand control keeps
        angles = []
        truth = []
        for p in points:
            u.reset(seed=self.seed)
            for _ in range(8):  # pybullet's IK is one linearisation: repeat it from where it got to
                q = u.robot.inverse_kinematics(link=u.robot.ee_link, position=p, orientation=down)
                u.robot.set_joint_angles(q)
                if np.linalg.norm(u.robot.get_ee_position() - p) < 1e-3:
                    break
            angles.append(np.asarray(q, dtype=np.float64))
            truth.append(np.asarray(u.robot.get_ee_position(), dtype=np.float64))
        self._starts = angles
        self._truth = np.array(truth)

        def set_state(q: np.ndarray) -> Any:
            u.robot.set_joint_angles(q)
            u.task.goal = self._goal.copy()
            u.sim.set_base_pose("target", self._goal, np.array([0.0, 0.0, 0.0, 1.0]))
            return u._get_obs()

        self._set_start = set_state
        return (
            f"{len(points)} hand positions on a {n}x{n}x{n} lattice (inverse kinematics), "
            f"target held at its centre {np.round(self._goal, 3).tolist()}"
        )

    def _panda_frame(self, n: int) -> np.ndarray:
        """panda-gym's camera (yaw 45, pitch -30, field of view 60) aimed at the held target from
        `camera_distance`, without shadows: pybullet's TinyRenderer spends about 40 % of a frame on them
        (`sme bench world` measures the frame rate), and they move with the arm, not the hand."""
        import pybullet as p

        pc = self.u.sim.physics_client
        view = pc.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=self._goal.tolist(),
            distance=self.params.camera_distance,
            yaw=45,
            pitch=-30,
            roll=0,
            upAxisIndex=2,
        )
        proj = pc.computeProjectionMatrixFOV(fov=60, aspect=1.0, nearVal=0.1, farVal=100.0)
        _, _, rgba, _, _ = pc.getCameraImage(
            n, n, view, proj, shadow=False, renderer=p.ER_TINY_RENDERER, flags=p.ER_NO_SEGMENTATION_MASK
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(n, n, 4)[..., :3]

    def _grid_starts(self, grid: StateGrid) -> str:
        n = self.params.start_grid
        axes = [np.linspace(c[0], c[1], n, endpoint=c[2]) for c in grid.components if isinstance(c, tuple)]
        points = np.array(list(itertools.product(*axes)), dtype=np.float64)
        states = []
        for p in points:
            vals, it = [], iter(p)
            for c in grid.components:
                vals.append(next(it) if isinstance(c, tuple) else float(c))
            states.append(np.array(vals, dtype=np.float64))
        self._starts = states
        self._raw = points
        lo, hi = points.min(axis=0), points.max(axis=0)
        self._truth = (points - lo) / np.where(hi > lo, hi - lo, 1.0)
        u: Any = self.env.unwrapped  # the environment's own attributes (P, s, state) are not typed

        def set_state(state: np.ndarray) -> Any:
            u.state = np.array(state, dtype=np.float64)
            return u._get_ob() if hasattr(u, "_get_ob") else np.array(u.state, dtype=np.float32)

        self._set_start = set_state
        return f"{len(states)} starts on a {n} x {n} grid of ({', '.join(grid.names)})"

    def _table_starts(self) -> str:
        u: Any = self.env.unwrapped  # the environment's own attributes (P, s, state) are not typed
        P: Mapping[int, Mapping[int, list]] = u.P
        init = np.flatnonzero(np.asarray(getattr(u, "initial_state_distrib", []), dtype=float) > 0).tolist()
        if not init:
            init = [int(self.env.reset(seed=self.seed)[0])]
        ended = {int(nxt) for s in P for a in P[s] for (_, nxt, _, term) in P[s][a] if term}
        seen, todo = set(init), deque(init)
        while todo:
            s = todo.popleft()
            if s in ended:
                continue
            for a in P[s]:
                for prob, nxt, _, _ in P[s][a]:
                    if prob > 0 and int(nxt) not in seen:
                        seen.add(int(nxt))
                        todo.append(int(nxt))
        self._starts = sorted(s for s in seen if s not in ended)
        if hasattr(u, "ncol") and hasattr(u, "nrow"):
            self._truth = np.array([divmod(s, int(u.ncol)) for s in self._starts], dtype=np.float64)
            what = "(row, col)"
        elif hasattr(u, "shape"):
            self._truth = np.array([np.unravel_index(s, tuple(u.shape)) for s in self._starts], dtype=np.float64)
            what = "(row, col)"
        elif hasattr(u, "decode"):
            self._truth = np.array([list(u.decode(s)) for s in self._starts], dtype=np.float64)
            what = "decoded state"
        else:
            what = "no truth"

        def set_state(s: int) -> Any:
            u.s = int(s)
            if hasattr(u, "lastaction"):
                u.lastaction = None
            return int(s)

        self._set_start = set_state
        return f"{len(self._starts)} reachable non-terminal states, truth {what}"
