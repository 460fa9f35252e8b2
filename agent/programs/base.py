"""What a developmental program is: an online policy over one world's observations that, now and
then, emits an embedding of what it learned (and events about itself).

A program answers every observation with exactly one Decision, handles one observation at a time,
owns its random generator, and never looks at ground truth (the link scores embeddings). Programs
are deterministic given their seed and the observation stream, so a recording replayed offline
gives the same embeddings.

Saved state (checkpoints) - one convention for every stateful component (programs, learners,
sweeps, detectors):

- Configuration is not state. A component is first built the ordinary way, from its constructor
  arguments (a program: `make_program(spec, seed, **params)`, `params` being what it was made with);
  what it holds that its owner builds later (e.g. the mountain car's driver, made from the first
  embedding) is rebuilt by that owner from values in the owner's own state.
- `state() -> dict` returns a snapshot of everything that changes as it runs: a nested dict with
  str keys (no dots, no leading "__") whose leaves are numpy arrays or plain values (int, float,
  str, bool, None, and lists/dicts of those). Arrays and lists are copies, so the snapshot stays
  valid while the component runs on. The random generator's state is included
  (`rng.bit_generator.state`, a plain dict), so a restored component continues exactly as the
  original would have.
- `restore(state) -> None` puts such a snapshot back into a freshly built component of the same
  configuration (generators are restored in place, so shared ones stay shared). It raises
  ValueError or KeyError when the snapshot does not fit the configuration.

`sensorimotor.agent.checkpoint` writes these snapshots as arrays plus JSON, never as a pickle.

Learning off the act path: a program whose learning is slow (policy iteration, an embedding)
calls `use_background(lag)` in its constructor, `self.background.tick()` first thing in every
`act`, and `self.background.submit(...)` to start a job; see `agent.programs.background`. The
jobs in flight are part of `state()` (the base class saves and restores them).
"""

from __future__ import annotations

import abc
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from sensorimotor.agent.programs.background import Background
from sensorimotor.agent.snapshot import rng_state, set_rng_state
from sensorimotor.protocol.messages import EventKind, Observation, Trigger, WorldSpec
from sensorimotor.protocol.params import option, parse


@dataclass(frozen=True)
class Decision:
    """The answer to one observation: action values, or a reset to `start` (-1 = random)."""

    values: tuple[float, ...] = ()
    reset: bool = False
    start: int = -1


@dataclass(frozen=True)
class EmbeddingOutput:
    """An embedding a program made; the link scores, versions and publishes it.

    `trigger` is one `Trigger` token; `iteration` and `drop_step` carry its specifics as typed
    values (never in the text)."""

    trigger: Trigger
    ids: tuple[int, ...]
    coordinates: np.ndarray
    eigenvalues: tuple[float, ...]
    step: int
    metrics: dict[str, float] = field(default_factory=dict)
    absolute: bool = False  # coordinates are in the truth's own units (E_geometry is meaningful)
    iteration: int = 0
    drop_step: int | None = None
    labels: tuple[int, ...] = ()  # trigger policy_map: cluster of each row


@dataclass(frozen=True)
class EventOutput:
    """An event a program reports about itself: `kind` is an `EventKind`, `detail` is for people."""

    kind: EventKind
    detail: str
    step: int
    values: dict[str, float] = field(default_factory=dict)
    reason: str = ""


@dataclass(frozen=True)
class EchoParams:
    """Parameters of the echo program (loop benchmarks)."""

    work_us: float = option(
        0.0,
        "CPU time spent in Python per answer, in us (a stand-in for a learner's act: `sme bench scale --agent-work-us`)",
        min=0.0,
        max=1e6,
    )


class Program(abc.ABC):
    """A developmental program. It declares its hyperparameters once, as a frozen dataclass (see
    `protocol.params`) named by the class attribute `Params`; its constructor takes
    `(spec, seed, params=None, **overrides)` and keeps the parsed instance as `self.params`."""

    name = "program"
    Params: ClassVar[type] = EchoParams
    params: Any  # the parsed `Params` instance the program was made with (set by each constructor)
    # settings for the daemon's drop detector that suit this program's `performance` stream, e.g. a
    # shorter warm-up for one value per episode than for one per step
    detector_params: dict[str, Any] = {}

    # set for every new Background (tests run the jobs on the act thread to compare)
    inline_background: ClassVar[bool] = False

    def __init__(self, spec: WorldSpec, seed: int = 0) -> None:
        self.spec = spec
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self._outbox: list[Any] = []
        self.background: Background | None = None

    def use_background(self, lag: int) -> Background:
        """Opt in to learning off the act path: jobs swapped in `lag` acts after they start."""
        self.background = Background(lag, inline=Program.inline_background)
        return self.background

    @abc.abstractmethod
    def act(self, obs: Observation) -> Decision:
        """Learn from `obs` and answer it."""

    def drain(self) -> list[Any]:
        """Embeddings and events produced since the last call."""
        out, self._outbox = self._outbox, []
        return out

    def emit(self, item: Any) -> None:
        """Queue an `EmbeddingOutput` or `EventOutput` for the link (see `drain`)."""
        self._outbox.append(item)

    def emit_lspi_iteration(self, lspi: Any, change: float, step: int) -> None:
        """Report an LSPI iteration whose weights were just swapped into `lspi` (an `agent.learners.LSPI`)."""
        self.emit(
            EventOutput(
                EventKind.POLICY_ITERATION,
                f"LSPI iteration {lspi.iterations}",
                step,
                {"weight_change": float(change), "samples": float(lspi.n_samples)},
            )
        )

    def emit_policy_map(
        self, traces: list[Any], ids: tuple[int, ...], step: int, n_clusters: int | None = None, kind: str = "edit"
    ) -> None:
        """Emit a policy map (ch. 9.6): the embedded traces of the program's trained policy from the
        start states `ids`, clustered; an `Embedding` with trigger ``policy_map`` and a cluster label
        per row, which `sme view` colours by cluster. Any program with a trained policy can call it."""
        from sensorimotor.agent.embedding.policy_map import policy_map

        if len(traces) < 3:
            return
        pm = policy_map(traces, n_clusters=n_clusters, kind=kind, seed=self.seed)
        sizes = np.bincount(pm.labels, minlength=pm.n_clusters)
        self.emit(
            EmbeddingOutput(
                trigger=Trigger.POLICY_MAP,
                ids=tuple(int(i) for i in ids),
                coordinates=pm.coordinates,
                eigenvalues=tuple(float(e) for e in pm.eigenvalues[:10]),
                step=step,
                metrics={"clusters": float(pm.n_clusters), "silhouette": pm.silhouette}
                | {f"cluster_{c}_size": float(n) for c, n in enumerate(sizes)},
                labels=tuple(int(v) for v in pm.labels),
            )
        )

    def describe(self) -> str:
        """How the program learns this world, for people (the attach event says it; "" if nothing to add)."""
        return ""

    def world_restarted(self) -> None:
        """The world process restarted (new session): an episode in progress is gone."""

    def performance(self, obs: Observation) -> float | None:
        """The signal the daemon's drop detector watches (None: nothing to report for this step).
        Programs without a meaningful per-step performance return None and are not watched."""
        return None

    def on_drop(self, step: int) -> None:
        """The detector saw a drop in `performance`: relearn as the learner prescribes."""

    def rebase_performance(self) -> None:
        """Say that `performance` is now measured another way (its scale changed, not the world):
        the daemon's drop detector forgets its reference before the next value."""
        self._rebase = True

    def take_rebase(self) -> bool:
        """Whether `rebase_performance` was called since the last call (the daemon asks each step)."""
        out, self._rebase = getattr(self, "_rebase", False), False
        return out

    def state(self) -> dict[str, Any]:
        """A snapshot of what the program learned and where it is (see the module docstring).
        Subclasses extend the base's dict; outputs not yet drained are not part of it."""
        out: dict[str, Any] = {"seed": self.seed, "rng": rng_state(self.rng)}
        if self.background is not None:
            out["background"] = self.background.state()
        return out

    def take_layout(self, state: dict[str, Any]) -> None:
        """Before `state`'s arrays are checked against this program's `state()` and restored: take
        the layout they were saved in, where a mode the program entered while running changes the
        shape of what it keeps (the generic program remembering the last action). Default: none."""

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a program built with the same spec and params."""
        self.seed = int(state["seed"])
        set_rng_state(self.rng, state["rng"])
        self._outbox = []
        if self.background is not None:
            self.background.restore(state.get("background", {"clock": 0, "jobs": {}}))


class EchoProgram(Program):
    """Answers every observation with action 0: the baseline for the loop benchmark."""

    name = "echo"
    Params = EchoParams

    def __init__(self, spec: WorldSpec, seed: int = 0, params: EchoParams | None = None, **overrides: Any) -> None:
        super().__init__(spec, seed)
        self.params = parse(EchoParams, overrides, name=self.name, base=params)

    def act(self, obs: Observation) -> Decision:
        """Action 0, whatever the observation (after `work_us` of CPU in Python, holding the GIL
        as a learner written in Python would)."""
        if self.params.work_us > 0:
            end = time.thread_time() + self.params.work_us * 1e-6
            while time.thread_time() < end:
                pass
        return Decision((0.0,))
