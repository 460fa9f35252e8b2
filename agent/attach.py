"""Attaching a world: the one path by which a world spec becomes a running link.

The daemon (live, over the bus), offline replay (from a recording) and the in-process runner
(tests, reproduce, benchmarks) all attach through `attach`, so they agree on when a returning
world resumes its old link (`same_body`), which program and detector a new link gets, and what the
`attached` event says (`AttachConfig`, a typed field that offline replay reads back).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from sensorimotor.agent.detectors import DEFAULT_DETECTOR, DropDetector, make_detector
from sensorimotor.agent.link import Publish, WorldLink
from sensorimotor.agent.programs.base import Program
from sensorimotor.agent.programs.registry import PROGRAMS, make_program, resolve_program
from sensorimotor.protocol import keys
from sensorimotor.protocol.messages import AttachConfig, EventKind, Truth, WorldSpec
from sensorimotor.protocol.params import format_value


def same_body(a: WorldSpec, b: WorldSpec) -> bool:
    """Whether what was learned on a world with spec `a` still applies to one with spec `b`: the
    same kind, program, sensors and action space (ids, sessions and parameters may differ)."""
    return (a.kind, a.program, a.sensors, a.action_space) == (b.kind, b.program, b.sensors, b.action_space)


@dataclass(frozen=True)
class AgentConfig:
    """What decides an agent's behaviour besides its observations.

    Parameters
    ----------
    agent_id : str
        Used in key expressions and in every message the agent publishes.
    seed : int
        Seed of every program's random generator.
    detector : str
        The reward-drop detector run on each link (see `agent.detectors.DETECTORS`).
    program_params : mapping
        Per program name, its parameters (as given on the command line or already typed).
    """

    agent_id: str = keys.DEFAULT_AGENT_ID
    seed: int = 0
    detector: str = DEFAULT_DETECTOR
    program_params: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def for_spec(self, spec: WorldSpec) -> AttachConfig:
        """The configuration a link to `spec` runs with, as carried by the `attached` event."""
        name = program_name(spec)
        params = self.program_params.get(name, {})
        return AttachConfig(self.seed, self.detector, name, {k: format_value(v) for k, v in params.items()})

    @classmethod
    def from_attach(cls, agent_id: str, cfg: AttachConfig) -> AgentConfig:
        """The configuration recorded in an `attached` event (offline replay)."""
        return cls(agent_id, cfg.seed, cfg.detector or DEFAULT_DETECTOR, {cfg.program: dict(cfg.program_params)})


def program_name(spec: WorldSpec) -> str:
    """The program that runs a world (the generic one when the agent lacks the one it asks for)."""
    return resolve_program(spec)


@dataclass(frozen=True)
class Restored:
    """A link's learned state read back from a checkpoint."""

    program: Program
    version: int
    detector: DropDetector | None
    steps: int = 0  # steps learned before the checkpoint was taken (the checkpoint's `steps`)


@dataclass(frozen=True)
class Attached:
    """The result of `attach`: the link and how it came to be (new, restored or resumed)."""

    link: WorldLink
    how: str


def attach(
    spec: WorldSpec,
    config: AgentConfig,
    publish: Publish,
    *,
    truth: Truth | None = None,
    previous: WorldLink | None = None,
    restored: Restored | None = None,
    program: Program | None = None,
    detector: DropDetector | None = None,
    last_published: int = 0,
) -> Attached:
    """Make (or resume) the link for a world that (re)appeared with `spec`.

    A previous link to the same body resumes with everything it learned; otherwise the link starts
    from `restored` (a checkpoint for the same body), or from `program` and `detector` when the
    caller built them, or else from the program and detector `config` names. The link publishes an
    `attached` (or `resumed`) event.

    Parameters
    ----------
    spec : WorldSpec
        The world as it announced itself.
    config : AgentConfig
        Agent id, seed, detector and program parameters.
    publish : callable
        `publish(channel, message)` for the link.
    truth : Truth, optional
        Ground truth for scoring (never seen by the program).
    previous : WorldLink, optional
        The link this world had before, if any.
    restored : Restored, optional
        State read back from a checkpoint.
    program, detector : optional
        A program (and detector) the caller built, used when there is nothing to resume or restore.
    last_published : int, default 0
        The highest embedding version of this world seen on the bus (any agent). A new or restored
        link whose state is older goes on numbering after it (a version is never published twice
        with different maps), and its `attached` event says how far behind the state is
        (`values`: ``checkpoint_version``, ``last_published_version``).

    Returns
    -------
    Attached
        The link and how it came to be: "new", "restored" or "resumed".

    Raises
    ------
    ValueError
        (or ProtocolError) When no program fits the spec.
    """
    if previous is not None and same_body(previous.spec, spec):
        previous.truth = truth or previous.truth
        previous.resume(spec)
        previous.event(
            EventKind.RESUMED,
            f"{spec.kind}: resumed with {previous.counters.steps} steps learned",
            reason="world_returned",
        )
        return Attached(previous, "resumed")
    cfg = config.for_spec(spec)
    how = "new"
    version = 0
    if restored is not None and same_body(restored.program.spec, spec):
        program, detector, version, how = restored.program, restored.detector, restored.version, "restored"
        program.world_restarted()
        if detector is None:
            detector = make_detector(config.detector, **program.detector_params)
    elif program is None:
        program = make_program(spec, config.seed, **config.program_params.get(cfg.program, {}))
        detector = make_detector(config.detector, **program.detector_params)
    link = WorldLink(config.agent_id, spec, program, publish, detector)
    link.truth = truth
    link.version = max(version, last_published)
    if how == "restored" and restored is not None:
        link.steps_before = restored.steps
    asked = spec.program or spec.kind
    if program.name != asked and asked not in PROGRAMS:
        link.event(
            EventKind.PROGRAM_FALLBACK,
            f"this agent has no program {asked!r}; the {program.name} program learns the world instead",
            reason=asked,
        )
    detail = (
        f"{spec.kind} with program {program.name} ({how}"
        + (f" at embedding v{version}, {link.steps_before:,} steps learned)" if how == "restored" else ")")
        + (f": {program.describe()}" if program.describe() else "")
    )
    values: dict[str, float] = {}
    if last_published > version:
        values = {"checkpoint_version": float(version), "last_published_version": float(last_published)}
        if how == "restored":
            detail += (
                f"; the state is older than the last published embedding v{last_published} "
                f"({last_published - version} version(s) behind); versions go on from v{last_published}"
            )
        else:
            detail += f"; no state behind the published embedding v{last_published}: versions go on from there"
    link.event(EventKind.ATTACHED, detail, values=values, reason=how, config=cfg)
    return Attached(link, how)
