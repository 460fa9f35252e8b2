"""Running a policy from every start state in turn and collecting its action traces: the part of
step 2 of the algorithm (ch. 3) that every trace-embedding program shares."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sensorimotor.agent.programs.base import Decision
from sensorimotor.protocol.messages import Observation


class StartStateSweep:
    """Drive the world through start states 0..n-1 (each by a reset), let `choose(obs, trace)` pick
    the actions, and record each trace until the episode ends, `max_trace` actions are taken, or
    `stop(obs, trace)` says the policy is stuck. `finished` is set after the last start state.
    A trace counts as `rewarded` when `goal(obs)` holds where it ends (default: a positive reward),
    or when its start state already ended the episode; `reached` says which traces did. With
    `repeats` > 1 each start state is run that many times in a row (`n_starts` counts traces)."""

    def __init__(
        self, n_starts: int, max_trace: int, goal: Callable[[Observation], bool] | None = None, repeats: int = 1
    ) -> None:
        self.n_starts = n_starts
        self.repeats = repeats  # traces per start state (stochastic worlds), run one after another
        self.order: list[int] | None = None  # the order the start states are visited in (None: 0, 1, ...)
        self.started: list[int] = []  # the start state of each trace, in the order they were run
        self.last: tuple[list[int], bool] | None = None  # the trace that ended last, and whether it reached the goal
        self.max_trace = max_trace
        self.goal = goal if goal is not None else (lambda o: o.reward > 0)
        self.reached: list[bool] = []
        self.traces: list[list[int]] = []
        self.rewarded = 0
        self.finished = False
        self._start = 0
        self._trace: list[int] = []
        self._restart = False
        self._retried = False  # the trace in progress is a second run of a doubted one
        self.retries = 0  # doubted traces run again

    def begin(self, order: list[int] | None = None) -> Decision:
        """The first decision of a sweep: reset the world to its first start state. `order`: visit the
        start states in this order (a permutation of 0..n-1); `traces` and `reached` are back in
        start-state order once the sweep has `finished`."""
        if order is not None:
            if sorted(order) != list(range(self.n_starts // self.repeats)):
                raise ValueError("order must be a permutation of the start states")
            self.order = [int(i) for i in order]
        return Decision(reset=True, start=self._start_of(0))

    @property
    def current(self) -> int:
        """The start state of the trace in progress (the one `step` ends next; -1 once finished)."""
        return self._start_of(self._start) if self._start < self.n_starts else -1

    def _start_of(self, i: int) -> int:
        k = i // self.repeats
        return self.order[k] if self.order is not None else k

    def step(
        self,
        obs: Observation,
        choose: Callable[[Observation, list[int]], int],
        stop: Callable[[Observation, list[int]], bool] | None = None,
        doubt: Callable[[int, list[int], bool], bool] | None = None,
    ) -> Decision:
        """Answer one observation of the sweep: the next action of the trace, or a reset to the next
        start state when the trace ends (`finished` after the last one). A trace that
        `doubt(start, trace, reached)` doubts is not kept: its start state is run once more and the
        second trace is kept, whatever it is (a world that is not bit-repeatable can fail a goal
        once by a hair: a simulator's contacts).
        """
        if self._restart or (obs.t == 0 and obs.start != self._start_of(self._start)):
            self._restart = False  # the world or the agent restarted mid-trace: this start state again
            return Decision(reset=True, start=self._start_of(self._start))
        if obs.done or len(self._trace) >= self.max_trace or (stop is not None and stop(obs, self._trace)):
            ok = bool(self.goal(obs) or (obs.done and not self._trace))
            if doubt is not None and not self._retried and doubt(self._start_of(self._start), self._trace, ok):
                self._retried = True
                self.retries += 1
                self._trace = []
                return Decision(reset=True, start=self._start_of(self._start))
            self._retried = False
            self.rewarded += int(ok)
            self.reached.append(ok)
            self.traces.append(self._trace)
            self.last = (self._trace, ok)
            self.started.append(self._start_of(self._start))
            self._trace = []
            self._start += 1
            if self._start < self.n_starts:
                return Decision(reset=True, start=self._start_of(self._start))
            self.finished = True
            if self.order is not None:  # back in start-state order (stable: a start's samples stay in turn)
                idx = sorted(range(len(self.traces)), key=lambda i: self.started[i])
                self.traces = [self.traces[i] for i in idx]
                self.reached = [self.reached[i] for i in idx]
                self.started = [self.started[i] for i in idx]
            return Decision(reset=True, start=-1)
        a = choose(obs, self._trace)
        self._trace.append(a)
        return Decision((float(a),))

    def state(self) -> dict[str, Any]:
        """Traces so far, the start state and trace in progress (n_starts, max_trace: configuration)."""
        return {
            "n_starts": self.n_starts,
            "repeats": self.repeats,
            "max_trace": self.max_trace,
            "traces": [list(t) for t in self.traces],
            "rewarded": self.rewarded,
            "reached": list(self.reached),
            "order": None if self.order is None else list(self.order),
            "started": list(self.started),
            "finished": self.finished,
            "start": self._start,
            "trace": list(self._trace),
            "restart": self._restart,
            "retried": self._retried,
            "retries": self.retries,
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a sweep over as many start states."""
        if (state["n_starts"], state["max_trace"]) != (self.n_starts, self.max_trace):
            raise ValueError(
                f"sweep state is for {state['n_starts']} start states and traces of "
                f"{state['max_trace']}, this sweep has {self.n_starts} and {self.max_trace}"
            )
        self.repeats = int(state.get("repeats", self.repeats))  # absent in older checkpoints
        self.traces = [[int(a) for a in t] for t in state["traces"]]
        self.rewarded, self.finished = int(state["rewarded"]), bool(state["finished"])
        self.reached = [bool(v) for v in state.get("reached", [])]
        order = state.get("order")
        self.order = None if order is None else [int(v) for v in order]
        self.started = [int(v) for v in state.get("started", [])]
        self._start, self._trace = int(state["start"]), [int(a) for a in state["trace"]]
        self._restart = bool(state["restart"])
        self._retried, self.retries = bool(state.get("retried", False)), int(state.get("retries", 0))

    def interrupted(self) -> None:
        """The world or the agent restarted: the trace in progress starts again, from a reset."""
        self._trace = []
        self._restart = not self.finished
