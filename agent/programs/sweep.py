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
    `stop(obs, trace)` says the policy is stuck. `finished` is set after the last start state."""

    def __init__(self, n_starts: int, max_trace: int) -> None:
        self.n_starts = n_starts
        self.max_trace = max_trace
        self.traces: list[list[int]] = []
        self.rewarded = 0
        self.finished = False
        self._start = 0
        self._trace: list[int] = []
        self._restart = False

    def begin(self) -> Decision:
        """The first decision of a sweep: reset the world to start state 0."""
        return Decision(reset=True, start=0)

    def step(
        self,
        obs: Observation,
        choose: Callable[[Observation, list[int]], int],
        stop: Callable[[Observation, list[int]], bool] | None = None,
    ) -> Decision:
        """Answer one observation of the sweep: the next action of the trace, or a reset to the next
        start state when the trace ends (`finished` after the last one).
        """
        if self._restart or (obs.t == 0 and obs.start != self._start):
            self._restart = False  # the world or the agent restarted mid-trace: this start state again
            return Decision(reset=True, start=self._start)
        if obs.done or len(self._trace) >= self.max_trace or (stop is not None and stop(obs, self._trace)):
            self.rewarded += int(obs.reward > 0 or (obs.done and not self._trace))
            self.traces.append(self._trace)
            self._trace = []
            self._start += 1
            if self._start < self.n_starts:
                return Decision(reset=True, start=self._start)
            self.finished = True
            return Decision(reset=True, start=-1)
        a = choose(obs, self._trace)
        self._trace.append(a)
        return Decision((float(a),))

    def state(self) -> dict[str, Any]:
        """Traces so far, the start state and trace in progress (n_starts, max_trace: configuration)."""
        return {
            "n_starts": self.n_starts,
            "max_trace": self.max_trace,
            "traces": [list(t) for t in self.traces],
            "rewarded": self.rewarded,
            "finished": self.finished,
            "start": self._start,
            "trace": list(self._trace),
            "restart": self._restart,
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a sweep over as many start states."""
        if (state["n_starts"], state["max_trace"]) != (self.n_starts, self.max_trace):
            raise ValueError(
                f"sweep state is for {state['n_starts']} start states and traces of "
                f"{state['max_trace']}, this sweep has {self.n_starts} and {self.max_trace}"
            )
        self.traces = [[int(a) for a in t] for t in state["traces"]]
        self.rewarded, self.finished = int(state["rewarded"]), bool(state["finished"])
        self._start, self._trace = int(state["start"]), [int(a) for a in state["trace"]]
        self._restart = bool(state["restart"])

    def interrupted(self) -> None:
        """The world or the agent restarted: the trace in progress starts again, from a reset."""
        self._trace = []
        self._restart = not self.finished
