"""The daemon's status (`sme status`): its links and counters, with its worker processes' polled
every 0.5 s and added, so the agent's status shows the whole agent."""

from __future__ import annotations

import logging
import time

from sensorimotor.agent.daemon_inbox import Inbox
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import BusError
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import AgentStatus

log = logging.getLogger("sme.agent")


class Reporting(Inbox):
    """Status and worker polling (see the module docstring)."""

    def _status(self, key: str, payload: bytes | None) -> bytes:
        """The status queryable's answer."""
        return codec.encode(self.status())

    def status(self) -> AgentStatus:
        """The agent's status: uptime, every link's status and the daemon's counters."""
        links = tuple(link.status() for link in list(self.links.values()))
        counters = dict(self.counters)
        counters["dropped"] += sum(ln.dropped for ln in links)
        counters["links"] = len(links)
        counters["owned"] = len(self._claims)
        if self.workers:
            mine = {ln.world_id for ln in links if ln.state == "attached"}
            extra = []
            for st in list(self._worker_status.values()):
                extra += [ln for ln in st.links if ln.world_id not in mine and ln.state == "attached"]
                for k, v in st.counters.items():
                    counters[k] = counters.get(k, 0) + v
            seen = {ln.world_id for ln in extra} | mine
            links = tuple(ln for ln in links if ln.state == "attached" or ln.world_id not in seen) + tuple(extra)
            counters["links"] = len(links)
            counters["workers"] = len(self._worker_status) + 1  # the processes that answer, this one included
        return AgentStatus(self.owner_id, time.time() - self._started, links, counters, time.time())

    def _poll_workers(self) -> None:
        """Keep the workers' latest statuses (for `status`), every 0.5 s until stopped."""
        while not self._stop.wait(0.5):
            for w in self.workers:
                try:
                    replies = self.bus.get(keys.agent_status(w), timeout=1.0)
                    if replies:
                        self._worker_status[w] = codec.decode(AgentStatus, replies[0].payload)
                    else:
                        self._worker_status.pop(w, None)
                except (BusError, ProtocolError):
                    self._worker_status.pop(w, None)
                except Exception:  # noqa: BLE001 - a closed session at shutdown
                    return
