"""What a run of embeddings says, in words that are true: first, best and final error, whether the
last versions are near the best, and, when a world was not embedded or not scored, why and what to
do. Used by `sme demo`'s summary; pure functions over the messages the agent published."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from sensorimotor.protocol.messages import AgentEvent, Embedding

# The last versions are "near the best" when each is within this factor of the best error (or
# within NEAR_ABS of it, for errors so small that a ratio says nothing).
NEAR_FACTOR = 1.5
NEAR_ABS = 0.005
LAST = 3  # how many of the last versions are judged
GOOD = 0.05  # below this a map is good (the project's bar for a learned map)
POOR = 0.3  # above this it is not a map of the world (0 is perfect, about 1 a random one)


@dataclass(frozen=True)
class RunVerdict:
    """The summary of one world's embeddings.

    Attributes
    ----------
    lines : tuple of str
        The summary lines, for people.
    embedded : bool
        Whether the world was embedded at all (at least one Embedding).
    first, best, final : float or None
        Procrustes errors (None without truth or embeddings).
    near_best : bool or None
        Whether the last `LAST` versions are all near the best (None without scores).
    """

    lines: tuple[str, ...]
    embedded: bool
    first: float | None = None
    best: float | None = None
    final: float | None = None
    near_best: bool | None = None


def _scored(embeddings: Sequence[Embedding]) -> list[tuple[int, float]]:
    return [
        (e.version, float(e.procrustes_error))
        for e in embeddings
        if e.procrustes_error is not None and math.isfinite(e.procrustes_error)
    ]


def near(err: float, best: float) -> bool:
    """Whether `err` is near `best` (see `NEAR_FACTOR`, `NEAR_ABS`)."""
    return err <= best * NEAR_FACTOR or err - best <= NEAR_ABS


def verdict(
    embeddings: Sequence[Embedding],
    events: Sequence[AgentEvent] = (),
    has_truth: bool = True,
    n_starts: int | None = None,
    seconds: float | None = None,
) -> RunVerdict:
    """Judge one world's run from what the agent published.

    Parameters
    ----------
    embeddings : sequence of Embedding
        The world's embeddings, in order (policy maps are left out).
    events : sequence of AgentEvent
        The agent's events for the world (a ``no_start_states`` reason says it cannot be embedded).
    has_truth : bool, default=True
        Whether the world gives ground truth (without it nothing can be scored).
    n_starts : int or None, default=None
        The start states the world declares, if known.
    seconds : float or None, default=None
        How long the run was, for the advice to run longer.

    Returns
    -------
    RunVerdict
    """
    embeddings = [e for e in embeddings if e.trigger != "policy_map"]
    # only the program knows whether it embeds start states (the retina embeds its receptive fields)
    no_starts = any(ev.reason == "no_start_states" for ev in events)
    if not embeddings:
        if no_starts:
            return RunVerdict(
                (
                    f"  not embedded: the world declares {n_starts if n_starts is not None else 'no'} start states, "
                    "and a map is made of the traces from start states; it is learned, never embedded. "
                    "Give the world start states (a World's n_starts and reset(start=i); for Gymnasium worlds "
                    "an environment whose state can be set, see the docs' worlds page).",
                ),
                False,
            )
        ran = f" in {seconds:.0f} s" if seconds is not None else ""
        return RunVerdict(
            (
                f"  no embedding yet{ran}: the program embeds after its first policy iterations or its first "
                "periodic sweep; run longer (--seconds, or leave the default and the demo waits for the first).",
            ),
            False,
        )
    last = embeddings[-1]
    n, d = last.coordinates.shape[0], (last.coordinates.shape[1] if last.coordinates.ndim == 2 else 1)
    trig = f"{last.trigger} {last.iteration}" if last.iteration else last.trigger
    head = f"  final embedding v{last.version} ({trig}): {n} points in {d}-D"
    scored = _scored(embeddings)
    if not has_truth or not scored:
        return RunVerdict(
            (
                f"{head}, not scored",
                "  not scored: the world gives no ground truth (`truth()`), so no Procrustes error can say how good "
                "the map is; look at it instead (--plot DIR, or `sme view`).",
            ),
            True,
        )
    (v1, first), (vf, final) = scored[0], scored[-1]
    vb, best = min(scored, key=lambda x: x[1])
    tail = [err for _, err in scored[-LAST:]]
    near_best = all(near(err, best) for err in tail)
    lines = [
        f"{head}, Procrustes error against truth {final:.4f}",
        f"  {len(scored)} versions scored (0 perfect, about 1 random): first {first:.4f} (v{v1}), "
        f"best {best:.4f} (v{vb}), final {final:.4f} (v{vf})",
    ]
    k = len(tail)
    span = f"{min(tail):.4f}-{max(tail):.4f}"
    kept = program_holds(embeddings, events) and near(final, best)
    if (k > 1 and near_best) or kept:
        agree = (
            f"the last {k} versions ({span}) agree"
            if k > 1 and near_best
            else "the program holds this version (it publishes another only for a better policy or after a change)"
        )
        if final > POOR:
            lines.append(f"  {agree}, but at this error there is no map to hold yet")
        elif k > 1 and near_best:
            lines.append(f"  the last {k} versions ({span}) are near the best (within {NEAR_FACTOR:g}x): the map held")
        else:
            lines.append(f"  {agree}: the map held")
    elif k == 1:
        lines.append("  one version only: too early to say whether the map holds; run longer to see it settle")
    elif near(final, best):
        lines.append(
            "  the error was still falling at the end (the final version is at or near the best): "
            "a longer run may lower it"
        )
    else:
        lines.append(f"  the final version is {final / max(best, 1e-12):.1f}x the best (v{vb}): the map did not hold")
    goal = last.metrics.get("goal_reached_fraction")
    if goal is not None:
        lines.append(
            f"  the greedy policy reached the goal from {goal:.0%} of the {n} start states of the final version"
        )
    if final > POOR:
        why = "this is not a map of the world"
        if goal is not None and goal == 0:
            why += (
                ": the greedy policy reached the goal from none of the start states, so its traces say "
                "nothing about where they start (the program learns toward the world's reward; a task that "
                "pays -1 every step needs more learning than this run had)"
            )
        lines.append(f"  {why}; run longer, or see the docs' worlds page for what this world needs")
    elif best < first and near(final, best):
        lines.append(f"  the error fell from {first:.4f} (v{v1}) to {final:.4f} as the agent learned")
    return RunVerdict(tuple(lines), True, first, best, final, near_best)


def program_holds(embeddings: Sequence[Embedding], events: Sequence[AgentEvent] = ()) -> bool:
    """Whether the program says it holds its last version: the embedding is of a *watched* policy
    (``watched`` metric 1: a new version comes only with a better policy), or a ``settled`` event
    came at or after it (a stochastic world's policy that newer ones did not beat)."""
    embeddings = [e for e in embeddings if e.trigger != "policy_map"]
    if not embeddings:
        return False
    last = embeddings[-1]
    return last.metrics.get("watched") == 1.0 or any(ev.reason == "settled" and ev.step >= last.step for ev in events)


def settled(embeddings: Sequence[Embedding], events: Sequence[AgentEvent] = ()) -> bool:
    """Whether a run has shown what it can: a world without truth once embedded; a scored one when
    its map held at an error of at most `POOR`: the last `LAST` versions near the best, or the
    program holding a last version near the best (`program_holds`)."""
    embeddings = [e for e in embeddings if e.trigger != "policy_map"]
    if not embeddings:
        return False
    scored = _scored(embeddings)
    if not scored:
        return True
    tail = [err for _, err in scored[-LAST:]]
    best = min(err for _, err in scored)
    if tail[-1] > POOR:
        return False
    if len(tail) == LAST and all(near(err, best) for err in tail):
        return True
    return program_holds(embeddings, events) and near(tail[-1], best)


def still_to_go(embeddings: Sequence[Embedding], steps_per_second: float) -> str:
    """What a run stopped at its bound before its map held would need, from its own pace: the steps
    (and seconds at `steps_per_second`) until the error falls below `POOR`, extrapolating the fall
    from the first scored version to the best one (log error linear in steps); or why no estimate."""
    pts = [
        (int(e.step), float(e.procrustes_error))
        for e in embeddings
        if e.trigger != "policy_map" and e.procrustes_error is not None and math.isfinite(e.procrustes_error)
    ]
    pts = [(s, err) for s, err in pts if err > 0]
    if len(pts) < 2:
        return "fewer than two scored versions, so no pace to go by"
    (s0, e0), (sb, eb) = pts[0], min(pts, key=lambda p: p[1])
    if eb <= POOR:
        return "the error was below the bar once: a longer run should let the map settle"
    if sb <= s0 or eb >= e0:
        return f"the error has not fallen since the first version ({e0:.4f}), so no estimate from this run"
    rate = math.log(eb / e0) / (sb - s0)  # per step, negative
    more = max(0.0, math.log(POOR / eb) / rate - (pts[-1][0] - sb))
    secs = f", about {more / steps_per_second:,.0f} s more at this run's pace" if steps_per_second > 0 else ""
    return (
        f"at the pace from v1 to the best ({e0:.4f} -> {eb:.4f} in {sb - s0:,} steps), about {more:,.0f} more "
        f"steps to an error below {POOR:g}{secs}"
    )
