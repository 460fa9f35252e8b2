"""The visual mountain car, staged as ch. 8: geometry first, then control on top of it.

Stage 1, depth from vergence (ch. 7): LSPI over RBF features of the foveated difference learns to
verge (converge/diverge until the perceptual reward); after each LSPI iteration the greedy policy
runs from the n_positions sweep states; once it fixates from all of them, the vergence traces are
embedded in 1-D by classical MDS (indel edit distance, Eq 7.3) and published. The MDS model then
places any new trace without re-embedding: that coordinate is the agent's position.

Stage 2, driving: every car step starts with the eyes parallel; the agent verges (greedy), reads its
position from the trace (refined below one vergence step by the foveal differences one step either
side of the fixation, `substep`), a constant-velocity Kalman filter (filterpy) over that position gives
velocity (`velocity=window`: the slope of the last positions instead), and Sarsa(lambda) with tile coding (alpha 0.3, undiscounted, lambda 0.9) picks reverse,
coast or forward (reward -1 per car step). Every `eval_every` training car steps, learning halts
and the greedy policy is run from the world's fixed evaluation states: the mean steps to goal is
published as an `evaluation` event (the learning curve).

The body changes: after `watch_after` training steps, each training episode reports its
performance, -(car steps) / report_after, when it ends; a trained driver gives up an episode after
`report_after` car steps (a failing body would otherwise show itself only once per 1000-step
timeout). A new camera baseline makes every
trace longer, positions shift, episodes run long: the daemon's detector sees the drop and calls
`on_drop`, and the program first finds which of its actions verge (a body whose actions were
exchanged: `vergence_roles`, 100 steps; `body` maps its own actions to the body's), then relearns
its vergence policy and re-embeds. (Scoring episodes against
the agent's own expectation, read off Sarsa's value, was tried first: Sarsa keeps learning and
lowers its expectation within a few failing episodes, so the surprise faded before a detector saw
it.) The new
embedding is put in the old one's coordinates by a similarity fit over the same start states
(the agent revisits the same places), so what Sarsa learned on top stays valid.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sensorimotor.agent.learners.kalman_velocity import VelocityFilter
from sensorimotor.agent.learners.lspi import LSPI, RBFBasis
from sensorimotor.agent.learners.sarsa_lambda import SarsaLambda, TileCoder
from sensorimotor.agent.learners.window_velocity import WindowVelocity
from sensorimotor.agent.programs.base import Decision, EmbeddingOutput, EventOutput, Program
from sensorimotor.agent.programs.mountaincar_params import MountainCarProgramParams
from sensorimotor.agent.programs.sweep import StartStateSweep
from sensorimotor.agent.programs.vergence import VergencePractice, foveal_difference
from sensorimotor.agent.programs.vergence_reading import VergenceReading
from sensorimotor.agent.programs.vergence_roles import VergenceRoleProbe
from sensorimotor.agent.snapshot import array_or_none
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import EventKind, Observation, Trigger, WorldSpec
from sensorimotor.protocol.params import parse

__all__ = ["MountainCarProgram", "MountainCarProgramParams"]

REVERSE = 2  # the first drive action: the driver's actions are reverse, coast, forward


class MountainCarProgram(Program):
    """The visual mountain car (ch. 8): vergence geometry first, then Sarsa(lambda) driving on it.

    Built by `make_program` as `MountainCarProgram(spec, seed, params=None, **overrides)`; the
    hyperparameters are `MountainCarProgramParams`. Needs 5 discrete actions (converge, diverge,
    reverse, coast, forward), sensors "left" and "right", and spec params `n_positions` (sweep
    states) and `n_eval` (evaluation states).
    """

    name = "mountaincar"
    # one value per training episode, -1 for a failed one. The lengths are skewed (a tail of slow
    # but successful episodes), so the CUSUM of failures rather than of z-scores (`failure`: see
    # agent/detectors/bernoulli_cusum.py and docs/body-changes.md); `rate` serves the detectors of
    # values a user may choose instead (a reference that follows an improving driver in ~20 episodes)
    detector_params = {"failure": -1.0, "shift": 0.3, "h": 8.0, "warmup": 20, "p0_rate": 0.02, "rate": 0.05}

    Params = MountainCarProgramParams
    params: MountainCarProgramParams

    def __init__(
        self, spec: WorldSpec, seed: int = 0, params: MountainCarProgramParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(spec, seed)
        self.params = prm = parse(MountainCarProgramParams, overrides, name=self.name, base=params)
        samples_per_iteration, epsilon, vergence_gamma, ridge = (
            prm.samples_per_iteration,
            prm.epsilon,
            prm.vergence_gamma,
            prm.ridge,
        )
        max_trace = prm.max_trace  # the driver's settings (alpha ... drive_epsilon) are read from self.params
        eval_every, n_eval, watch_after = prm.eval_every, prm.n_eval, prm.watch_after
        report_after, process_var = prm.report_after, prm.process_var
        if not spec.action_space.discrete or spec.action_space.n != 5:
            raise SpecMismatch(
                "mountaincar program needs 5 discrete actions (converge, diverge, reverse, coast, forward)"
            )
        spec.sensor("left"), spec.sensor("right")
        try:
            self.n_positions = int(spec.params.get("n_positions", "0"))
            world_evals = int(spec.params.get("n_eval", "0"))
        except ValueError as e:
            raise SpecMismatch(f"mountaincar spec params n_positions/n_eval must be integers: {e}") from None
        if self.n_positions < 2 or self.n_positions + world_evals > spec.n_starts:
            raise SpecMismatch("mountaincar spec needs n_positions >= 2 sweep states and n_eval evaluation states")
        self.n_eval = world_evals if n_eval is None else min(n_eval, world_evals)
        if eval_every < 1 or max_trace < 2 or samples_per_iteration < 1:
            raise ValueError("eval_every, max_trace and samples_per_iteration must be positive")
        self.max_trace = max_trace
        if report_after < 1:
            raise ValueError("report_after must be >= 1")
        self.eval_every, self.watch_after, self.process_var = eval_every, watch_after, process_var
        self.report_after = report_after
        self.lspi = LSPI(
            RBFBasis(tuple(float(c) for c in np.linspace(0.0, 0.3, 13)), 0.025, 2), gamma=vergence_gamma, ridge=ridge
        )
        self.sarsa: SarsaLambda | None = None
        self.practice = VergencePractice(self.lspi, self.rng, samples_per_iteration, epsilon)
        self.phase = "explore"
        self._explore_len = 0
        self._sweep = StartStateSweep(self.n_positions, max_trace)
        try:
            k_max = int(spec.params["max_vergence"]) if "max_vergence" in spec.params else None
        except ValueError as e:
            raise SpecMismatch(f"mountaincar spec param max_vergence must be an integer: {e}") from None
        #: the embedding and the reading of positions from it (sub-step, recalled readings)
        self.reading = VergenceReading(k_max, prm.recall_check)
        self._verge: dict[float, int] = {}  # the greedy vergence action per foveal difference, while LSPI is fixed
        # driving
        self.training_steps = 0
        self.episodes = 0
        self._kf: VelocityFilter | WindowVelocity | None = None
        self._trace: list[int] | None = None  # the vergence trace being read, None between readings
        self._last_drive = False
        self._s: np.ndarray | None = None
        self._a = 0
        self._ep_steps = 0
        self._watching = False
        self._perf: float | None = None
        self._eval_i = 0
        self._eval_steps: list[int] = []
        self._eval_reached: list[bool] = []
        self._eval_traces: list[list[int]] = []  # drive actions of each evaluation episode (policy maps)
        self._eval_trace: list[int] = []
        self.curve: list[tuple[int, float]] = []
        self.episode_log: list[tuple[int, int]] = []  # (training steps at the end, car steps) per training episode
        self.relearn_at: int | None = None
        #: the body's action for each of the program's (converge, diverge, reverse, coast, forward);
        #: found again by a probe when the actions were exchanged
        self.body: tuple[int, ...] = tuple(range(5))
        self._probe: VergenceRoleProbe | None = None
        self._probe_first = False  # the probe's first step (a reset) is still to be sent

    # stage 1: vergence ---------------------------------------------------------------------------
    def _explore(self, obs: Observation, d: float) -> Decision:
        if self.practice.observe(obs, d, obs.reward > 0, self.emit):
            self.phase = "sweep"
            self._sweep = StartStateSweep(self.n_positions, self.max_trace)
            return self._sweep.begin()
        if obs.reward > 0 or obs.done or self._explore_len >= self.max_trace:
            self._explore_len = 0
            return Decision(reset=True, start=-1)
        self._explore_len += 1
        return Decision((float(self.practice.choose(d)),))

    def _sweeping(self, obs: Observation) -> Decision:
        dec = self._sweep.step(
            obs, lambda o, tr: self.lspi.greedy(foveal_difference(o)), stop=lambda o, tr: o.reward > 0
        )
        if not self._sweep.finished:
            return dec
        if self._sweep.rewarded < self.n_positions:
            self.phase = "explore"  # not yet fixating from everywhere: more samples, another iteration
            return dec
        self._embed(obs.step)
        self.phase = "drive"
        self._start_training_episode()
        return Decision(reset=True, start=-1)

    def _embed(self, step: int) -> None:
        """Embed the sweep's traces and publish them; the first embedding makes the driver over its
        span, a later one (after a drop) is put in the first one's coordinates."""
        traces = [list(t) for t in self._sweep.traces]
        coords, eigenvalues, first = self.reading.embed(traces)
        if first:
            self._make_driver(float(coords.min()), float(coords.max()))
        self._verge = {}
        n = len(traces)
        self.emit(
            EmbeddingOutput(
                Trigger.POLICY_ITERATION if first else Trigger.RELEARNED,
                tuple(range(n)),
                coords,
                eigenvalues,
                step,
                {
                    "lspi_iterations": float(self.lspi.iterations),
                    "mean_trace_length": float(np.mean([len(t) for t in traces])),
                },
                iteration=self.lspi.iterations,
                drop_step=None if first else self.relearn_at,
            )
        )

    def position(self, trace: list[int]) -> float:
        """The agent's position: the embedding coordinate of a vergence trace (out of sample)."""
        return self.reading.position(trace)

    @property
    def landmarks(self) -> list[list[int]]:
        """The sweep's vergence traces the embedding was made from."""
        return self.reading.landmarks

    def _move_eyes(self, a: int) -> Decision:
        self.reading.move(a)
        return Decision((float(a),))

    # stage 2: driving ----------------------------------------------------------------------------
    def _make_driver(self, lo: float, hi: float) -> None:
        prm = self.params
        margin = 0.1 * (hi - lo)
        vmax = self.params.velocity_range * (hi - lo)
        coder = TileCoder([lo - margin, -vmax], [hi + margin, vmax], tiles=prm.tiles, n_tilings=prm.n_tilings)
        self.sarsa = self._sarsa(coder, int(self.rng.integers(2**31)))
        self._kf = self._filter()

    def _sarsa(self, coder: TileCoder, seed: int) -> SarsaLambda:
        prm = self.params
        return SarsaLambda(
            coder, 3, alpha=prm.alpha, gamma=prm.gamma, lam=prm.lam, epsilon=prm.drive_epsilon, seed=seed
        )

    def _filter(self) -> VelocityFilter | WindowVelocity:
        """The velocity estimate (`velocity`). The Kalman filter's measurement noise: a position is
        quantised to one vergence step (uniform, variance q^2/12), or read below one step (`substep`:
        a tenth of a step's standard deviation, as measured along the track)."""
        if self.params.velocity == "window":
            return WindowVelocity(self.params.velocity_window)
        q = self.reading.quantum
        return VelocityFilter(
            measurement_var=q**2 / (100 if self.params.substep else 12), process_var=self.process_var * q**2
        )

    @property
    def evaluation_steps(self) -> tuple[int, ...]:
        """Car steps to the goal from each evaluation state, in the world's order: the evaluation in
        progress so far, or the last one (the cap where the goal was not reached)."""
        return tuple(self._eval_steps)

    @property
    def evaluating(self) -> bool:
        """Whether learning is halted for an evaluation run."""
        return self.phase == "evaluate"

    def _start_training_episode(self) -> None:
        self._trace, self._last_drive, self._s, self._ep_steps, self._watching = None, False, None, 0, False

    def _drive(self, obs: Observation) -> Decision:
        """A step of a car step: verge (greedy) from parallel eyes until the perceptual goal, look
        either side (`substep`), read the position, and drive; or recall the reading of this view."""
        r = self.reading
        if obs.t == 0:
            self._trace, self._s, self._ep_steps, self._last_drive = [], None, 0, False
        elif self._last_drive:
            self._last_drive = False
            if obs.done:
                return self._episode_over(obs)
            self._trace = []
        if self._trace is None:
            self._trace = []
        if not self._trace:
            r.begin()
        if r.goal is not None and obs.done:  # not from this world (a vergence step never ends it)
            r.abandon()
            return self._episode_over(obs)
        if r.goal is not None:  # looking either side of the fixated vergence
            r.ds[r.k] = foveal_difference(obs)
            aside = r.look_aside()
            if aside is not None:
                return self._move_eyes(aside)
        elif (
            not (obs.reward > 0 and self._trace) and len(self._trace) < self.max_trace and not (obs.t > 0 and obs.done)
        ):
            if not self._trace:
                p = r.recalled(obs)
                if p is not None:
                    self._trace = None
                    return self._car_step(p)
            d = r.ds[r.k] = foveal_difference(obs)
            a = self._verge.get(d)
            if a is None:
                a = self._verge[d] = self.lspi.greedy(d)
            self._trace.append(a)
            return self._move_eyes(a)
        elif obs.done:  # the world ended the episode while we were reading (its car-step limit)
            r.view = r.checking = None
            return self._episode_over(obs)
        elif self.params.substep and obs.reward > 0:
            r.goal = r.k
            r.ds[r.k] = foveal_difference(obs)
            aside = r.look_aside()
            if aside is not None:
                return self._move_eyes(aside)
        p = r.position(self._trace)
        if r.goal is not None:
            p += r.substep() * r.slope
            r.goal = None
        r.remember(p)
        self._trace = None
        return self._car_step(p)

    def _car_state(self, p: float, first: bool) -> np.ndarray:
        """The state Sarsa drives on: the filtered position and its velocity (Kalman filter)."""
        kf = self._kf
        assert kf is not None, "the driver is made with the first embedding"
        if first:
            kf.reset(p)
        pos, vel = kf.update(p)
        return np.array([pos, vel])

    def _car_step(self, p: float) -> Decision:
        """One car step from position `p`: Sarsa(lambda) picks (and, training, learns) the drive."""
        sarsa = self.sarsa
        assert sarsa is not None, "the driver is made with the first embedding"
        s = self._car_state(p, self._s is None)
        if self.evaluating:
            a = sarsa.greedy(s)
            self._eval_trace.append(a)
        else:
            a = sarsa.act(s)
            if self._s is None:
                sarsa.begin_episode()
                self._watching = self.training_steps >= self.watch_after
            else:
                sarsa.learn_one(self._s, self._a, -1.0, s, a)
        self._s, self._a = s, a
        self._ep_steps += 1
        self._last_drive = True
        if not self.evaluating:
            self.training_steps += 1
            if self._watching and self._ep_steps >= self.report_after:
                # a trained driver gives up an episode this long: it is reported and a new one
                # begins, so a failing body shows itself every `report_after` steps, not once per timeout
                return self._end_training_episode(reached=False)
        return Decision((float(REVERSE + a),))

    def _episode_over(self, obs: Observation) -> Decision:
        reached = obs.reward > 0
        if self.evaluating:
            self._eval_steps.append(self._ep_steps)
            self._eval_reached.append(reached)
            self._eval_traces.append(self._eval_trace)
            self._eval_trace = []
            self._eval_i += 1
            if self._eval_i < self.n_eval:
                return self._eval_reset()
            mean = float(np.mean(self._eval_steps))
            self.curve.append((self.training_steps, mean))
            failed = int(sum(not r for r in self._eval_reached))
            self.emit(
                EventOutput(
                    EventKind.EVALUATION,
                    f"mean steps to goal {mean:.1f} from {self.n_eval} states after "
                    f"{self.training_steps} training steps",
                    obs.step,
                    {"steps_to_goal": mean, "training_steps": float(self.training_steps), "failures": float(failed)},
                )
            )
            if self.params.policy_map:
                ids = tuple(range(self.n_positions, self.n_positions + len(self._eval_traces)))
                self.emit_policy_map(self._eval_traces, ids, obs.step, self.params.policy_map)
            self.phase = "drive"
            self._start_training_episode()
            return Decision(reset=True, start=-1)
        if reached and self._s is not None:
            assert self.sarsa is not None, "a state was driven from, so the driver exists"
            self.sarsa.learn_one(self._s, self._a, -1.0, self._s, None)
        return self._end_training_episode(reached)

    def _end_training_episode(self, reached: bool) -> Decision:
        self.episodes += 1
        self.episode_log.append((self.training_steps, self._ep_steps))
        if self._watching and self._ep_steps > 0:
            self._report(self._ep_steps, reached)
        self._start_training_episode()
        if self.n_eval and self.training_steps // self.eval_every > len(self.curve):
            return self._begin_evaluation()
        return Decision(reset=True, start=-1)

    def _report(self, steps: int, reached: bool) -> None:
        """Performance of this episode, once: -(car steps) / report_after, in [-1, 0); -1 for an
        episode that failed (given up, or ended by the world before the goal)."""
        self._perf = -min(steps, self.report_after - 1) / self.report_after if reached else -1.0
        self._watching = False

    def _begin_evaluation(self) -> Decision:
        self.phase = "evaluate"
        self._eval_i, self._eval_steps, self._eval_reached = 0, [], []
        self._eval_traces, self._eval_trace = [], []
        return self._eval_reset()

    def _eval_reset(self) -> Decision:
        self._start_training_episode()
        self._eval_trace = []
        return Decision(reset=True, start=self.n_positions + self._eval_i)

    # Program interface ---------------------------------------------------------------------------
    def act(self, obs: Observation) -> Decision:
        """Dispatch to the current stage: explore, sweep (then embed), or drive/evaluate (their
        actions are the program's own, sent as the body's: `body`), or find which actions verge."""
        if self.phase == "probe":
            return self._probing(obs)
        if self.phase == "explore":
            dec = self._explore(obs, foveal_difference(obs))
        elif self.phase == "sweep":
            dec = self._sweeping(obs)
        else:
            dec = self._drive(obs)
        if dec.values and self.body != tuple(range(5)):
            return Decision((float(self.body[int(dec.values[0])]),), dec.reset, dec.start)
        return dec

    def _probing(self, obs: Observation) -> Decision:
        """A step of the vergence role probe; when done, the roles found and vergence relearned."""
        assert self._probe is not None
        if self._probe_first:
            self._probe_first = False
            return self._probe.begin()
        dec = self._probe.step(obs)
        if dec is not None:
            return dec
        found = self._probe.roles()
        self._probe = None
        if found is None:
            self.emit(
                EventOutput(
                    EventKind.POLICY_ITERATION,
                    "no pair of actions turns the eyes and back: vergence is relearned with the actions as they were",
                    obs.step,
                    reason="action_roles",
                )
            )
        elif found[:2] != self.body[:2]:
            names = ("converge", "diverge", "reverse", "coast", "forward")
            said = ", ".join(f"{n} {a}" for n, a in zip(names, found, strict=True))
            self.emit(
                EventOutput(
                    EventKind.POLICY_ITERATION,
                    f"the actions that verge are now {found[0]} and {found[1]}, found by the views they give "
                    f"(the body's actions: {said})",
                    obs.step,
                    reason="action_roles",
                )
            )
            self.body = found
        self.lspi.reset()
        self.practice.reset()
        self._verge = {}
        self.phase, self._explore_len = "explore", 0
        return Decision(reset=True, start=-1)

    def performance(self, obs: Observation) -> float | None:
        """-(car steps) / report_after of a training episode that just ended, once; else None."""
        out, self._perf = self._perf, None
        return out

    def on_drop(self, step: int) -> None:
        """The body changed: find which actions verge (`vergence_roles`), relearn vergence (LSPI
        from scratch) and re-embed; Sarsa is kept."""
        if self.phase not in ("drive", "evaluate"):
            return
        self.relearn_at = step
        self.lspi.reset()
        self._verge = {}
        self.reading.forget()
        self.practice.reset()
        self.phase, self._explore_len = "probe", 0
        # the first of the world's evaluation states: fixed, the car moving
        self._probe = VergenceRoleProbe(5, start=self.n_positions if self.spec.n_starts > self.n_positions else -1)
        self._probe_first = True
        self.emit(EventOutput(EventKind.RELEARNING, "vergence policy relearned from scratch, then re-embedded", step))

    # saved state ---------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """Everything stage 1 and 2 learned, and where the program is. The driver (tile coder bounds,
        Sarsa, Kalman filter) exists once the first embedding is made; it is saved with the bounds
        and seed it was built from, so `restore` rebuilds it the same way."""
        driver = None
        if self.sarsa is not None:
            assert self._kf is not None, "Sarsa and the velocity filter are made together"
            driver = {
                "low": self.sarsa.coder.low.copy(),
                "high": self.sarsa.coder.high.copy(),
                "sarsa": self.sarsa.state(),
                "filter": self._kf.state(),
            }
        return {
            **super().state(),
            **self.reading.state(),
            "lspi": self.lspi.state(),
            "practice": self.practice.state(),
            "phase": self.phase,
            "explore_len": self._explore_len,
            "sweep": self._sweep.state(),
            "verge": [[d, a] for d, a in self._verge.items()],
            "training_steps": self.training_steps,
            "episodes": self.episodes,
            "driver": driver,
            "trace": None if self._trace is None else list(self._trace),
            "last_drive": self._last_drive,
            "s": array_or_none(self._s),
            "a": self._a,
            "ep_steps": self._ep_steps,
            "watching": self._watching,
            "perf": self._perf,
            "eval_i": self._eval_i,
            "eval_steps": list(self._eval_steps),
            "eval_reached": list(self._eval_reached),
            "eval_traces": [list(t) for t in self._eval_traces],
            "eval_trace": list(self._eval_trace),
            "curve": [list(c) for c in self.curve],
            "episode_log": [list(e) for e in self.episode_log],
            "relearn_at": self.relearn_at,
            "body": list(self.body),
            "probe": None if self._probe is None else self._probe.state(),
            "probe_first": self._probe_first,
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a program built with the same spec and params; the
        driver is rebuilt from its saved bounds and seed."""
        super().restore(state)
        self.lspi.restore(state["lspi"])
        self.practice.restore(state["practice"])
        self.phase, self._explore_len = str(state["phase"]), int(state["explore_len"])
        self._sweep = StartStateSweep(self.n_positions, self.max_trace)
        self._sweep.restore(state["sweep"])
        trace = state["trace"]
        self._trace = None if trace is None else [int(a) for a in trace]
        self.reading.restore(state, self._trace)  # before the driver: its filter is in the reading's units
        self._verge = {float(d): int(a) for d, a in state["verge"]}
        self.training_steps, self.episodes = int(state["training_steps"]), int(state["episodes"])
        driver = state["driver"]
        if driver is None:
            self.sarsa, self._kf = None, None
        else:
            coder = TileCoder(
                np.array(driver["low"]),
                np.array(driver["high"]),
                tiles=self.params.tiles,
                n_tilings=self.params.n_tilings,
            )
            self.sarsa = self._sarsa(coder, int(driver["sarsa"]["seed"]))
            self.sarsa.restore(driver["sarsa"])
            self._kf = self._filter()
            self._kf.restore(driver["filter"])
        self._last_drive, self._s = bool(state["last_drive"]), array_or_none(state["s"])
        self._a, self._ep_steps, self._watching = int(state["a"]), int(state["ep_steps"]), bool(state["watching"])
        self._perf = None if state["perf"] is None else float(state["perf"])
        self._eval_i = int(state["eval_i"])
        self._eval_steps = [int(n) for n in state["eval_steps"]]
        self._eval_reached = [bool(r) for r in state["eval_reached"]]
        self._eval_traces = [[int(a) for a in t] for t in state.get("eval_traces", [])]
        self._eval_trace = [int(a) for a in state.get("eval_trace", [])]
        self.curve = [(int(n), float(m)) for n, m in state["curve"]]
        self.episode_log = [(int(n), int(k)) for n, k in state["episode_log"]]
        self.relearn_at = None if state["relearn_at"] is None else int(state["relearn_at"])
        body = tuple(int(a) for a in state.get("body", range(5)))
        if sorted(body) != list(range(5)):
            raise ValueError(f"saved body actions {body} are not an order of the 5 actions")
        self.body, self._probe_first = body, bool(state.get("probe_first", False))
        probe = state.get("probe")
        self._probe = None
        if probe is not None:
            self._probe = VergenceRoleProbe(5, start=int(probe.get("start", -1)))
            self._probe.restore(probe)
        if (self.phase == "probe") != (self._probe is not None):
            raise ValueError("a mountaincar state in phase probe needs its probe, and only then")

    def world_restarted(self) -> None:
        """Drop the pending vergence sample and restart the trace and episode in progress."""
        self.practice.reset()
        self._sweep.interrupted()
        if self._probe is not None:
            self._probe.interrupted()
        self.reading.abandon()
        self._start_training_episode()
