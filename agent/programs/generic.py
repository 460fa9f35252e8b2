"""The generic developmental program (the recipe of ch. 6, for any world): learn toward the
world's reward with LSPI over features of the raw observations, run the greedy policy from every
start state the world declares, embed the action traces.

Features: an observation that is one integer sensor with few values is a state id (tabular, as in
the gridworld of ch. 5); anything else is flattened, scaled by the sensors' declared ranges,
randomly projected to at most `projection` dimensions (fixed, seeded: keeps memory bounded for
images), reduced by PCA fitted on a reservoir sample of every observation seen so far, and fed
through Gaussian radial basis functions placed by farthest-point sampling (ch. 6: PCA + RBF).
Box action spaces are discretised into `action_levels` values per dimension; their traces are
compared with the padded sum (continuous actions), discrete ones with the edit distance.

Phases alternate: *explore* (random actions, samples stored) until `samples_per_iteration` new
samples, then features are refitted and LSPI iterates; *embed*: the greedy policy from each start
state (`StartStateSweep`), trace distances, classical MDS, Embedding vN. Each finished trace's score
(gamma^length when it reached a reward, else 0) feeds the drop detector; on a drop the samples are
dropped, the policy relearned from fresh experience and the next embedding says `relearned`.

The feature refit + policy iteration and the distances + MDS run off the act path
(`agent.programs.background`), each swapped in `learn_lag` acts after it starts; the program
explores meanwhile (those samples count toward the next iteration).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from sensorimotor.agent.embedding import classical_mds, trace_distances
from sensorimotor.agent.learners.lspi import LSPI, TabularBasis
from sensorimotor.agent.programs.base import Decision, EmbeddingOutput, EventOutput, Program
from sensorimotor.agent.programs.sweep import StartStateSweep
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import EventKind, Observation, Trigger, WorldSpec
from sensorimotor.protocol.params import option, parse


@dataclass(frozen=True)
class GenericProgramParams:
    """Hyperparameters of the generic program (ch. 6 recipe)."""

    samples_per_iteration: int = option(500, "new random-action samples between policy iterations", min=1)
    lspi_iterations: int = option(8, "at most this many LSPI iterations after each exploration phase", min=1)
    max_trace: int = option(60, "longest greedy trace recorded from a start state", min=1)
    gamma: float = option(0.9, "LSPI discount", min=0.0, max=0.999)
    ridge: float = option(1e-3, "LSPI ridge regulariser", min=0.0)
    dims: int = option(2, "embedding dimensions (classical MDS)", min=1)
    components: int = option(8, "PCA components of the observations", min=1)
    centres: int = option(60, "radial basis functions in the PCA space", min=1)
    width: float = option(1.0, "RBF width, in units of the median spacing of the centres", min=0.01)
    projection: int = option(256, "observations longer than this are randomly projected to it first", min=8)
    reservoir: int = option(1000, "observations kept (a uniform sample of all seen) to fit PCA and centres", min=10)
    max_samples: int = option(5000, "LSPI samples kept (the newest)", min=10)
    max_categories: int = option(4096, "an integer sensor with at most this many values is a state id", min=2)
    action_levels: int = option(3, "values per dimension when a box action space is discretised", min=2)
    watch_after: float = option(
        0.9, "the drop detector watches once a sweep reaches the goal from this fraction of starts", min=0.0, max=1.0
    )
    learn_lag: int = option(
        75,
        "acts between the start of a background learning job (feature refit + LSPI, MDS) and the act "
        "that uses it (short: the samples taken meanwhile come from the previous policy)",
        min=1,
    )


def _action_table(spec: WorldSpec, levels: int) -> np.ndarray:
    """The action values the program chooses among: (n_actions, dims)."""
    a = spec.action_space
    if a.discrete:
        return np.arange(a.n, dtype=np.float64)[:, None]
    if len(a.low) > 4:
        raise SpecMismatch(f"generic program: {len(a.low)} action dimensions; at most 4 are discretised")
    grids = [np.linspace(lo, hi, levels) for lo, hi in zip(a.low, a.high, strict=True)]
    return np.array(list(itertools.product(*grids)), dtype=np.float64)


class _RBFFeatures:
    """LSPI basis over observation ids: id -> stored (projected) observation -> PCA -> RBFs, one
    block of `centres + 1` features per action. Refitted between policy iterations."""

    def __init__(self, store: np.ndarray, n_actions: int, n_centres: int) -> None:
        self.store = store
        self.n_actions = n_actions
        self.m = n_centres + 1
        self.mean = np.zeros(store.shape[1])
        self.axes = np.zeros((store.shape[1], 0))
        self.scale = np.ones(0)
        self.centres = np.zeros((0, 0))
        self.width = 1.0
        self._cache = np.zeros((store.shape[0], self.m))  # features of stored rows under this fit
        self._cached = np.zeros(store.shape[0], dtype=bool)

    @property
    def k(self) -> int:
        return self.m * self.n_actions

    def forget(self, rows: np.ndarray | int | slice) -> None:
        """Stored rows were overwritten: their cached features are stale."""
        self._cached[rows] = False

    def fit(self, X: np.ndarray, components: int, n_centres: int, width: float) -> None:
        """PCA of the sample `X` (rows), then RBF centres by farthest-point sampling in its scores,
        starting from the point nearest the mean (deterministic given the sample)."""
        self._cached[:] = False
        self.mean = X.mean(axis=0)
        Xc = X - self.mean
        _, s, vt = np.linalg.svd(Xc, full_matrices=False)
        c = max(1, min(components, int((s > 1e-9 * max(s[0], 1e-300)).sum()) if s.size else 1))
        self.axes = np.ascontiguousarray(vt[:c].T)  # the layout a restored copy has: same rounding
        Z = Xc @ self.axes
        self.scale = Z.std(axis=0) + 1e-12
        Z = Z / self.scale
        n = min(n_centres, Z.shape[0])
        chosen = [int(np.linalg.norm(Z, axis=1).argmin())]
        dist = np.linalg.norm(Z - Z[chosen[0]], axis=1)
        for _ in range(1, n):
            i = int(dist.argmax())
            chosen.append(i)
            dist = np.minimum(dist, np.linalg.norm(Z - Z[i], axis=1))
        centres = Z[chosen]
        if centres.shape[0] < n_centres:  # fewer distinct points than centres: repeat (features stay finite)
            centres = np.resize(centres, (n_centres, centres.shape[1]))
        self.centres = centres
        d = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=2)
        d[np.diag_indices_from(d)] = np.inf
        nearest = d.min(axis=1)
        spacing = float(np.median(nearest[np.isfinite(nearest) & (nearest > 0)])) if np.any(nearest > 0) else 1.0
        self.width = width * (spacing if np.isfinite(spacing) and spacing > 0 else 1.0)

    def features(self, X: np.ndarray) -> np.ndarray:
        """RBF features (with a constant) of raw (projected) observations: (n, m). Each row is
        computed on its own (einsum and broadcasting, not BLAS, whose rounding depends on the batch),
        so a row's features do not depend on which rows it was computed with: a run restored from a
        checkpoint or replayed offline computes exactly the same numbers."""
        Z = np.einsum("nd,dc->nc", np.atleast_2d(X) - self.mean, self.axes) / self.scale
        d2 = ((Z[:, None, :] - self.centres[None, :, :]) ** 2).sum(axis=2)
        return np.hstack([np.ones((Z.shape[0], 1)), np.exp(-0.5 * d2 / self.width**2)])

    def phi(self, ids: np.ndarray, actions: np.ndarray) -> sp.csr_matrix:
        rows = np.asarray(ids, dtype=np.int64).reshape(-1) % self.store.shape[0]
        a = np.asarray(actions, dtype=np.int64).reshape(-1)
        todo = np.unique(rows[~self._cached[rows]])
        if todo.size:
            self._cache[todo] = self.features(self.store[todo].astype(np.float64))
            self._cached[todo] = True
        f = self._cache[rows]
        # one block of m features per row, at the column block of its action: sparse, 1/n_actions dense
        cols = (a[:, None] * self.m + np.arange(self.m)[None, :]).ravel()
        return sp.csr_matrix((f.ravel(), cols, np.arange(0, f.size + 1, self.m)), shape=(rows.size, self.k))


def _basis_state(b: _RBFFeatures) -> dict[str, Any]:
    return {
        "mean": b.mean.copy(),
        "axes": b.axes.copy(),
        "scale": b.scale.copy(),
        "centres": b.centres.copy(),
        "width": b.width,
    }


def _set_basis(b: _RBFFeatures, s: dict[str, Any]) -> None:
    b.mean, b.axes, b.scale = (np.array(s[k], dtype=np.float64) for k in ("mean", "axes", "scale"))
    b.centres, b.width = np.array(s["centres"], dtype=np.float64), float(s["width"])
    b.forget(slice(None))


def iterate_job(
    n_states: int,
    n_actions: int,
    gamma: float,
    ridge: float,
    capacity: int,
    iterations: int,
    samples: dict[str, Any],
    store: np.ndarray | None,
    basis: dict[str, Any] | None,
    refit: np.ndarray | None,
    fit: dict[str, Any],
) -> dict[str, Any]:
    """Feature refit (when `refit` holds the reservoir sample) and up to `iterations` LSPI
    iterations over a snapshot of the samples: the new basis (if refitted), weights, iterations
    done and the last change. Tabular when `store` is None. A pure function, run off the act path."""
    if store is None:
        lspi = LSPI(TabularBasis(n_states, n_actions), gamma=gamma, ridge=ridge, capacity=capacity)
    else:
        rbf = _RBFFeatures(np.asarray(store), n_actions, int(fit["centres"]))
        if refit is not None:
            rbf.fit(
                np.asarray(refit, dtype=np.float64), int(fit["components"]), int(fit["centres"]), float(fit["width"])
            )
        else:
            assert basis is not None
            _set_basis(rbf, basis)
        lspi = LSPI(rbf, gamma=gamma, ridge=ridge, capacity=capacity)
    lspi.restore(samples)
    change, done = 0.0, 0
    for _ in range(iterations):  # policy iteration until the weights settle
        change = lspi.iterate()
        done += 1
        if change <= 1e-3 * (float(np.linalg.norm(lspi.w)) + 1e-12):
            break
    return {
        "w": lspi.w,
        "iterations": done,
        "change": change,
        "basis": None if store is None or refit is None else _basis_state(rbf),
    }


def embed_job(traces: list[list[int]], actions: np.ndarray | None, dims: int) -> dict[str, Any]:
    """Trace distances (edit distance of discrete actions; padded sum of the action values when
    `actions` is the table of a discretised box) and classical MDS. A pure function, run off the act path."""
    if actions is None:
        D = trace_distances(traces, kind="edit", substitution_cost=2)
    else:
        table = np.asarray(actions)
        D = trace_distances([table[np.asarray(t, dtype=np.int64)] for t in traces], kind="continuous")
    mds = classical_mds(D, dims)
    return {"coordinates": mds.coordinates, "eigenvalues": mds.eigenvalues}


class GenericProgram(Program):
    """Learns any world that declares start states: see the module docstring."""

    name = "generic"
    Params = GenericProgramParams
    _rbf: _RBFFeatures  # the LSPI basis when observations are not state ids
    detector_params = {"warmup": 30, "rate": 0.05}

    def __init__(
        self, spec: WorldSpec, seed: int = 0, params: GenericProgramParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(spec, seed)
        self.params = prm = parse(GenericProgramParams, overrides, name=self.name, base=params)
        if not spec.sensors:
            raise SpecMismatch(f"generic program: world {spec.world_id} declares no sensors")
        self.actions = _action_table(spec, prm.action_levels)
        self.n_actions = self.actions.shape[0]
        self.discrete = spec.action_space.discrete
        s0 = spec.sensors[0]
        self.tabular = (
            len(spec.sensors) == 1
            and np.dtype(s0.dtype).kind in "iu"
            and int(np.prod(s0.shape)) == 1
            and 0 < s0.high - s0.low + 1 <= prm.max_categories
        )
        if self.tabular:
            self.low = int(s0.low)
            self.n_states = int(s0.high - s0.low) + 1
            basis: Any = TabularBasis(self.n_states, self.n_actions)
        else:
            d = sum(int(np.prod(s.shape)) for s in spec.sensors)
            lo = np.concatenate([np.full(int(np.prod(s.shape)), s.low, float) for s in spec.sensors])
            hi = np.concatenate([np.full(int(np.prod(s.shape)), s.high, float) for s in spec.sensors])
            span = np.where(hi > lo, hi - lo, 1.0)
            self._lo, self._span = lo, span
            self.dim = min(d, prm.projection)
            proj_rng = np.random.default_rng([seed, 6])  # fixed per seed: stored vectors stay comparable
            self._proj = proj_rng.standard_normal((d, self.dim)) / np.sqrt(self.dim) if d > prm.projection else None
            self._store = np.zeros((2 * prm.max_samples + 2, self.dim), dtype=np.float32)
            self._reservoir = np.zeros((prm.reservoir, self.dim), dtype=np.float32)
            self._rbf = basis = _RBFFeatures(self._store, self.n_actions, prm.centres)
        self._next_id = 0
        self._seen = 0
        self._fitted_at = 0
        self.lspi = LSPI(basis, gamma=prm.gamma, ridge=prm.ridge, capacity=prm.max_samples)
        self.phase = "explore"
        self.new_samples = 0
        self.relearn_at: int | None = None
        self._prev: tuple[int, int] | None = None
        self._sweep = StartStateSweep(spec.n_starts, prm.max_trace)
        self._visited: set[tuple[bytes, int]] = set()
        self._perf: list[float] = []
        self._said_no_starts = False
        self._watching = False  # the detector sees trace scores only once the policy is good
        self.detector_params = {"warmup": max(30, spec.n_starts), "rate": 0.05}
        self._pending_embedding: dict[str, Any] | None = None  # what the embed job in flight is of
        self.use_background(prm.learn_lag)

    # observations -> states --------------------------------------------------------------------
    def _vector(self, obs: Observation) -> np.ndarray:
        parts = []
        for s in self.spec.sensors:
            a = obs.tensors.get(s.name)
            if a is None:
                raise SpecMismatch(f"observation step {obs.step} has no tensor {s.name!r}")
            parts.append(np.asarray(a, dtype=np.float64).reshape(-1))
        x = (np.concatenate(parts) - self._lo) / self._span
        return x @ self._proj if self._proj is not None else x

    def _state(self, obs: Observation) -> int:
        """The LSPI state of an observation met while exploring: a state id, or a new store id."""
        if self.tabular:
            s = int(np.asarray(obs.tensors[self.spec.sensors[0].name]).reshape(-1)[0]) - self.low
            if not 0 <= s < self.n_states:
                raise SpecMismatch(f"state id {s + self.low} outside the declared range")
            return s
        x = self._vector(obs)
        i = self._next_id
        self._next_id += 1
        self._store[i % self._store.shape[0]] = x
        self._rbf.forget(i % self._store.shape[0])
        self._seen += 1  # reservoir sampling: every observation seen is equally likely to be kept
        r = self._reservoir.shape[0]
        if self._seen <= r:
            self._reservoir[self._seen - 1] = x
        else:
            j = int(self.rng.integers(self._seen))
            if j < r:
                self._reservoir[j] = x
        return i

    def _q(self, obs: Observation) -> np.ndarray:
        w = self.lspi.w.reshape(self.n_actions, -1)
        if self.tabular:
            return self.lspi.q(self._state(obs))
        f = self._rbf.features(self._vector(obs))[0]
        return w @ f

    # the program -------------------------------------------------------------------------------
    def _iterate(self) -> None:
        """Start the refit + policy iteration job on a snapshot; `_iterated` swaps its result in."""
        prm = self.params
        refit = None
        if not self.tabular and self._seen >= 2 * self._fitted_at:
            # refit while experience still doubles; later fits would only reshuffle a settled basis
            n = min(self._seen, self._reservoir.shape[0])
            refit = self._reservoir[:n].astype(np.float64)
            self._fitted_at = self._seen
        assert self.background is not None
        self.background.submit(
            "lspi",
            iterate_job,
            n_states=self.n_states if self.tabular else 0,
            n_actions=self.n_actions,
            gamma=self.lspi.gamma,
            ridge=self.lspi.ridge,
            capacity=self.lspi.capacity,
            iterations=prm.lspi_iterations,
            samples=self.lspi.samples(),
            store=None if self.tabular else self._store.copy(),
            basis=None if self.tabular else _basis_state(self._rbf),
            refit=refit,
            fit={"components": prm.components, "centres": prm.centres, "width": prm.width},
        )

    def _iterated(self, result: dict[str, Any], step: int) -> None:
        """The job's basis and weights swapped in; report the policy iteration."""
        if result["basis"] is not None:
            _set_basis(self._rbf, result["basis"])
        self.lspi.w = np.asarray(result["w"], dtype=np.float64)
        self.lspi.iterations += int(result["iterations"])
        self.emit_lspi_iteration(self.lspi, result["change"], step)

    def _key(self, obs: Observation) -> bytes:
        return b"".join(np.ascontiguousarray(obs.tensors[s.name]).tobytes() for s in self.spec.sensors)

    def _choose(self, obs: Observation, trace: list[int]) -> int:
        if not trace:
            self._visited = set()
        self._visited.add((self._key(obs), trace[-1] if trace else -1))
        return self.lspi.choose(self._q(obs), trace[-1] if trace else None)

    def _cycle(self, obs: Observation, trace: list[int]) -> bool:
        """A deterministic greedy policy that meets the same observation after the same action again
        is in a loop that never ends: the trace stops there."""
        return bool(trace) and (self._key(obs), trace[-1]) in self._visited

    def _embed(self, step: int, relearned: bool) -> None:
        """Start the distances + MDS job on the sweep's traces; `relearned`: the first good policy
        after a drop (the trigger will say so, with the drop's step)."""
        traces = [list(t) for t in self._sweep.traces]
        n = len(traces)
        assert self.background is not None
        self.background.submit(
            "embed",
            embed_job,
            traces=traces,
            actions=None if self.discrete else self.actions.copy(),
            dims=self.params.dims,
        )
        self._pending_embedding = {
            "step": step,
            "n": n,
            "relearned": relearned,
            "drop_step": self.relearn_at if relearned else None,
            "iteration": self.lspi.iterations,
            "lspi_iterations": float(self.lspi.iterations),
            "samples": float(self.lspi.n_samples),
            "goal_reached_fraction": self._sweep.rewarded / n,
            "mean_trace_length": float(np.mean([len(t) for t in traces])),
            "rewarded": self._sweep.rewarded,
        }
        if relearned:
            self.relearn_at = None

    def _embedded(self, result: dict[str, Any]) -> None:
        """The distances + MDS job's result swapped in: emit Embedding vN (and `relearned`)."""
        p = self._pending_embedding
        assert p is not None
        self._pending_embedding = None
        n, step = int(p["n"]), int(p["step"])
        eig = np.asarray(result["eigenvalues"])
        self.emit(
            EmbeddingOutput(
                Trigger.RELEARNED if p["relearned"] else Trigger.POLICY_ITERATION,
                tuple(range(n)),
                np.asarray(result["coordinates"]),
                tuple(float(e) for e in eig[: min(10, len(eig))]),
                step,
                {k: float(p[k]) for k in ("lspi_iterations", "samples", "goal_reached_fraction", "mean_trace_length")},
                iteration=int(p["iteration"]),
                drop_step=None if p["drop_step"] is None else int(p["drop_step"]),
            )
        )
        if p["relearned"]:
            self.emit(
                EventOutput(
                    EventKind.RELEARNED,
                    f"the policy reaches the goal again from {int(p['rewarded'])} of {n} starts",
                    step,
                    {"drop_step": float(p["drop_step"] or 0)},
                )
            )

    def act(self, obs: Observation) -> Decision:
        s: int | None = None
        if self.phase == "explore":
            s = self._state(obs)
            if obs.t > 0 and self._prev is not None:
                ps, pa = self._prev
                self.lspi.learn_one(ps, pa, obs.reward, s, obs.done)
                self.new_samples += 1
            self._prev = None
        assert self.background is not None
        iterated = False
        for name, result in self.background.tick():
            if name == "embed":
                self._embedded(result)
            elif name == "lspi":
                self._iterated(result, obs.step)
                iterated = True
        if self.phase == "explore":
            assert s is not None
            if iterated and self.spec.n_starts >= 2:
                self._prev = None
                self.phase = "embed"
                self._sweep = StartStateSweep(self.spec.n_starts, self.params.max_trace)
                return self._sweep.begin()
            if self.new_samples >= self.params.samples_per_iteration and not self.background.pending("lspi"):
                self.new_samples = 0
                self._iterate()
                if self.spec.n_starts < 2 and not self._said_no_starts:
                    self._said_no_starts = True
                    self.emit(
                        EventOutput(
                            EventKind.POLICY_ITERATION,
                            f"world declares {self.spec.n_starts} start states: it is learned, not embedded",
                            obs.step,
                            reason="no_start_states",
                        )
                    )
            if obs.done:
                return Decision(reset=True, start=-1)
            a = int(self.rng.integers(self.n_actions))
            self._prev = (s, a)
            return Decision(tuple(float(v) for v in self.actions[a]))

        done_before = len(self._sweep.traces)
        dec = self._sweep.step(obs, self._choose, self._cycle)
        if len(self._sweep.traces) > done_before:
            trace = self._sweep.traces[-1]
            reached = obs.reward > 0 or (obs.done and not trace)
            if self._watching:
                self._perf.append(self.params.gamma ** len(trace) if reached else 0.0)
        elif not dec.reset:
            dec = Decision(tuple(float(v) for v in self.actions[int(dec.values[0])]))
        if self._sweep.finished:
            good = self._sweep.rewarded >= self.params.watch_after * len(self._sweep.traces)
            self._watching = self._watching or good
            self._embed(obs.step, relearned=good and self.relearn_at is not None)
            self.phase = "explore"
        return dec

    def performance(self, obs: Observation) -> float | None:
        return self._perf.pop(0) if self._perf else None

    def on_drop(self, step: int) -> None:
        """The body changed: what was learned no longer holds; relearn from fresh samples."""
        self.relearn_at = step
        self.lspi.reset()
        assert self.background is not None
        self.background.discard("lspi")  # an iteration over the dropped samples is never swapped in
        self.new_samples = 0
        self._prev = None
        self.phase = "explore"
        self._perf.clear()
        self._watching = False
        self.emit(
            EventOutput(EventKind.RELEARNING, "samples and policy dropped; relearning from fresh experience", step)
        )

    def world_restarted(self) -> None:
        self._prev = None
        self._sweep.interrupted()
        self._visited = set()

    # saved state ---------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            **super().state(),
            "lspi": self.lspi.state(),
            "phase": self.phase,
            "new_samples": self.new_samples,
            "relearn_at": self.relearn_at,
            "prev": None if self._prev is None else list(self._prev),
            "sweep": self._sweep.state(),
            "perf": list(self._perf),
            "next_id": self._next_id,
            "seen_count": self._seen,
            "fitted_at": self._fitted_at,
            "said_no_starts": self._said_no_starts,
            "watching": self._watching,
            "pending_embedding": None if self._pending_embedding is None else dict(self._pending_embedding),
            # (observation, previous action) pairs met on the trace in progress: its cycle check
            "visited": sorted([key.hex(), a] for key, a in self._visited),
        }
        if not self.tabular:
            out.update(store=self._store.copy(), reservoir=self._reservoir.copy(), basis=_basis_state(self._rbf))
        return out

    def restore(self, state: dict[str, Any]) -> None:
        super().restore(state)
        self.lspi.restore(state["lspi"])
        self.phase, self.new_samples = str(state["phase"]), int(state["new_samples"])
        self.relearn_at = None if state["relearn_at"] is None else int(state["relearn_at"])
        self._prev = None if state["prev"] is None else (int(state["prev"][0]), int(state["prev"][1]))
        self._sweep = StartStateSweep(self.spec.n_starts, self.params.max_trace)
        self._sweep.restore(state["sweep"])
        self._perf = [float(v) for v in state["perf"]]
        self._next_id, self._seen = int(state["next_id"]), int(state["seen_count"])
        self._fitted_at = int(state["fitted_at"])
        self._said_no_starts = bool(state["said_no_starts"])
        self._watching = bool(state["watching"])
        pending = state.get("pending_embedding")
        self._pending_embedding = None if pending is None else dict(pending)
        self._visited = {(bytes.fromhex(str(h)), int(a)) for h, a in state.get("visited", [])}
        if not self.tabular:
            self._store[...] = np.asarray(state["store"], dtype=np.float32)
            self._reservoir[...] = np.asarray(state["reservoir"], dtype=np.float32)
            _set_basis(self._rbf, state["basis"])


__all__ = ["GenericProgram", "GenericProgramParams"]
