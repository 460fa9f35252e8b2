"""Leases: the world's keeper (grant, refuse, release, fence), the owner's client, and a world node
on a real bus that applies only its lease holder's actions."""

from __future__ import annotations

import threading

import pytest

from sensorimotor.agent.lease import LeaseClient, lost_by, read_reply
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig, BusError
from sensorimotor.protocol.messages import (
    Action,
    Lease,
    LeaseRequest,
    Observation,
    WorldEvent,
    WorldEventKind,
)
from sensorimotor.worlds.gridworld import GridWorld
from sensorimotor.worlds.lease import LeaseKeeper
from sensorimotor.worlds.node import WorldNode
from tests.conftest import wait_for


def act(owner: str, epoch: int, step: int = 0) -> Action:
    return Action("g1", step, (0.0,), owner=owner, epoch=epoch)


# the world's keeper ---------------------------------------------------------------------------------
def test_a_lease_goes_to_the_first_asker_and_a_live_holder_keeps_it():
    k = LeaseKeeper("g1", "s", ttl=1.5)
    first = k.request(LeaseRequest("g1", "b", request_id="r1"), now=0.0)
    assert (first.granted, first.holder, first.epoch, first.reason) == (True, "b", 1, "granted")
    other = k.request(LeaseRequest("g1", "a", request_id="r2"), now=1.0)  # lower id, but b answers
    assert (other.granted, other.holder, other.epoch, other.reason) == (False, "b", 1, "held")
    assert k.admit(act("b", 1), now=1.2) and not k.admit(act("a", 0), now=1.3)
    # b answered at 1.2: at 2.6 it is 1.4 s silent, still its lease; at 2.8 (1.6 s) it may go
    assert not k.request(LeaseRequest("g1", "a"), now=2.6).granted
    won = k.request(LeaseRequest("g1", "a"), now=2.8)
    assert (won.granted, won.holder, won.epoch) == (True, "a", 2)
    assert not k.admit(act("b", 1), now=2.9)  # fenced: the old lease
    assert k.counts.summary()["max_owners_per_lease"] == 1
    assert k.counts.owners == {1: {"b"}} and (k.counts.granted, k.counts.refused, k.counts.fenced) == (2, 2, 2)


def test_a_copy_of_the_granting_request_gets_the_same_lease_and_a_restarted_owner_a_new_epoch():
    k = LeaseKeeper("g1", "s")
    req = LeaseRequest("g1", "a", request_id="same")
    assert k.request(req, 0.0).epoch == 1
    again = k.request(req, 0.0)  # the same request through a second router
    assert (again.granted, again.epoch) == (True, 1)
    renewed = k.request(LeaseRequest("g1", "a", epoch=1, request_id="x"), 0.1)
    assert (renewed.granted, renewed.epoch, renewed.reason) == (True, 1, "renewed")
    restarted = k.request(LeaseRequest("g1", "a", epoch=0, request_id="y"), 0.2)  # a new process, same id
    assert (restarted.granted, restarted.epoch) == (True, 2)
    assert not k.admit(act("a", 1), 0.3) and k.admit(act("a", 2), 0.3)


def test_release_frees_the_lease_and_the_epoch_never_goes_back():
    k = LeaseKeeper("g1", "s")
    k.request(LeaseRequest("g1", "a"), 0.0)
    assert k.request(LeaseRequest("g1", "b", epoch=1, release=True), 0.1).reason == "not_holder"
    assert k.request(LeaseRequest("g1", "a", epoch=7, release=True), 0.1).reason == "not_holder"
    freed = k.request(LeaseRequest("g1", "a", epoch=1, release=True), 0.1)
    assert (freed.granted, freed.holder, freed.epoch, freed.reason) == (False, "", 1, "released")
    assert k.request(LeaseRequest("g1", "b"), 0.2).epoch == 2  # at once, no ttl to wait
    assert k.request(LeaseRequest("g9", "b"), 0.2).reason == "not_holder"


def test_unleased_actions_apply_only_while_nobody_holds_the_lease():
    k = LeaseKeeper("g1", "s")
    assert k.admit(Action("g1", 0, (0.0,)), 0.0) and k.admit(act("old", 0), 0.0)  # agents before leases
    k.request(LeaseRequest("g1", "a"), 0.1)
    assert not k.admit(Action("g1", 1, (0.0,)), 0.2)
    assert k.counts.unleased == 2 and k.counts.fenced == 1


def test_a_vanished_holder_token_frees_the_lease_only_once_the_holder_is_silent():
    k = LeaseKeeper("g1", "s", ttl=10.0, gone_grace=0.25)
    k.request(LeaseRequest("g1", "a"), 0.0)
    k.admit(act("a", 1), 1.0)
    k.owner_alive("a", False)  # e.g. a partition dropped it on one path while a still answers on another
    assert not k.request(LeaseRequest("g1", "b"), 1.1).granted
    assert k.request(LeaseRequest("g1", "b"), 1.3).granted  # a silent 0.3 s and its token gone: dead
    k.owner_alive("a", True)
    k.owner_alive("b", False)
    k.owner_alive("b", True)  # back: its lease is kept for the full ttl again
    assert not k.request(LeaseRequest("g1", "a"), 2.0).granted


def test_lease_lost_events_name_both_sides_and_are_rate_limited():
    k = LeaseKeeper("g1", "s", lost_every=0.5)
    k.request(LeaseRequest("g1", "b"), 0.0)
    ev = k.lost_event(act("a", 3, step=17), 1.0)
    assert ev is not None and ev.kind == WorldEventKind.LEASE_LOST
    assert (ev.owner, ev.epoch, ev.holder, ev.holder_epoch, ev.step) == ("a", 3, "b", 1, 17)
    assert k.lost_event(act("a", 3), 1.2) is None and k.lost_event(act("a", 3), 1.6) is not None
    assert k.lost_event(act("c", 3), 1.2) is not None  # another owner: its own budget
    assert k.lost_event(Action("g1", 0, (0.0,)), 1.2) is None  # nobody to tell
    assert k.counts.lost_sent == 3


def test_keeper_refuses_a_bad_ttl():
    with pytest.raises(ValueError, match="ttl"):
        LeaseKeeper("g1", "s", ttl=0)


# the owner's client -----------------------------------------------------------------------------
def lease_bytes(**kw) -> bytes:
    base = dict(world_id="g1", session="s", holder="a", epoch=4, granted=True, reason="granted", ttl=1.5)
    return codec.encode(Lease(**{**base, **kw}))


def test_read_reply_tells_granted_held_no_lease_and_bad_replies():
    assert read_reply("g1", "a", [lease_bytes()]).granted
    held = read_reply("g1", "a", [lease_bytes(holder="b", granted=False, reason="held")])
    assert (held.granted, held.holder, held.epoch, held.reason) == (False, "b", 4, "held")
    none = read_reply("g1", "a", [])
    assert none.unfenced and not none.granted
    assert read_reply("g1", "a", [b"\x00garbage"]).reason == "bad_reply"
    assert read_reply("g1", "a", [lease_bytes(world_id="g2")]).reason == "bad_reply"
    assert not read_reply("g1", "a", [lease_bytes(holder="b")]).granted  # "granted" to someone else


def test_client_uses_one_request_id_for_its_tries_and_releases_only_a_held_epoch():
    sent: list[LeaseRequest] = []

    def get(key, payload, timeout):
        assert key == keys.world_lease("g1")
        sent.append(codec.decode(LeaseRequest, payload))
        return []  # a world without leases: nobody answers

    c = LeaseClient(get, "a")
    assert c.acquire("g1", tries=3).unfenced
    assert len(sent) == 3 and len({r.request_id for r in sent}) == 1 and sent[0].request_id
    assert not c.release("g1", 0) and len(sent) == 3
    c.release("g1", 5)
    assert sent[-1].release and sent[-1].epoch == 5

    def failing(key, payload, timeout):
        raise RuntimeError("bus closed")

    assert LeaseClient(failing, "a").acquire("g1").reason == "bad_reply"


def test_lost_by_is_for_this_owner_and_this_epoch_only():
    ev = WorldEvent("g1", WorldEventKind.LEASE_LOST, owner="a", epoch=3, holder="b", holder_epoch=4)
    assert lost_by(ev, "a", 3)
    assert not lost_by(ev, "a", 4) and not lost_by(ev, "b", 3)
    mine = WorldEvent("g1", WorldEventKind.LEASE_LOST, owner="a", epoch=3, holder="a", holder_epoch=3)
    assert not lost_by(mine, "a", 3)
    assert not lost_by(WorldEvent("g1", WorldEventKind.ACTION_REFUSED, owner="a", epoch=3), "a", 3)


# a world node on a real bus ---------------------------------------------------------------------
@pytest.mark.integration
def test_world_node_applies_only_the_lease_holders_actions(endpoint):
    router = Bus(BusConfig(mode="router", connect=(), listen=(endpoint,)))
    world_bus = Bus(BusConfig(mode="client", connect=(endpoint,)))
    node = WorldNode(GridWorld("g1"), world_bus, lease_ttl=30.0)
    t = threading.Thread(target=node.run, daemon=True)
    obs: list[Observation] = []
    events: list[WorldEvent] = []
    try:
        router.subscribe(keys.world_obs("g1"), lambda m: obs.append(codec.decode(Observation, m.payload)))
        router.subscribe(keys.world_event("g1"), lambda m: events.append(codec.decode(WorldEvent, m.payload)))
        t.start()
        assert wait_for(lambda: obs, 10)
        pub = router.publisher(keys.world_act("g1"), codec.schema_name(Action))

        def ask(owner: str, **kw) -> Lease:
            r = router.get(keys.world_lease("g1"), payload=codec.encode(LeaseRequest("g1", owner, **kw)))
            return codec.decode(Lease, r[0].payload)

        a = ask("a")
        assert a.granted and a.epoch == 1 and a.session == node.session and a.ttl == 30.0
        assert not ask("b").granted  # a holds it (30 s ttl)
        step = obs[-1].step
        pub.put(codec.encode(Action("g1", step, (0.0,), owner="b", epoch=1)))  # b pretends
        assert wait_for(lambda: events, 5)
        assert events[0].kind == "lease_lost" and (events[0].owner, events[0].holder) == ("b", "a")
        assert obs[-1].step == step  # not applied
        pub.put(codec.encode(Action("g1", step, (0.0,), owner="a", epoch=1)))
        assert wait_for(lambda: obs[-1].step == step + 1, 5)
        assert ask("a", epoch=1, release=True).reason == "released"
        assert ask("b").epoch == 2
        with pytest.raises(BusError, match="lease|version|protobuf"):  # an error reply, counted
            router.get(keys.world_lease("g1"), payload=b"\x08\x09garbage")
    finally:
        node.stop()
        t.join(5)
        world_bus.close()
        router.close()
    s = node.stats.summary()
    assert (s["actions_fenced"], s["lease_owners"], s["leases_granted"], s["leases_refused"]) == (1, {"1": ["a"]}, 2, 1)
    assert s["rejected"].get("malformed", 0) + s["rejected"].get("unknown_version", 0) == 1
