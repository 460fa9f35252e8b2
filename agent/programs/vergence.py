"""The vergence program (ch. 7): LSPI learns to verge on what the fovea sees; the lengths of the
resulting vergence traces are a 1-D map of depth.

State feature: the foveated left/right difference d = mean |f_l - f_r| (Eq 7.2), which the agent
computes from its two foveae (Gaussian RBFs of d, one block per action). Exploration is
epsilon-greedy around the current policy. After every `samples_per_iteration` samples, one LSPI
iteration, then the greedy policy runs from every start state; traces are action sequences, the
trace distance is the indel edit distance (for pure converge traces: the difference of their
lengths, Eq 7.3), classical MDS to 1-D.

Which policy's map is published (`accept`, on by default): a sweep is scored without truth by the
fraction of its traces that reached the goal and their mean length (`acceptance.sweep_score`); a
policy that does worse than the accepted one is not embedded, and the accepted policy's map stays
the published one (an event says so; LSPI keeps iterating). LSPI over the foveal difference alone
can fall from a perfect policy to one that oscillates from a few starts (d is aliased: one d at many vergences);
one trace that never reaches the goal is 100 actions long and throws the whole 1-D map off
(Procrustes 0.5-1.0 instead of 0.002 on the stereo pair), so that map is not the agent's best.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, trace_distances
from sensorimotor.agent.learners.lspi import LSPI, RBFBasis
from sensorimotor.agent.programs.acceptance import Score, compare, sweep_score
from sensorimotor.agent.programs.background import Background
from sensorimotor.agent.programs.base import Decision, EmbeddingOutput, EventOutput, Program
from sensorimotor.agent.programs.sweep import StartStateSweep
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import EventKind, Observation, Trigger, WorldSpec
from sensorimotor.protocol.params import option, parse


def foveal_difference(obs: Observation) -> float:
    """d = mean |f_l - f_r| (Eq 7.2): how far the two foveae are from seeing the same thing."""
    left = obs.tensors["left"].astype(np.float64, copy=False)
    right = obs.tensors["right"].astype(np.float64, copy=False)
    if left.shape != right.shape:
        raise SpecMismatch(f"left {left.shape} and right {right.shape} foveae differ in shape")
    return float(np.abs(left - right).mean())


def lspi_job(
    centres: list[float],
    width: float,
    gamma: float,
    ridge: float,
    capacity: int,
    samples: dict[str, Any],
    n_actions: int = 2,
) -> dict[str, Any]:
    """One LSPI iteration (RBF features of the foveal difference, 2 actions) over a snapshot of the
    samples: the new weights and their change. A pure function, run off the act path."""
    lspi = LSPI(
        RBFBasis(tuple(float(c) for c in centres), float(width), n_actions),
        gamma=gamma,
        ridge=ridge,
        capacity=capacity,
    )
    lspi.restore(samples)
    change = lspi.iterate()
    return {"w": lspi.w, "change": change}


def embed_job(traces: list[list[int]]) -> dict[str, Any]:
    """Edit distances between vergence traces and classical MDS to 1-D (depth). A pure function,
    run off the act path."""
    mds = classical_mds(trace_distances(traces, kind="edit", substitution_cost=2), 1)
    return {"coordinates": mds.coordinates, "eigenvalues": mds.eigenvalues}


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


class VergencePractice:
    """Epsilon-greedy vergence practice feeding LSPI, one LSPI iteration (reported as an event)
    after every `samples_per_iteration` samples: the learning half of the vergence program, which
    the mountain-car program runs as its first stage."""

    def __init__(self, lspi: LSPI, rng: np.random.Generator, samples_per_iteration: int, epsilon: float) -> None:
        if samples_per_iteration < 1 or not 0 <= epsilon <= 1:
            raise ValueError("samples_per_iteration must be >= 1 and epsilon in [0, 1]")
        self.lspi, self.rng = lspi, rng
        self.samples_per_iteration, self.epsilon = samples_per_iteration, epsilon
        self.reset()

    def reset(self) -> None:
        """Drop the pending step and the count of samples since the last iteration."""
        self.new_samples = 0
        self._prev: tuple[float, int] | None = None

    def observe(
        self,
        obs: Observation,
        d: float,
        terminal: bool,
        emit: Callable[[EventOutput], None],
        background: Background | None = None,
    ) -> bool:
        """Learn from the step that led to `obs`; True when an LSPI iteration has just run. With a
        `background`, the iteration is started there as job "lspi" instead (False), and the owner
        hands its result to `iterated` when it is swapped in."""
        if obs.t > 0 and self._prev is not None:
            self.lspi.learn_one(self._prev[0], self._prev[1], obs.reward, d, terminal)
            self.new_samples += 1
        self._prev = None
        if self.new_samples < self.samples_per_iteration:
            return False
        if background is not None:
            if not background.pending("lspi"):
                self.new_samples = 0
                basis = self.lspi.basis
                assert isinstance(basis, RBFBasis)
                background.submit(
                    "lspi",
                    lspi_job,
                    centres=[float(c) for c in basis.centres],
                    width=float(basis.width),
                    gamma=self.lspi.gamma,
                    ridge=self.lspi.ridge,
                    capacity=self.lspi.capacity,
                    samples=self.lspi.samples(),
                    n_actions=basis.n_actions,
                )
            return False
        self.new_samples = 0
        return self.iterated({"w": None, "change": self.lspi.iterate()}, obs.step, emit)

    def iterated(self, result: dict[str, Any], step: int, emit: Callable[[EventOutput], None]) -> bool:
        """An LSPI iteration's result (`lspi_job`; w None: already in place): report it; True."""
        if result["w"] is not None:
            self.lspi.w = np.asarray(result["w"], dtype=np.float64)
            self.lspi.iterations += 1
        emit(
            EventOutput(
                EventKind.POLICY_ITERATION,
                f"LSPI iteration {self.lspi.iterations}",
                step,
                {"weight_change": float(result["change"])},
            )
        )
        return True

    def state(self) -> dict[str, Any]:
        """Samples since the last iteration and the step awaiting its outcome (the LSPI and the
        generator belong to the owner, which saves them)."""
        return {"new_samples": self.new_samples, "prev": None if self._prev is None else list(self._prev)}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot."""
        self.new_samples = int(state["new_samples"])
        prev = state["prev"]
        self._prev = None if prev is None else (float(prev[0]), int(prev[1]))

    def choose(self, d: float) -> int:
        """An epsilon-greedy vergence action for difference `d` (remembered for `observe`)."""
        n = self.lspi.basis.n_actions if isinstance(self.lspi.basis, RBFBasis) else 2
        a = int(self.rng.integers(n)) if self.rng.random() < self.epsilon else self.lspi.greedy(d)
        self._prev = (d, a)
        return a


@dataclass(frozen=True)
class VergenceProgramParams:
    """Hyperparameters of the vergence program (ch. 7)."""

    samples_per_iteration: int = option(300, "new samples between LSPI iterations", min=1)
    epsilon: float = option(0.2, "exploration: probability of a random vergence action", min=0.0, max=1.0)
    gamma: float = option(0.95, "LSPI discount", min=0.0, max=1.0)
    ridge: float = option(1e-3, "LSPI ridge regulariser", min=0.0)
    max_trace: int = option(100, "longest greedy trace recorded from a start state", min=1)
    centres: tuple[float, ...] = option(
        tuple(float(c) for c in np.linspace(0.0, 0.2, 11)), "RBF centres over the foveal difference d"
    )
    width: float = option(0.02, "RBF width")
    learn_lag: int = option(
        50,
        "acts between the start of a background learning job (LSPI, MDS) and the act that uses it "
        "(the LSPI has 24 features: a few ms; a short lag keeps the practice samples near the current policy)",
        min=1,
    )
    accept: bool = option(
        True, "publish a sweep's map only when its policy reaches the goal from as many starts as the accepted one"
    )


class VergenceProgram(Program):
    """The vergence program (ch. 7): LSPI verging, vergence-trace lengths embedded as 1-D depth.

    Built by `make_program` as `VergenceProgram(spec, seed, params=None, **overrides)`; the
    hyperparameters are `VergenceProgramParams`. Needs 1 or 2 discrete actions (converge[, diverge]),
    sensors "left" and "right", and >= 2 start states.
    """

    name = "vergence"
    Params = VergenceProgramParams

    def __init__(
        self, spec: WorldSpec, seed: int = 0, params: VergenceProgramParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(spec, seed)
        self.params = prm = parse(VergenceProgramParams, overrides, name=self.name, base=params)
        samples_per_iteration, epsilon, gamma, ridge = prm.samples_per_iteration, prm.epsilon, prm.gamma, prm.ridge
        max_trace, centres, width = prm.max_trace, prm.centres, prm.width
        if not spec.action_space.discrete or spec.action_space.n not in (1, 2) or spec.n_starts < 2:
            raise SpecMismatch(
                "vergence program needs 1 or 2 discrete actions (converge[, diverge]) and >= 2 start states"
            )
        spec.sensor("left"), spec.sensor("right")
        self.samples_per_iteration = samples_per_iteration
        self.epsilon = epsilon
        self.max_trace = max_trace
        n_actions = int(spec.action_space.n or 2)
        self.lspi = LSPI(RBFBasis(tuple(float(c) for c in centres), width, n_actions), gamma=gamma, ridge=ridge)
        self.practice = VergencePractice(self.lspi, self.rng, samples_per_iteration, epsilon)
        self.phase = "explore"
        self._sweep = StartStateSweep(spec.n_starts, max_trace)
        self._pending_embedding: dict[str, Any] | None = None  # what the embed job in flight is of
        self.accept = prm.accept
        self._accepted: Score | None = None  # the sweep score of the policy whose map was published last
        self.use_background(prm.learn_lag)

    def act(self, obs: Observation) -> Decision:
        """Explore (feeding LSPI) or, after each LSPI iteration, sweep the start states and embed;
        LSPI and the embedding run in the background, swapped in `learn_lag` acts after they start."""
        d = foveal_difference(obs)
        bg = self.background
        assert bg is not None
        iterated = False
        if self.phase == "explore":
            self.practice.observe(obs, d, obs.done, self.emit, bg)
        for name, result in bg.tick():
            if name == "embed":
                self._embedded(result)
            elif name == "lspi":
                iterated = self.practice.iterated(result, obs.step, self.emit)
        if self.phase == "explore":
            if iterated:
                self.phase = "embed"
                self._sweep = StartStateSweep(self.spec.n_starts, self.max_trace)
                return self._sweep.begin()
            if obs.done:
                return Decision(reset=True, start=-1)
            return Decision((float(self.practice.choose(d)),))
        dec = self._sweep.step(obs, lambda o, trace: self.lspi.greedy(foveal_difference(o)))
        if self._sweep.finished:
            self._embed(obs.step)
            self.phase = "explore"
        return dec

    def _embed(self, step: int) -> None:
        """The sweep is over: start the distances + MDS job; `_embedded` emits its result."""
        traces = [list(t) for t in self._sweep.traces]
        n = len(traces)
        if self.accept:
            score = sweep_score(list(self._sweep.reached), traces)
            verdict = compare(score, self._accepted, stochastic=False)
            if not (verdict.better or verdict.equal):
                assert self._accepted is not None  # compare(x, None) is better
                self.emit(
                    EventOutput(
                        EventKind.EVALUATION,
                        f"policy of LSPI iteration {self.lspi.iterations} not accepted: goal from "
                        f"{score.fraction:.0%} of starts (accepted policy: {self._accepted.fraction:.0%}); "
                        "its map is not published",
                        step,
                        {
                            "policy_success": score.fraction,
                            "accepted": 0.0,
                            "lspi_iterations": float(self.lspi.iterations),
                        },
                    )
                )
                return
            self._accepted = score
        assert self.background is not None
        self.background.submit("embed", embed_job, traces=traces)
        self._pending_embedding = {
            "step": step,
            "n": n,
            "iteration": self.lspi.iterations,
            "lspi_iterations": float(self.lspi.iterations),
            "policy_success": self._sweep.rewarded / n,
            "mean_trace_length": float(np.mean([len(t) for t in traces])),
        }

    def _embedded(self, result: dict[str, Any]) -> None:
        """The distances + MDS job's result swapped in: emit the embedding."""
        p = self._pending_embedding
        assert p is not None
        self._pending_embedding = None
        n = int(p["n"])
        eig = np.asarray(result["eigenvalues"])
        self.emit(
            EmbeddingOutput(
                Trigger.POLICY_ITERATION,
                tuple(range(n)),
                np.asarray(result["coordinates"]),
                tuple(float(e) for e in eig[: min(10, n)]),
                int(p["step"]),
                {k: float(p[k]) for k in ("lspi_iterations", "policy_success", "mean_trace_length")},
                iteration=int(p["iteration"]),
            )
        )

    def state(self) -> dict[str, Any]:
        """The base snapshot plus LSPI, practice, phase and sweep (see `agent.programs.base`)."""
        return {
            **super().state(),
            "lspi": self.lspi.state(),
            "practice": self.practice.state(),
            "phase": self.phase,
            "sweep": self._sweep.state(),
            "pending_embedding": None if self._pending_embedding is None else dict(self._pending_embedding),
            "accepted": None
            if self._accepted is None
            # no trace reached the goal: length inf, saved as None (checkpoints hold finite numbers)
            else [self._accepted.fraction, _finite_or_none(self._accepted.length), self._accepted.traces],
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a program built with the same spec and params."""
        super().restore(state)
        self.lspi.restore(state["lspi"])
        self.practice.restore(state["practice"])
        self.phase = str(state["phase"])
        self._sweep = StartStateSweep(self.spec.n_starts, self.max_trace)
        self._sweep.restore(state["sweep"])
        pending = state.get("pending_embedding")
        self._pending_embedding = None if pending is None else dict(pending)
        acc = state.get("accepted")  # absent in snapshots from before acceptance
        self._accepted = (
            None
            if acc is None
            else Score(float(acc[0]), float("inf") if acc[1] is None else float(acc[1]), int(acc[2]))
        )

    def world_restarted(self) -> None:
        """Drop the pending sample and restart the trace in progress."""
        self.practice.reset()
        self._sweep.interrupted()
