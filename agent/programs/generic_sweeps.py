"""The generic program's sweeps and the acceptance of their policies.

Phases alternate: *learn* until `samples_per_iteration` new samples (LSPI: then features are
refitted and LSPI iterates off the act path; a table learner: a plan, swept only once the model is
complete and its greedy policy changed, or once watched) or `embed_every` steps (Sarsa, which
learns on every step); *embed*: the greedy policy from each start state (`StartStateSweep`), trace
distances, classical MDS, Embedding vN. A sweep that repeats the accepted traces once watched
publishes nothing: every version is a new map. Which policy is better is decided by the pure rules
of `agent.programs.acceptance`. Until the policy is *watched* every sweep's policy is published
and accepted in a deterministic world; in a stochastic one only a policy better beyond the noise of
the sampled goal fractions (1.64 standard errors) is. A sweep that reaches the goal from
`watch_after` of the starts makes the policy watched; so does, in a stochastic world, an accepted
policy that `settle` newer policies in a row did not beat beyond the noise (the best there is where
no policy reaches `watch_after`: the event says `settled`). Once watched, a new policy is embedded
only when its sweep is better (stochastic: beyond the noise), else the accepted policy is swept
again - a stochastic world's sweep of the accepted policy is another draw of its traces and is never
a new map - so embeddings hold once learned, and the drop detector sees only the accepted policy's
trace scores, never the program's own experiments: in a deterministic world 0 for a start whose
goal the accepted policy reached and no longer does (twice: the start is run once more first), else
1; in a stochastic one gamma^length at the goal, else 0. On a drop the samples and policy are
dropped, the policy relearned from fresh experience and the first good embedding after it (in a
stochastic world that settles below `watch_after`: the settled policy's map, published again; in a
deterministic one whose changed body cannot reach `watch_after`: the exact plan of a complete model,
the best that body allows) says `relearned`.
"""

from __future__ import annotations

import numpy as np

from sensorimotor.agent.learners.lspi_features import basis_state
from sensorimotor.agent.programs.acceptance import Score, Verdict, compare, compare_ends, end_disparity, sweep_score
from sensorimotor.agent.programs.base import Decision, EventOutput
from sensorimotor.agent.programs.generic_relearn import GenericRelearn
from sensorimotor.protocol.messages import EventKind, Observation


class GenericSweeps(GenericRelearn):
    """Sweeps of the start states and the acceptance of their policies."""

    RELEARN_CONFIRM = 3  # good sweeps after a drop that may go unpublished while their traces still change

    def _init_sweeps(self) -> None:
        """Nothing swept, nothing accepted, nothing watched yet."""
        self.phase = "explore"
        self.new_samples = 0
        self.relearn_at = None
        self._sweep = self._new_sweep()
        self._visited = set()
        self._perf = []
        self._watching = False  # the detector sees trace scores only once the policy is good
        self._held = 0  # stochastic: newer policies since the accepted one, none better beyond noise
        self._accepted = None  # the accepted policy's weights (see the module docstring)
        self._best = None
        self._best_disparity = None  # planner, distance=net: the accepted sweep's end disparity
        self._checking = False  # this sweep runs the accepted policy, not the newest one
        self._sweep_w = None  # the weights the sweep in progress follows
        self._accepted_basis = None  # lspi: the RBF basis the accepted weights are over
        self._sweep_rbf = None  # the basis the sweep in progress computes features with
        self._sweep_basis = None  # and its state (lspi)
        self._accepted_traces = None  # the accepted policy's last sweep
        self._accepted_reached = None  # and which of its traces reached the goal
        self._candidate_traces = None  # a better policy's traces, not yet confirmed
        self._published = None  # the traces of the last map published (a version is a new map)
        self._relearn_unconfirmed = 0  # good sweeps since a drop whose traces the next one did not keep
        self._diverged = False  # the trace in progress left the accepted policy's choices
        self._unfed = []  # trace scores of this sweep held back from the detector
        self._start_scores = []  # scores of the start state in progress (one per sample)
        self._start_fair = True  # all of them came from the accepted policy's choices
        self._trace_from = None  # planner: where the trace in progress started
        self._ends = {}  # planner: each start's (start, end) this sweep
        self._pending_embedding = None  # what the embed job in flight is of
        self._last_choice = 0  # the action table's row the last sweep step sent
        self._chance_seen = False
        self.retried_total = 0  # traces run once more before they counted (`_in_doubt`), every sweep

    def _choose(self, obs: Observation, trace: list[int]) -> int:
        if not trace:
            self._visited = set()
        self._visited.add((self._key(obs), trace[-1] if trace else -1))
        prefer = trace[-1] if trace else None
        a = self._pick(self._q(obs, self._sweep_w), prefer)
        if self._watching and not self._checking and self._accepted is not None and not self._diverged:
            rbf, self._sweep_rbf = self._sweep_rbf, self._accepted_rbf()
            try:
                self._diverged = a != self._pick(self._q(obs, self._accepted), prefer)
            finally:
                self._sweep_rbf = rbf
        return a

    def _cycle(self, obs: Observation, trace: list[int]) -> bool:
        """A deterministic greedy policy that meets the same observation after the same action again
        is in a loop that never ends: the trace stops there (not in a stochastic world, where the
        next step may differ)."""
        return bool(trace) and not self.stochastic and (self._key(obs), trace[-1]) in self._visited

    def _start_sweep(self, check: bool) -> Decision:
        """Sweep the start states with the newest policy, or (`check`) with the accepted one."""
        check = check or self._chance_seen
        self._prev, self._prev_x, self._prev_key = None, None, None
        self.phase = "embed"
        self._checking = check
        w = self._accepted if check and self._accepted is not None else self._weights()
        self._sweep_w = np.array(w, copy=True)
        if self.learner == "lspi":
            # the basis is frozen for the sweep, as its weights are: a refit swapped in mid-sweep would
            # give the weights features they were not fitted on, and the accepted policy's basis would
            # not be the one its traces were made with (a check sweep then differs: a false drop)
            use = self._accepted_basis if check and self._accepted_basis is not None else basis_state(self._rbf)
            self._sweep_basis = use
            self._sweep_rbf = self._rbf_of(use)
        else:
            self._sweep_basis, self._sweep_rbf = None, None
        self._inherit_order()
        self._sweep = self._new_sweep()
        self._diverged = False
        self._unfed = []
        self._start_scores, self._start_fair = [], True
        self._ends, self._trace_from = {}, None
        # a random order: the detector then sees trace scores in no spatial order (a run of far
        # starts, long traces, would look like a drop)
        return self._sweep.begin([int(i) for i in self.rng.permutation(self.spec.n_starts)])

    def _sweep_act(self, obs: Observation) -> Decision:
        n_before = len(self._sweep.traces)
        # the trace in progress's start (`started` is put back in start order once the sweep ends)
        start = self._sweep.current
        if self.planner is not None and obs.t == 0:
            self._trace_from = self._vector(obs)
        dec = self._sweep.step(obs, self._choose, self._cycle, self._in_doubt)
        if len(self._sweep.traces) > n_before:
            if self._trace_from is not None:
                self._ends[start] = (self._trace_from, self._vector(obs))
            # a trace ended: its score goes to the detector now when it is the accepted policy's own
            # trace (a check sweep, or a newer policy that chose as the accepted one at every step),
            # else only if the newer policy is accepted when the sweep ends
            assert self._sweep.last is not None
            trace, ok = self._sweep.last
            self._trim(trace, ok)  # (generic_relearn: the action that never acted, in history mode)
            self._start_scores.append(self._trace_score(start, trace, ok))
            self._start_fair = self._start_fair and (self._checking or not self._diverged)
            if len(self._start_scores) >= self._sweep.repeats:
                # one value per start state: its samples' mean (samples of one start run in a row,
                # and a run of like scores would read as a drop)
                score = float(np.mean(self._start_scores))
                if self._watching and self._start_fair:
                    self._perf.append(score)
                else:
                    self._unfed.append(score)
                self._start_scores, self._start_fair = [], True
            self._diverged = False
        if self.sarsa is not None and not self._checking and self.params.epsilon == 0.0:
            self._learn_in_sweep(obs, None if dec.reset else int(dec.values[0]))
        if self.planner is not None:  # a model learns from every transition, whoever chose it
            self._model_step(obs, None if dec.reset else int(dec.values[0]))
        if not dec.reset:
            self._last_choice = int(dec.values[0])
            dec = Decision(tuple(float(v) for v in self.actions[self._last_choice]))
        if self._sweep.finished:
            again = self._swept(obs.step)
            if again is not None:
                return again
        return dec

    def _in_doubt(self, start: int, trace: list[int], ok: bool) -> bool:
        """A deterministic world's trace that misses a goal the accepted policy reached from its
        start is run once more before it counts (the sweep keeps the second run): a simulator that
        is not bit-repeatable (panda-gym's contacts, ~0.1 mm) can tip one trace off its goal once,
        and a constant stream of 1s would read that single 0 as a drop. A changed body fails twice.
        Only traces whose score the detector would see are doubted (a newer policy that chose
        otherwise than the accepted one is not judged by it)."""
        if ok or self.stochastic or self._accepted_reached is None or start >= len(self._accepted_reached):
            return False
        return bool(self._accepted_reached[start]) and (self._checking or not self._diverged)

    def _trace_score(self, start: int, trace: list[int], ok: bool) -> float:
        """The detector's value of a trace. In a deterministic world, relative to the accepted
        policy's own sweep: 0 for a start whose goal it reached and no longer does, else 1 - so an
        unchanged world gives a constant stream, however long or varied the traces (a sweep of many
        starts in random order would otherwise show runs of long traces that read as drops), and a
        change that breaks the policy shows at once. Lengths do not count: a trace that still
        reaches the goal another way is not a drop. Otherwise (stochastic, or nothing accepted
        yet) gamma^length at the goal, else 0."""
        if self.stochastic or self._accepted_reached is None or start >= len(self._accepted_reached):
            return self.lspi.gamma ** len(trace) if ok else 0.0
        if not ok:
            return 0.0 if self._accepted_reached[start] else 1.0
        return 1.0

    def _swept(self, step: int) -> Decision | None:
        """A sweep finished: accept, publish, feed the detector, or sweep the accepted policy again."""
        sw = self._sweep
        k = sw.repeats
        self.retried_total += sw.retries
        if self._chance_seen and self._checking and not self.stochastic:
            reached_before = self._accepted_reached or []
            if not any(bool(a) and not r for a, r in zip(reached_before, sw.reached, strict=False)):
                # the accepted policy reaches every goal it reached: the body is as it was, and the
                # outcomes that alternated are chance (or states that look alike)
                self._chance_seen, self._checking, self.phase = False, False, "explore"
                self._become_stochastic(step)
                return None
            # it misses some: their zeros reach the detector, and the accepted policy is checked at
            # every sweep until the drop
        if self.stochastic and k > 1 and all(sw.traces[i] == sw.traces[i - i % k] for i in range(len(sw.traces))):
            # every start's samples were the same trace: the policy controls whatever made the
            # transitions differ (or distinct states looked alike), so one trace per start will do
            # (ch. 9.4); the transitions are watched again from here
            n_sampled = len(sw.traces)
            sw.traces, sw.reached = sw.traces[::k], sw.reached[::k]
            if self._accepted_traces is not None and len(self._accepted_traces) == n_sampled:
                self._accepted_traces = self._accepted_traces[::k]  # one per start, as the sweep's
            if self._accepted_reached is not None and len(self._accepted_reached) == n_sampled:
                self._accepted_reached = self._accepted_reached[::k]
            sw.repeats, k, sw.rewarded = 1, 1, sum(sw.reached)
            self.stochastic = False
            self._plan_for_chance()
            self.emit(
                EventOutput(
                    EventKind.POLICY_ITERATION,
                    "the sampled traces from every start state were the same: one trace per start state again",
                    step,
                    reason="deterministic",
                )
            )
        self._trace_distance(step)  # `distance=auto`: this sweep's traces may settle it (generic_continuous)
        if self._regauge:
            self._regauge = False
            if self._watching and self._accepted_traces and self._accepted_reached:
                # the accepted policy's map under the distance now in force (a newer policy is then
                # ranked by its ends once one is accepted: `_best_disparity` is set at acceptance)
                self.phase, self._best_disparity, self._checking = "explore", None, True
                acc = (self._accepted_traces, self._accepted_reached)
                self._embed(step, False, len(acc[0]) // self.spec.n_starts, of=acc)
                self._checking = False
                return None
        new = sweep_score(sw.reached, sw.traces)
        score = (new.fraction, new.length)
        exact = self._exact_plan()
        # after a drop, the plan of the complete model (made from it as it is: `_plan_exact`) is the
        # best the changed body allows, even where it reaches fewer than `watch_after` of the starts
        # (a lesioned motor, a start walled in): its map is the relearned one, and it is watched
        best_allowed = self.relearn_at is not None and exact and self._plan_exact and new.fraction > 0
        good = new.fraction >= self.params.watch_after or best_allowed
        best = self._best
        disparity = end_disparity(self._ends)
        if self._by_ends() and disparity is not None and self._best_disparity is not None:
            verdict = compare_ends(disparity, self._best_disparity, good)  # (agent.programs.acceptance)
        elif self.stochastic and (best is None or self._accepted_reached is None):
            verdict = Verdict(True, True)  # nothing sampled to compare with yet
        else:
            accepted = None if best is None else Score(best[0], best[1], len(self._accepted_reached or ()))
            verdict = compare(new, accepted, self.stochastic)
        better, equal = verdict.better, verdict.equal
        same = self._accepted_traces is not None and [list(t) for t in sw.traces] == self._accepted_traces
        self.phase = "explore"
        if self.stochastic and not (self._watching or self._checking or better) and best is not None:
            # not better beyond the noise: the accepted map stays the published one; when `settle`
            # newer policies in a row were not, the accepted policy has converged (the best there is
            # in a world where no policy reaches `watch_after` of the starts) and is watched
            self._hold(step)
            return None
        if self._watching and not self._checking and self._accepted is not None and not (better or same):
            if equal:
                # as good as the accepted policy but other traces (ties broken another way): the
                # accepted map stays the published one; its scores are fair for the detector only
                # where they are absolute (a stochastic world), not relative to the accepted traces
                if self.stochastic:
                    self._perf.extend(self._unfed)
                return None
            # the newest policy is worse than the accepted one: not published, not judged by the
            # detector; the accepted policy is swept again, so that a changed world still shows
            return self._start_sweep(check=True)
        traces = [list(t) for t in sw.traces]
        # scores held back as their traces ended (see `_sweep_act`) are fed when they are absolute
        # (a stochastic world, or nothing accepted yet), never when relative to the accepted traces
        absolute = self.stochastic or self._accepted_reached is None
        if self._watching and not self._checking and better and not same and self.tabular and not self.stochastic:
            if traces != self._candidate_traces and not exact:
                # a better policy, seen once: published when the next policy iteration keeps its
                # traces - a policy still changing from one iteration to the next has not converged,
                # and the maps of its passing detours can be far worse than the accepted one
                self._candidate_traces = traces
                if absolute:
                    self._perf.extend(self._unfed)  # better than the accepted policy: its scores are fair
                return None
        if (
            good
            and self.relearn_at is not None
            and not self.stochastic
            and traces != self._candidate_traces
            and self._relearn_unconfirmed < self.RELEARN_CONFIRM
            and not exact
        ):
            # relearning after a body change: the first policies that reach the goal again still
            # change from one iteration to the next, and the map of their detours can be far off
            # the new body; the relearned map is published once an iteration keeps the traces of
            # the one before (or after RELEARN_CONFIRM good sweeps that never settled)
            self._candidate_traces = traces
            self._relearn_unconfirmed += 1
            if absolute:
                self._perf.extend(self._unfed)
            return None
        if (self._watching or good) and absolute:
            self._perf.extend(self._unfed)
        if self._checking and self.stochastic:
            # a re-draw of the accepted policy's traces: its scores are the detector's, but it is no
            # new map (the published one was drawn from the same policy; publishing each draw would
            # only publish the noise of the sampling)
            self._checking = False
            return None
        relearned = good and self.relearn_at is not None
        if self._watching and same and not relearned:
            # the accepted policy's own traces again: the published map stands (a version is a new map)
            self._checking = False
            return None
        # the accepted policy checked again with the traces of the map last published (a world that
        # changed under it, noticed or not): that map stands, and the repeat is not emitted
        repeat = self._checking and not relearned and traces == self._published
        if relearned:
            self._relearn_unconfirmed = 0
            self._order_kept()
        if not self._checking and (better or not self._watching):
            self._accepted, self._best, self._held = np.array(self._sweep_w, copy=True), score, 0
            self._best_disparity = disparity if self._by_ends() else None
            self._accepted_traces = traces
            self._accepted_reached = [bool(r) for r in sw.reached]
            self._candidate_traces = None
            self._accepted_basis = None if self.learner != "lspi" else self._sweep_basis
        self._watching = self._watching or good
        self._embed(step, relearned, k)
        if repeat and self._pending_embedding is not None:
            self._pending_embedding["repeat"] = True
        self._checking = False
        return None

    def _exact_plan(self) -> bool:
        """Whether the swept policy is the exact shortest way: the model learner's plan over a
        complete model of a deterministic world. Such a policy needs no second sweep to show it has
        converged (the confirmations above are for learners whose policy changes between iterations),
        so a relearned map is published at its first good sweep."""
        return self.model is not None and not self.stochastic and self.model.complete()

    def _hold(self, step: int) -> None:
        """A newer policy was not better beyond the noise (stochastic world): one more round the
        accepted policy held; after `settle` of them it has converged and is watched."""
        assert self._best is not None
        self._held += 1
        if self._held >= self.params.settle:
            self._watching = True
            self.emit(
                EventOutput(
                    EventKind.POLICY_ITERATION,
                    f"the accepted policy (goal from {self._best[0]:.0%} of sampled traces) held through "
                    f"{self._held} newer policies, none better beyond the noise: watched from here",
                    step,
                    reason="settled",
                )
            )
            if self.relearn_at is not None and self._accepted_traces and self._accepted_reached:
                # after a drop, the settled policy is the relearned one: its map (published when
                # it was accepted) again, now saying so
                self._checking = True
                acc = (self._accepted_traces, self._accepted_reached)
                self._embed(step, True, len(acc[0]) // self.spec.n_starts, of=acc)
                self._checking = False

    def _by_ends(self) -> bool:
        """Whether policies are ranked by where their traces end (`end_disparity`) once watched: the
        planner's net-move maps in a deterministic world (`generic.rank=auto`), or when told."""
        rank = self.params.rank
        chosen = rank == "ends" or (rank == "auto" and self._trace_distance() == "net")
        return chosen and self.planner is not None and not self.stochastic
