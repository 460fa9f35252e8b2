"""The agent daemon: discovers worlds by liveliness, attaches one link per world, runs each
world's developmental program, answers a status queryable, checkpoints, stops cleanly.

A world that vanishes pauses its link; when it returns (same id) the link resumes with everything
the program learned. With `state_dir`, each link's program is checkpointed atomically and picked up
again by a daemon started later. A world gone longer than `link_ttl` seconds has its link
checkpointed (with `state_dir`) and released from memory, so worlds that come and go do not pile up
links; if it returns, it is attached again through the normal path (restored from its checkpoint,
or fresh without a state dir).

One owner per world (see `agent.ownership` and protocol/README.md, "Owners"): the daemon answers a
world only while it holds the world's claim token and no lower owner id claims it too; several
daemons (or the workers of one, `owner_id`) share the worlds of a bus by count. Each owner shares
its worlds' checkpoints on the bus (`sme/v1/agent/{owner}/checkpoint/{world}`); every daemon keeps
the newest copy of the others', so the survivor of a dead owner resumes its worlds from there.

This module is the main loop (start, run, stop, close) over the daemon's parts, one job per module:
`daemon_config` (the typed settings), `daemon_state` (what the parts share), `daemon_publish`,
`daemon_restore` and `daemon_share` (checkpoints), `daemon_inbox` (bus callbacks), `daemon_status`
(status and worker polling), `daemon_leases`, `daemon_attach` and `daemon_own` (ownership).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any

from sensorimotor.agent.daemon_config import DaemonConfig
from sensorimotor.agent.daemon_own import Owning
from sensorimotor.agent.programs.registry import PROGRAMS
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus
from sensorimotor.protocol.messages import Action, AgentStatus, Embedding

log = logging.getLogger("sme.agent")


def _import_programs() -> None:
    """Import every program's module now, beside the first worlds, not inside a later attach: the
    first world of a kind would otherwise hold the process (its GIL) for the import, ~1.5 s for the
    generic program's scipy.stats and filterpy, while its lockstep worlds wait for their answers."""
    for kind in PROGRAMS.values():
        try:
            kind.program_class()
        except Exception as e:  # noqa: BLE001 - a broken optional dependency: the attach reports it
            log.debug("program module %s not imported: %s", kind.module, e)


class DuplicateAgent(Exception):
    """Another agent (or worker) with this owner id is alive on the bus (the message says which)."""


class AgentDaemon(Owning):
    """The agent daemon: discovers worlds on the bus, attaches a `WorldLink` to each, checkpoints.

    Parameters
    ----------
    bus : Bus
        The message bus (Zenoh session or an in-process stand-in).
    agent_id : str, optional
        The agent's id in key expressions (default: the config's, `keys.DEFAULT_AGENT_ID`).
    config : DaemonConfig, optional
        Every other setting, typed (see `DaemonConfig` for each and its default).
    **options
        Settings by name, replacing the config's (`AgentDaemon(bus, "a0", state_dir="state")`);
        an unknown name is refused with the valid ones.

    Examples
    --------
    ::

        with AgentDaemon(bus, config=DaemonConfig(state_dir="state")) as daemon:  # start() ... close()
            daemon.run(seconds=60)
    """

    def __init__(
        self, bus: Bus, agent_id: str | None = None, *, config: DaemonConfig | None = None, **options: Any
    ) -> None:
        if agent_id is not None:
            options["agent_id"] = agent_id
        super().__init__(bus, DaemonConfig.of(config, **options).checked())

    UNIQUE_ID_TIMEOUT = 1.0  # seconds the liveliness query for another agent with this id waits

    def check_unique(self) -> None:
        """Raise DuplicateAgent when an agent with this owner id is alive on the bus already (its
        liveliness token is there): two processes with one id would both answer its status and
        fight over its worlds' claims under one name."""
        if self._unique_checked:
            return
        self._unique_checked = True
        key = keys.alive_agent(self.owner_id)
        try:
            alive = self.bus.alive(key, timeout=self.UNIQUE_ID_TIMEOUT)
        except Exception as e:  # noqa: BLE001 - no answer is no proof of a duplicate: start
            log.debug("liveliness query %s failed: %s", key, e)
            return
        if alive:
            raise DuplicateAgent(
                f"an agent with id {self.owner_id!r} is already running on this bus (its liveliness token {key} "
                "is alive); give this one another --id, or stop that one first (the token of an agent that "
                "died without closing its connection stays until the zenoh lease expires, 10 s by default)"
            )

    def start(self) -> None:
        """Refuse an id already alive on the bus (DuplicateAgent), then declare the status
        queryable and liveliness token, subscribe, and watch for worlds."""
        self.check_unique()
        self.bus.queryable(keys.agent_status(self.owner_id), self._status, codec.schema_name(AgentStatus))
        if self.all_obs:
            self.bus.subscribe(keys.ALL_OBS, self._on_obs)
            self.bus.subscribe(f"{keys.PREFIX}/world/*/truth", self._on_truth)
            self.bus.subscribe(keys.ALL_WORLD_EVENTS, self._on_world_event)
        self.bus.subscribe(keys.ALL_CHECKPOINTS, self._on_checkpoint)
        self.bus.subscribe(keys.ALL_EMBEDDINGS, self._on_embedding)
        self.bus.queryable(f"{keys.PREFIX}/agent/{self.owner_id}/checkpoint/*", self._answer_checkpoint)
        self.bus.token(keys.alive_agent(self.owner_id))
        self.bus.token(keys.alive_owner(self.owner_id))
        self.bus.watch_alive(keys.ALL_ALIVE_OWNERS, self._on_owner, history=True)
        self.bus.watch_alive(keys.ALL_CLAIMS, self._on_claim, history=True)
        self.bus.watch_alive(keys.ALL_ALIVE_WORLDS, self._on_alive, history=True)
        if self.workers:
            threading.Thread(target=self._poll_workers, name="poll-workers", daemon=True).start()
        threading.Thread(target=_import_programs, name="import-programs", daemon=True).start()
        threading.Thread(target=self._audit_liveliness, name="liveliness-audit", daemon=True).start()

    TICK = 0.1  # seconds between two ownership ticks when no world appeared or vanished
    MIN_TICK = 0.02  # when some did or the last tick claimed one: at most one per MIN_TICK (a tick is O(worlds))

    def run(self, seconds: float | None = None) -> None:
        """Process attach/detach until stop() or `seconds` elapse."""
        t0 = time.monotonic()
        last_ckpt = last_sweep = last_share = t0
        last_tick = float("-inf")
        busy = False  # the last tick claimed a world (more may wait: the next tick comes at MIN_TICK)
        sweep_every = min(1.0, self.link_ttl / 2) if self.link_ttl is not None else None
        while not self._stop.is_set():
            if seconds is not None and time.monotonic() - t0 >= seconds:
                break
            try:
                changes = [self._changes.get(timeout=self.MIN_TICK if busy else self.TICK)]
            except queue.Empty:
                changes = []
            while True:  # every change queued so far, then one tick for all of them
                try:
                    changes.append(self._changes.get_nowait())
                except queue.Empty:
                    break
            for wid, alive in changes:
                if not alive:
                    self._detach(wid)
            if time.monotonic() - last_tick < (self.MIN_TICK if changes or busy else self.TICK):
                continue  # a burst of worlds appearing or vanishing is one tick, not one each
            last_tick = time.monotonic()
            try:
                self._handle_lost()
                claims = self.counters["claimed"]
                self.own()
                busy = self.counters["claimed"] > claims  # one claim per tick: the next one soon
                self.share_new_versions()
            except Exception:  # noqa: BLE001 - one bad tick must not stop the daemon
                if self.bus.closed:
                    break
                log.exception("ownership tick failed")
            if self.share_every is not None and time.monotonic() - last_share >= self.share_every:
                self.share()
                last_share = time.monotonic()
            if sweep_every is not None and time.monotonic() - last_sweep >= sweep_every:
                self.release_expired()
                last_sweep = time.monotonic()
            if self.state_dir and time.monotonic() - last_ckpt >= self.checkpoint_every:
                self.checkpoint()
                last_ckpt = time.monotonic()

    def stop(self) -> None:
        """Make `run` return."""
        self._stop.set()

    def close(self) -> None:
        """Stop, stop every link, withdraw every claim and write a final checkpoint."""
        self._stop.set()
        try:
            self.share()  # the others resume from here
        except Exception as e:  # noqa: BLE001 - a closing bus: stopping goes on
            log.warning("final share failed: %s", e)
        for wid in list(self._claims):
            self._release(wid, "agent stopping")
        for link in list(self.links.values()):
            link.stop()
        try:
            self.checkpoint()
        except OSError as e:
            log.warning("final checkpoint failed: %s", e)

    def __enter__(self) -> AgentDaemon:
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


__all__ = ["AgentDaemon", "DaemonConfig", "DuplicateAgent", "Action", "Embedding"]
