"""Issue 41, item 3: a release never loses learned state silently. A world that another owner only
claimed (and never got the lease of) is checkpointed when its link is released: the newest state is
decided by lease epochs, not by who claimed last; a world whose lease another owner held since is
not, and the log says which owner and epoch."""

from __future__ import annotations

import logging
import threading
import time

import pytest

from sensorimotor.agent.checkpoint import read_checkpoint
from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.protocol import keys
from sensorimotor.protocol.bus import Bus, BusConfig
from tests.conftest import wait_for


def _run(daemon: AgentDaemon) -> threading.Thread:
    t = threading.Thread(target=daemon.run, daemon=True)
    t.start()
    return t


@pytest.mark.integration
def test_a_world_claimed_elsewhere_but_never_leased_there_is_checkpointed_on_release(
    procs, endpoint, tmp_path, caplog
) -> None:
    caplog.set_level(logging.INFO, logger="sme.agent")
    with Bus(BusConfig.for_role("agent", endpoint)) as bus:
        d = AgentDaemon(bus, "a0", state_dir=str(tmp_path), link_ttl=1.0, checkpoint_every=3600.0)
        d.start()
        runner = _run(d)
        try:
            world = procs.start("world", "gridworld", "--id", "g1", "--connect", endpoint, "-q")
            assert wait_for(lambda: "g1" in d.links and d.links["g1"].learned_steps > 300, 60), d.counters
            epoch = d.links["g1"].epoch
            assert epoch > 0  # the world grants leases
            with Bus(BusConfig.for_role("tool", endpoint)) as other:
                other.token(keys.alive_claim("g1", "0x"))  # a lower owner claims it, and never asks for the lease
                assert wait_for(lambda: d.links["g1"].state != "attached", 20)
                steps = d.links["g1"].learned_steps
                assert procs.stop(world) == 0  # the world goes (its lease only ever went to a0)
                assert wait_for(lambda: "g1" not in d.links, 20), "the link was not released"
        finally:
            d.stop()
            runner.join(10)
            d.close()
    ck = read_checkpoint(str(tmp_path / "g1.ckpt.npz"))  # on main: no file, "not checkpointed here"
    assert ck.owner == "a0" and ck.epoch == epoch and ck.steps == steps
    assert "not checkpointed here" not in caplog.text
    assert f"lease epoch {epoch} was the last seen" in caplog.text


def test_a_world_whose_lease_another_owner_held_since_is_not_checkpointed_here(tmp_path, caplog) -> None:
    from sensorimotor.agent.attach import attach
    from sensorimotor.worlds.bench import BenchWorld

    class _Bus:
        closed = False

        def publisher(self, key: str, schema: str | None = None) -> object:  # noqa: ARG002
            return type("P", (), {"put": lambda self, data: None, "_pub": None})()

        def undeclare(self, entity: object) -> None:
            pass

    d = AgentDaemon(_Bus(), state_dir=str(tmp_path), link_ttl=5.0)  # type: ignore[arg-type]
    spec = BenchWorld("b1", params=None, obs_bytes=16).spec()
    d.links["b1"] = attach(spec, d.config, d.publish).link
    d._held["b1"] = (3, time.time() - 10)  # a0 held epoch 3 ...
    d._note_lease_elsewhere("b1", "b", 4, time.time() - 5)  # ... then b held epoch 4 (lease_lost / refused / shared)
    d._elsewhere.add("b1")
    d._detach("b1")
    with caplog.at_level("INFO", logger="sme.agent"):
        assert d.release_expired(now=time.monotonic() + 6) == ["b1"]
    assert not (tmp_path / "b1.ckpt.npz").exists()
    assert "not checkpointed here (owner b held its lease (epoch 4) after this owner did" in caplog.text
