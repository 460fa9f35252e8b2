"""The agent daemon's settings: one typed, frozen value, checked before anything starts.

`AgentDaemon(bus, config=DaemonConfig(...))` takes it whole; the keyword arguments
`AgentDaemon(bus, agent_id, seed=..., state_dir=...)` still work and build one (an unknown keyword
is refused with the valid names).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Any

from sensorimotor.agent.checkpoint_store import MAX_SHARED_BYTES
from sensorimotor.agent.detectors import DEFAULT_DETECTOR, make_detector
from sensorimotor.agent.programs.registry import check_program_params
from sensorimotor.protocol import keys


@dataclass(frozen=True)
class DaemonConfig:
    """What an agent daemon is told at start-up (everything but its bus).

    Parameters
    ----------
    agent_id : str, default keys.DEFAULT_AGENT_ID
        The agent's id in key expressions.
    seed : int, default 0
        Seed of every program's generator.
    state_dir : str, optional
        Directory of the checkpoints (`<world>.ckpt.npz`); without it nothing is saved or loaded.
    checkpoint_every : float, default 30.0
        Seconds between checkpoints while `run` loops.
    program_params : dict, optional
        `{program: {key: value}}` hyperparameters, validated at once.
    on_output : callable, optional
        Also called with `(channel, message)` for every embedding and event published.
    threaded_links : bool, default False
        Run each link on its own thread instead of in the bus callback.
    detector : str, default DEFAULT_DETECTOR
        The drop detector of every link (see `agent.detectors.DETECTORS`).
    link_ttl : float or None, default 600.0
        Seconds after which the link of a world gone is released (None: never).
    owner_id : str, optional
        The id this daemon claims worlds and answers status under (default: `agent_id`); the
        workers of `sme agent --workers N` are owners ``AGENT.wK`` publishing as agent AGENT.
    claim_settle : float, default 0.3
        Seconds a claim is held before the daemon answers the world (a lower claimant seen in that
        time wins); longer than the bus takes to carry a liveliness token between owners.
    claim_delay : float, default 0.3
        Seconds a world must be unclaimed before this daemon claims it (times 1 + its rank among
        the least-loaded owners; 0 for a world it has a paused link for).
    share_every : float or None, default None
        Seconds between checkpoints shared on the bus while another owner is alive (default:
        `checkpoint_every`; None there too: never).
    workers : tuple of str, default ()
        The owner ids of this daemon's worker processes (`sme agent --workers N`): its status adds
        their links and counters, so `sme status --agent ID` shows the whole agent.
    all_obs : bool, default True
        Subscribe to every world's observations, truth and events (those of worlds it does not answer are
        counted); False: only to the worlds it claims (the workers, so that N workers do not each receive all).
    share_on_embedding : float or None, default 2.0
        Also share a world's checkpoint soon after each new embedding version, at most once per
        this many seconds per world (None: only periodically); see `agent.checkpoint_store`.
    share_max_bytes : int, default MAX_SHARED_BYTES
        Checkpoints larger than this are not shared on the bus (nor accepted from it).
    """

    agent_id: str = keys.DEFAULT_AGENT_ID
    seed: int = 0
    state_dir: str | None = None
    checkpoint_every: float = 30.0
    program_params: dict[str, dict[str, Any]] | None = None
    on_output: Callable[[str, Any], None] | None = None
    threaded_links: bool = False
    detector: str = DEFAULT_DETECTOR
    link_ttl: float | None = 600.0
    owner_id: str | None = None
    claim_settle: float = 0.3
    claim_delay: float = 0.3
    share_every: float | None = None
    workers: tuple[str, ...] = field(default=())
    all_obs: bool = True
    share_on_embedding: float | None = 2.0
    share_max_bytes: int = MAX_SHARED_BYTES

    @classmethod
    def of(cls, config: DaemonConfig | None = None, **options: Any) -> DaemonConfig:
        """`config` (default: all defaults) with the named `options` replaced; an unknown name is
        refused with the valid ones."""
        valid = [f.name for f in fields(cls)]
        unknown = sorted(set(options) - set(valid))
        if unknown:
            raise TypeError(f"AgentDaemon got unknown option(s) {unknown}; valid: {', '.join(valid)}")
        return replace(config or cls(), **options)

    def checked(self) -> DaemonConfig:
        """This config with its values checked and completed (the owner id, typed program params),
        or the error that names what is wrong: an unknown detector, a bad id, unknown program
        params, a link ttl <= 0."""
        make_detector(self.detector)  # fail early on an unknown name
        agent_id = keys.check_id(self.agent_id, "agent id")
        owner_id = keys.check_id(self.owner_id or self.agent_id, "owner id")
        program_params = check_program_params(self.program_params)  # fail early, typed values only
        if self.link_ttl is not None and self.link_ttl <= 0:
            raise ValueError(f"link_ttl must be > 0 seconds (or None: never release), not {self.link_ttl}")
        return replace(
            self,
            agent_id=agent_id,
            owner_id=owner_id,
            program_params=program_params,
            workers=tuple(self.workers),
            share_every=self.checkpoint_every if self.share_every is None else self.share_every,
        )
