"""`sme bench changes`: the field's scorecard for noticing a body change and relearning after it.

Per zoo world (in-process, seeded, as `sme bench zoo` runs them, each wrapped in the generic body
changes), per change kind and seed: the generic program learns until its policy is watched (its
detector fed and warmed up), the change is applied live (the agent is not told), and the run goes on
until the map is relearned or the budget ends. Reported: detection delay (steps, seconds, and sweeps
of the start states: stream samples / starts), missed detections, false alarms per 100,000 steps
(drops before the change, and a whole unperturbed run per world and seed), steps to the relearned
map (the first version, from the first relearned one on, within 1.5x the error before the change)
and its error against the world's truth beside the changed body's reference (its map learned from
scratch: a changed body can draw a worse map by its nature), and the harm of the change: the drop of the watched stream's mean
in the first sweep after it (1 - the fraction of starts the accepted policy still reaches, in a
deterministic world). Beside ours, river's ADWIN and Page-Hinkley (mode down) score the same
stream: a second run of the same seed in which the agent does not react (its detector only
records), so every detector sees the changed body's stream for as long as it needs; ours is scored
on it as well (it equals the live delay: the runs are the same until the first alarm)."""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.agent.detectors import DEFAULT_DETECTOR, DropDetector, make_detector
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol.messages import Control, Embedding, EventKind
from sensorimotor.tools.bench.changes_families import FAMILIES
from sensorimotor.tools.bench.changes_kinds import CHANGES, FULL, NONE, QUICK, Budget, Change
from sensorimotor.tools.bench.zoo import ZOO, ZooWorld
from sensorimotor.tools.common import UsageError, require
from sensorimotor.tools.inprocess import InProcessRun, run_inprocess
from sensorimotor.worlds.body_changes.layer import BodyChanges
from sensorimotor.worlds.registry import make_world

#: The zoo worlds the scorecard runs by default: deterministic worlds whose map converges
DEFAULT_WORLDS = (
    "FrozenLake 8x8",
    "CliffWalking",
    "MiniGrid Empty 8x8",
    "FrozenLake random 10x10 (map 0), not slippery",
)


class Tap:
    """Wraps the agent's detector where the link calls it: keeps every value it is fed, the step
    each came at and where the link reset it; with `react` False it never fires (the agent then
    does not notice: the stream goes on under the changed body)."""

    def __init__(self, detector: DropDetector, react: bool = True) -> None:
        self.detector, self.react = detector, react
        self.values: list[float] = []
        self.resets: list[int] = []  # indices into `values` where the link reset the detector
        self.alarms: list[int] = []  # indices of the values that fired
        self.step = 0  # set by the runner before each step
        self.steps: list[int] = []
        self.since_reset = 0
        update, reset = detector.update, detector.reset

        def tapped_update(x: float) -> bool:
            self.values.append(float(x))
            self.steps.append(self.step)
            self.since_reset += 1
            fired = bool(update(x)) and self.react
            if fired:
                self.alarms.append(len(self.values) - 1)
                self.since_reset = 0
            return fired

        def tapped_reset() -> None:
            self.resets.append(len(self.values))
            self.since_reset = 0
            reset()

        setattr(detector, "update", tapped_update)  # noqa: B010 (an instance's method, replaced)
        setattr(detector, "reset", tapped_reset)  # noqa: B010


def score(make: Callable[[], Any], values: list[float], resets: list[int], change: int) -> tuple[int, int | None]:
    """(false alarms before `change`, delay in samples of the first alarm at or after it) of a
    detector made by `make` on `values`, made afresh where the agent's detector was reset."""
    d, fa = make(), 0
    marks = set(resets)
    for i, v in enumerate(values):
        if i in marks and i > 0:
            d = make()
        if d.update(float(v)):
            if i < change:
                fa += 1
            else:
                return fa, i - change
    return fa, None


def peers(params: dict[str, Any]) -> dict[str, Callable[[], Any]]:
    """Ours (the agent's default detector with the program's settings) and river's ADWIN and
    Page-Hinkley (mode down) with their defaults."""
    from sensorimotor.tools.bench.detectors import _River

    drift = require("river.drift", package="river")
    return {
        "ours": lambda: make_detector(DEFAULT_DETECTOR, **params),
        "adwin": lambda: _River(drift.ADWIN, "river.ADWIN"),
        "page_hinkley": lambda: _River(lambda: drift.PageHinkley(mode="down"), "river.PageHinkley"),
    }


@dataclass
class _Live:
    """What one run saw: the step the change was applied at, its stream index and wall time."""

    at: int | None = None
    sample: int | None = None
    t: float | None = None
    t_detected: float | None = None


def _world(z: ZooWorld, seed: int) -> BodyChanges:
    build = getattr(z, "build", None)  # a family of our own worlds (changes_families) builds its own
    return build(seed) if build is not None else BodyChanges(make_world(z.world, None, seed, z.params))


def relearned_version(z: ZooWorld, e: Embedding, run: InProcessRun, at: int) -> bool:
    """Whether `e` is a version of the relearned map: one that names the drop, or, for a family
    whose program names only its first and then refines the map periodically (the retina and the
    roving eye: changes_families), any version after a drop detected since the change at `at`."""
    if e.drop_step is not None:
        return True
    return bool(getattr(z, "refines", False)) and any(
        at < d.step <= e.step for d in run.events(EventKind.DROP_DETECTED)
    )


def sweep_len(z: ZooWorld, spec: Any) -> int:
    """Stream samples per sweep: the start states, or a family's own count (a world without them)."""
    return int(getattr(z, "sweep", 0) or spec.n_starts)


def _run(
    z: ZooWorld,
    ch: Change,
    seed: int,
    budget: Budget,
    react: bool,
    stop: Callable[[InProcessRun, _Live, Tap], bool],
    at_start: bool = False,
) -> tuple[InProcessRun, _Live, Tap, Any, float]:
    """One seeded run of `z` with change `ch` applied once the policy is watched and the detector
    warmed up (`before` steps at least), or (`at_start`) after the first step, before anything is
    learned; returns the run, when the change came, the tap, the world's spec and the wall time."""
    w = _world(z, seed)
    with w:
        spec = w.spec()
        program = make_program(spec, seed, **z.program)
        params = dict(getattr(program, "detector_params", {}) or {})
        tap = Tap(make_detector(DEFAULT_DETECTOR, **params), react)
        warm = int(params.get("warmup", 100)) + 2 * sweep_len(z, spec)
        live = _Live()
        t0 = time.perf_counter()

        def on_step(k: int, obs: Any) -> None:
            tap.step = k

        def perturb(k: int) -> Control | None:
            if ch.kind is None or live.at is not None:
                return None
            if not at_start and (k < budget.before or tap.since_reset < warm):
                return None
            live.at, live.sample, live.t = k, len(tap.values), time.perf_counter()
            return Control(w.world_id, ch.kind, dict(ch.params))

        def on_output(msg: Any) -> None:
            if (
                getattr(msg, "kind", None) == EventKind.DROP_DETECTED
                and live.at is not None
                and live.t_detected is None
            ):
                live.t_detected = time.perf_counter()

        steps = budget.quiet if ch.kind is None else budget.ready_by + budget.after
        run = run_inprocess(
            w,
            program,
            steps,
            detector=tap.detector,
            on_step=on_step,
            perturb=perturb,
            on_output=on_output,
            stop_when=lambda r: (
                stop(r, live, tap) or (ch.kind is not None and (live.at is None and r.steps >= budget.ready_by))
            ),
        )
        return run, live, tap, spec, time.perf_counter() - t0


def _relearned(z: ZooWorld, run: InProcessRun, at: int) -> list[Embedding]:
    """The maps of the relearned policy: the first version after the change that is a relearned
    one (`relearned_version`), and every version after it (a later one may be better: the first
    good sweep's policy can still take detours among states not all met yet)."""
    embeddings = run.embeddings
    first = next((i for i, e in enumerate(embeddings) if e.step > at and relearned_version(z, e, run, at)), None)
    return [] if first is None else [e for e in embeddings[first:] if e.procrustes_error is not None]


def _error(e: Embedding) -> float:
    return float(e.procrustes_error if e.procrustes_error is not None else np.nan)


def from_scratch(z: ZooWorld, ch: Change, seed: int, budget: Budget) -> float | None:
    """The changed body's own map: the error (against the world's truth) of the last map the program
    makes of the changed body when it learns it from scratch, in as many steps as the live run has
    before and after the change (None: it makes none). A relearned map is held to the larger of
    this and the error before the change: relearning cannot beat learning the new body afresh (a
    motor of double gain skips every other cell: its traces are another map, see
    docs/body-changes.md)."""
    run, *_ = _run(z, ch, seed, budget, True, lambda r, lv, t: r.steps >= budget.before + budget.after, at_start=True)
    maps = [e for e in run.embeddings if e.procrustes_error is not None]
    return _error(maps[-1]) if maps else None


def run_one(z: ZooWorld, ch: Change, seed: int, budget: Budget = FULL) -> dict[str, Any]:
    """One (world, change, seed) of the scorecard: the changed body learned from scratch (its
    reference), the live run (the agent notices and relearns) and, for a change, the same seed
    again with the agent not reacting (the detectors' stream)."""
    fresh = None if ch.kind is None else from_scratch(z, ch, seed, budget)

    def relearned(r: InProcessRun, live: _Live, tap: Tap) -> bool:
        if live.at is None:
            return False
        if r.steps >= live.at + budget.after:
            return True
        pre = [e for e in r.embeddings if e.step <= live.at and e.procrustes_error is not None]
        post = _relearned(z, r, live.at)
        if not (pre and post):
            return False
        bar = _error(pre[-1]) if fresh is None else max(_error(pre[-1]), fresh)
        return bool(_error(post[-1]) <= 1.5 * bar + 1e-9)

    run, live, tap, spec, seconds = _run(z, ch, seed, budget, True, relearned)
    drops = [e.step for e in run.events(EventKind.DROP_DETECTED)]
    row: dict[str, Any] = {
        "bench": "changes",
        "world": z.label,
        "name": z.world,
        "change": ch.label,
        "kind": ch.kind,
        "params": ch.params,
        "seed": seed,
        "n_starts": sweep_len(z, spec),
        "steps": run.steps,
        "seconds": round(seconds, 1),
    }
    if ch.kind is None:
        return row | {"unperturbed_steps": run.steps, "false_alarms": len(drops)}
    if live.at is None:
        return row | {"applied": False, "note": f"the policy was not watched within {budget.ready_by} steps"}
    before = [e for e in run.embeddings if e.step <= live.at and e.procrustes_error is not None]
    pre_err = _error(before[-1]) if before else None
    detected = next((d for d in drops if d > live.at), None)
    after = _relearned(z, run, live.at)
    first = after[0] if after else None
    good = next((e for e in after if pre_err is not None and _error(e) <= 1.5 * pre_err + 1e-9), None)
    ref = pre_err if fresh is None or pre_err is None else max(pre_err, fresh)
    near = next((e for e in after if ref is not None and _error(e) <= 1.5 * ref + 1e-9), None)
    row |= {
        "applied": True,
        "changed_at": live.at,
        "unperturbed_steps": live.at,
        "false_alarms": sum(d <= live.at for d in drops),
        "error_before": pre_err,
        "detected": detected is not None,
        "delay_steps": None if detected is None else detected - live.at,
        "delay_seconds": None if live.t_detected is None or live.t is None else round(live.t_detected - live.t, 3),
        "delay_samples_live": None
        if not tap.alarms or live.sample is None or tap.alarms[-1] < live.sample
        else next(a for a in tap.alarms if a >= live.sample) - live.sample,
        "steps_to_relearned": None if first is None else first.step - live.at,
        "relearned_error": None if first is None else _error(first),
        "steps_to_1.5x": None if good is None else good.step - live.at,
        "error_at_1.5x": None if good is None else _error(good),
        # the changed body's reference: its map learned from scratch, and the larger of that and before
        "fresh_error": fresh,
        "error_reference": ref,
        "steps_to_reference": None if near is None else near.step - live.at,
        "error_at_reference": None if near is None else _error(near),
        "final_error": _error(run.embeddings[-1]) if run.embeddings else None,
        "versions_repeat": _repeats([e.version for e in run.embeddings]),
    }
    # the same seed, the agent not reacting: the stream every detector scores
    n = sweep_len(z, spec)
    need = 20 * n

    def enough(r: InProcessRun, lv: _Live, t: Tap) -> bool:
        if lv.sample is None or lv.at is None:
            return False
        return len(t.values) - lv.sample >= need or r.steps >= lv.at + budget.after

    _, blind, btap, _, _ = _run(z, ch, seed, budget, False, enough)
    if blind.sample is None:
        return row | {"stream": None}
    post = btap.values[blind.sample : blind.sample + n]
    pre = btap.values[max(0, blind.sample - n) : blind.sample]
    harm = None
    if hasattr(z, "harm"):  # a family whose stream is not a goal fraction says how it counts one
        harm = z.harm(pre, post)
    elif pre and post and np.mean(pre) > 0:
        harm = float(1.0 - np.mean(post) / np.mean(pre))
    row["harm"] = harm
    row["stream_samples"] = len(btap.values)
    row["same_change_step"] = blind.at == live.at
    params = dict(getattr(make_program(spec, seed, **z.program), "detector_params", {}) or {})
    for name, make in peers(params).items():
        fa, d = score(make, btap.values, btap.resets, blind.sample)
        row[f"{name}_delay_samples"] = d
        row[f"{name}_delay_sweeps"] = None if d is None else round((d + 1) / n, 3)
        row[f"{name}_false_alarms"] = fa
    return row


def _repeats(versions: list[int]) -> int:
    """How many versions were not above the one before."""
    return sum(b <= a for a, b in zip(versions, versions[1:], strict=False))


def _median(vals: list[float]) -> float | None:
    return float(np.median(vals)) if vals else None


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (world, change) over the seeds; a change is harmful when the first sweep after it lost
    >= 20 % of the stream's mean (the starts the accepted policy reached)."""
    out = []
    for key in dict.fromkeys((r["world"], r["change"]) for r in rows):
        rs = [r for r in rows if (r["world"], r["change"]) == key]
        applied = [r for r in rs if r.get("applied")]
        harmful = [r for r in applied if (r.get("harm") or 0.0) >= 0.2]
        s: dict[str, Any] = {"bench": "changes", "summary": True, "world": key[0], "change": key[1], "seeds": len(rs)}
        steps = sum(r.get("unperturbed_steps") or 0 for r in rs)
        fas = sum(r.get("false_alarms") or 0 for r in rs)
        s["unperturbed_steps"] = steps
        s["false_alarms_per_100k"] = round(fas / steps * 100_000, 2) if steps else None
        if rs[0]["kind"] is None:
            out.append(s)
            continue

        def med(k: str, among: list[dict[str, Any]] = applied) -> float | None:
            return _median([r[k] for r in among if r.get(k) is not None])

        s |= {
            "applied": len(applied),
            "harm": med("harm"),
            "harmful": len(harmful),
            "detected": sum(bool(r.get("detected")) for r in applied),
            "missed": sum(not r.get("detected") for r in harmful),
            "delay_steps": med("delay_steps"),
            "delay_seconds": med("delay_seconds"),
            "delay_sweeps": med("ours_delay_sweeps"),
            "adwin_delay_sweeps": med("adwin_delay_sweeps"),
            "page_hinkley_delay_sweeps": med("page_hinkley_delay_sweeps"),
            "adwin_missed": sum(r.get("adwin_delay_samples") is None for r in harmful),
            "page_hinkley_missed": sum(r.get("page_hinkley_delay_samples") is None for r in harmful),
            "steps_to_relearned": med("steps_to_relearned"),
            "steps_to_1.5x": med("steps_to_1.5x"),
            "error_before": med("error_before"),
            "relearned_error": med("relearned_error"),
            "error_at_1.5x": med("error_at_1.5x"),
            "relearned_within_1.5x": sum(r.get("steps_to_1.5x") is not None for r in applied if r.get("detected")),
            "fresh_error": med("fresh_error"),
            "steps_to_reference": med("steps_to_reference"),
            "error_at_reference": med("error_at_reference"),
            "within_reference": sum(r.get("steps_to_reference") is not None for r in applied if r.get("detected")),
        }
        ours, adwin = s["delay_sweeps"], s["adwin_delay_sweeps"]
        s["ours_over_adwin"] = None if ours is None or not adwin else round(ours / adwin, 3)
        out.append(s)
    return out


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:,.0f}" if abs(v) >= 1000 else f"{v:.3g}"
    return "-" if v is None else str(v)


def select(only: list[str] | None) -> list[ZooWorld]:
    """The zoo entries named (a whole label names that entry alone; else every label containing
    the name), or the default worlds; refused naming the valid ones."""
    every: tuple[ZooWorld, ...] = (*ZOO, *FAMILIES)
    labels = {z.label.lower(): z for z in every}
    if not only:
        return [labels[w.lower()] for w in DEFAULT_WORLDS]
    out: list[ZooWorld] = []
    for o in only:
        hit = [labels[o.lower()]] if o.lower() in labels else [z for z in every if o.lower() in z.label.lower()]
        if not hit:
            raise UsageError(f"no zoo world {o!r}; valid: {', '.join(z.label for z in every)}")
        out += [z for z in hit if z not in out]
    return out


def pick_changes(names: list[str] | None, among: tuple[Change, ...] = CHANGES) -> list[Change]:
    """The changes named (by label or kind; `none`: the unperturbed run alone), or every one, of
    `among` (a world's own list: changes_families)."""
    if not names:
        return list(among)
    if [n.lower() for n in names] == ["none"]:
        return []
    out = [c for c in among if any(n.lower() in (c.label.lower(), c.kind) for n in names)]
    unknown = [n for n in names if not any(n.lower() in (c.label.lower(), c.kind) for c in among)]
    if unknown:
        raise UsageError(f"no change {', '.join(unknown)}; valid: {', '.join(c.label for c in among)}, none")
    return out


def command(world: str, change: str, seeds: int) -> str:
    """The command that gives one row of the table alone."""
    c = "none" if change == NONE.label else change
    q = lambda t: f'"{t}"' if " " in t else t  # noqa: E731
    return f"sme bench changes --world {q(world)} --change {q(c)} --seeds {seeds}"


def render_scorecard(src: Any, text: str) -> str:
    """The docs' table (tools/docgen/results_doc.py): one row per (world, change) summary line of the kept
    output, each with the command that gives it alone."""
    rows = [json.loads(ln) for ln in text.splitlines() if ln.strip().startswith("{")]
    runs = [r for r in rows if not r.get("summary")]
    rows = summary(runs) if runs else rows  # from the runs themselves: every figure the code now reports
    head = (
        "| world | change | harm | missed / harmful | delay: steps | sweeps | ADWIN | Page-Hinkley | ours / ADWIN "
        "| false alarms / 100k steps | first map after: steps | its error | within 1.5x of the changed body: steps "
        "| its error (before; from scratch) | within 1.5x: of before | of the changed body | command |"
    )
    out = [head, "|" + "---|" * head.count(" | ") + "---|"]

    def f(v: Any, nd: int = 3) -> str:
        return "-" if v is None else f"{v:,.{nd}g}" if isinstance(v, float) and abs(v) < 1000 else f"{v:,.0f}"

    def g(v: Any) -> str:
        return "-" if v is None else str(v)

    for r in rows:
        if not r.get("summary"):
            continue
        cmd = f"`{command(r['world'], r['change'], r['seeds'])}`"
        if r["change"] == NONE.label:
            out.append(
                f"| {r['world']} | {r['change']} | | | | | | | | {f(r['false_alarms_per_100k'])} "
                f"in {r['unperturbed_steps']:,} | | | | | | | {cmd} |"
            )
            continue
        out.append(
            f"| {r['world']} | {r['change']} | {f(r['harm'], 2)} | {r['missed']} / {r['harmful']} "
            f"| {f(r['delay_steps'])} | {f(r['delay_sweeps'], 2)} | {f(r['adwin_delay_sweeps'], 2)} "
            f"| {f(r['page_hinkley_delay_sweeps'], 2)} | {f(r['ours_over_adwin'], 2)} "
            f"| {f(r['false_alarms_per_100k'])} in {r['unperturbed_steps']:,} | {f(r['steps_to_relearned'])} "
            f"| {f(r['relearned_error'])} | {f(r.get('steps_to_reference'))} "
            f"| {f(r.get('error_at_reference'))} ({f(r['error_before'])}; {f(r.get('fresh_error'))}) "
            f"| {r['relearned_within_1.5x']} of {r['detected']} | {g(r.get('within_reference'))} of {r['detected']} "
            f"| {cmd} |"
        )
    return "\n".join(out) + f"\n\nFrom `{src.command}` (its output: `docs/{src.file}`)."


def render_life(src: Any, text: str) -> str:
    """The docs' table of the life of changes: one row per world and seed."""
    rows = [json.loads(ln) for ln in text.splitlines() if ln.strip().startswith("{")]
    out = [
        "| world | seed | changes | noticed | relearned | steps from noticed to relearned: first | last | last / first "
        "| median delay (steps) | RSS at the first change | growth to the end | versions not rising |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]

    def g(v: Any) -> str:
        return "-" if v is None else f"{v:,}"

    for r in rows:
        if not r.get("life"):
            continue
        growth = "-" if r["rss_growth"] is None else f"{100 * r['rss_growth']:.1f} %"
        out.append(
            f"| {r['world']} | {r['seed']} | {r['changes']} | {r['detected']} | {r['relearned']} "
            f"| {g(r['first_steps_to_relearn'])} | {g(r['last_steps_to_relearn'])} | {g(r['last_over_first'])} "
            f"| {g(r['median_delay'])} | {r['rss_first_change_mb']} MB | {growth} "
            f"| {r['versions_repeat']} of {r['versions']} |"
        )
    return "\n".join(out) + f"\n\nFrom `{src.command}` (its output: `docs/{src.file}`)."


def _run_task(task: tuple[ZooWorld, Change, int, Budget]) -> dict[str, Any]:
    return run_one(*task)


def main(
    seeds: int = 3,
    quick: bool = False,
    only: list[str] | None = None,
    changes: list[str] | None = None,
    json_out: bool = False,
    workers: int = 1,
    quiet: bool = True,
) -> int:
    """Run the scorecard; one line per run (JSON with `json_out`) and the summary."""
    import importlib.util
    import multiprocessing as mp

    budget = QUICK if quick else Budget()
    tasks = []
    for z in select(only):
        if z.needs and importlib.util.find_spec(z.needs) is None:
            print(f"changes: {z.label}: skipped ({z.needs} is not installed)", file=sys.stderr)
            continue
        chosen = pick_changes(changes, getattr(z, "changes", ()) or CHANGES)
        chosen += [NONE] if quiet or changes == ["none"] else []
        b = getattr(z, "quick_budget" if quick else "budget", budget)  # a family's own budgets
        tasks += [(z, c, s, b) for c in chosen for s in range(seeds)]
    pool = mp.get_context("spawn").Pool(workers) if workers > 1 and len(tasks) > 1 else None
    rows: list[dict[str, Any]] = []
    try:
        for r in pool.imap(_run_task, tasks) if pool is not None else map(_run_task, tasks):
            rows.append(r)
            if json_out:
                print(json.dumps(r), flush=True)
            print(
                f"changes: {r['world']} / {r['change']} / seed {r['seed']}: delay {_fmt(r.get('delay_steps'))} steps, "
                f"harm {_fmt(r.get('harm'))}, relearned in {_fmt(r.get('steps_to_1.5x'))} steps "
                f"(error {_fmt(r.get('error_before'))} -> {_fmt(r.get('error_at_1.5x'))}), ADWIN "
                f"{_fmt(r.get('adwin_delay_samples'))} / ours {_fmt(r.get('ours_delay_samples'))} samples, "
                f"false alarms {r.get('false_alarms')} ({r['seconds']} s)",
                file=sys.stderr,
                flush=True,
            )
    finally:
        if pool is not None:
            pool.terminate()
    table = summary(rows)
    if json_out:
        for t in table:
            print(json.dumps(t))
        return 0
    cols = (
        "world",
        "change",
        "harm",
        "detected",
        "missed",
        "delay_steps",
        "delay_sweeps",
        "adwin_delay_sweeps",
        "page_hinkley_delay_sweeps",
        "ours_over_adwin",
        "false_alarms_per_100k",
        "steps_to_1.5x",
        "error_before",
        "error_at_1.5x",
        "fresh_error",
        "within_reference",
    )
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for t in table:
        print("| " + " | ".join(_fmt(t.get(c)) for c in cols) + " |")
    return 0


__all__ = ["CHANGES", "Budget", "Change", "Tap", "main", "peers", "run_one", "score", "select", "summary"]
