"""One owner per world: the claim rules (pure), and two agents sharing four worlds over real zenoh,
then failing over when one is killed (-9)."""

from __future__ import annotations

import json
import signal
import time

import pytest

from sensorimotor.agent.ownership import OwnerBook, TokenAudit, View, plan
from sensorimotor.tools.common import free_port
from tests.conftest import Lines, wait_for
from tests.conftest import agent_status as status
from tests.conftest import world_link as link


def view(worlds, owners, claims) -> View:
    return View(frozenset(worlds), frozenset(owners), {w: frozenset(c) for w, c in claims.items()})


def test_broken_worlds_never_make_an_owner_hand_off_a_healthy_one():
    # owner "a" answers "good" and holds 20 fake worlds it could not attach; "b" holds none
    fakes = {f"fz-{i}" for i in range(20)}
    v = view(fakes | {"good"}, {"a", "b"}, {w: {"a"} for w in fakes | {"good"}})
    mine = fakes | {"good"}
    assert plan("a", v, mine, {}, may_shed=True).shed == "good"  # counted as load: the healthy one moved
    p = plan("a", v, mine, {}, failed=frozenset(fakes), may_shed=True)
    assert p.shed is None and p.release == {}
    # three working worlds against an idle owner: one is still handed off (the balance is kept)
    v3 = view({"g1", "g2", "g3"}, {"a", "b"}, {w: {"a"} for w in ("g1", "g2", "g3")})
    assert plan("a", v3, {"g1", "g2", "g3"}, {}, failed=frozenset(), may_shed=True).shed == "g3"


def test_lower_owner_id_wins_a_double_claim_and_a_gone_world_is_released():
    v = view({"g1", "g2"}, {"a", "b"}, {"g1": {"a", "b"}, "g3": {"b"}})
    p = plan("b", v, {"g1", "g3"}, {})
    assert set(p.release) == {"g1", "g3"}
    assert "a claims it too" in p.release["g1"] and p.release["g3"] == "world gone"
    assert plan("a", v, {"g1"}, {}).release == {}  # the winner keeps it


def test_claims_balance_by_count_and_wait_their_turn():
    v = view({"g1", "g2", "g3"}, {"a", "b"}, {"g1": {"a"}})
    # a owns one, b none: a defers, b claims the first free world once it waited its delay
    assert plan("a", v, {"g1"}, {"g2": 5.0, "g3": 5.0}).claim == ()
    assert plan("b", v, set(), {"g2": 0.1, "g3": 0.1}, claim_delay=0.3).claim == ()
    assert plan("b", v, set(), {"g2": 0.4, "g3": 0.4}, claim_delay=0.3).claim == ("g2",)
    # tied owners: the second in id order waits twice as long
    v0 = view({"g1"}, {"a", "b"}, {})
    assert plan("a", v0, set(), {"g1": 0.35}, claim_delay=0.3).claim == ("g1",)
    assert plan("b", v0, set(), {"g1": 0.35}, claim_delay=0.3).claim == ()
    assert plan("b", v0, set(), {"g1": 0.65}, claim_delay=0.3).claim == ("g1",)
    # a world this owner had a link for is claimed at once, before the others
    assert plan("b", view({"g1", "g9"}, {"a", "b"}, {}), set(), {}, known=frozenset({"g9"})).claim == ("g9",)


def test_an_overloaded_owner_hands_one_world_off():
    v = view({"g1", "g2", "g3"}, {"a", "b"}, {"g1": {"a"}, "g2": {"a"}, "g3": {"a"}})
    assert plan("a", v, {"g1", "g2", "g3"}, {}, may_shed=True).shed == "g3"
    assert plan("a", v, {"g1", "g2", "g3"}, {}, may_shed=False).shed is None
    v2 = view({"g1", "g2"}, {"a", "b"}, {"g1": {"a"}, "g2": {"b"}})
    assert plan("a", v2, {"g1"}, {}, may_shed=True).shed is None


def test_owner_book_follows_tokens():
    b = OwnerBook()
    b.world("g1", True)
    b.owner("a", True)
    b.claim("sme/v1/alive/claim/g1/a", True)
    b.claim("sme/v1/alive/claim/g1/b", True)
    assert b.view().claimants("g1") == {"a", "b"} and b.claimed_by_other("g1", "a")
    b.claim("sme/v1/alive/claim/g1/b", False)
    assert not b.claimed_by_other("g1", "a") and b.claimed_by_other("g1", "z")
    b.world("g1", False)
    assert b.view().load("a") == 0


def test_token_audit_reports_only_disagreements_that_lasted_with_no_event_about_them():
    audit = TokenAudit(patience=1.0)
    w = "sme/v1/alive/world/*"
    # g2 alive but booked gone, g9 booked but gone: at first an event could still be on its way
    assert audit.check(w, {"g1", "g9"}, {"g1", "g2"}, now=0.0) == []
    assert audit.check(w, {"g1", "g9"}, {"g1", "g2"}, now=0.5) == []
    assert audit.check(w, {"g1", "g9"}, {"g1", "g2"}, now=1.0) == [("g2", True, 0.0), ("g9", False, 0.0)]
    # an event about g2 at 1.2 restarts its clock, even though the book still disagrees
    touched = {"g2": 1.2}.get
    assert audit.check(w, {"g1", "g9"}, {"g1", "g2"}, 1.5, lambda k: touched(k, float("-inf"))) == [("g9", False, 0.0)]
    assert audit.check(w, {"g1", "g9"}, {"g1", "g2"}, 2.2, lambda k: touched(k, float("-inf"))) == [
        ("g2", True, 1.2),
        ("g9", False, 0.0),
    ]
    # a disagreement the events mended is forgotten; seen again, it waits its patience again
    assert audit.check(w, {"g1", "g2", "g9"}, {"g1", "g2"}, now=2.5) == [("g9", False, 0.0)]
    assert audit.check(w, {"g1", "g9"}, {"g1", "g2"}, now=3.0) == [("g9", False, 0.0)]
    # each key expression is its own comparison
    assert audit.check("sme/v1/alive/owner/*", {"a"}, set(), now=3.0) == []
    with pytest.raises(ValueError):
        TokenAudit(patience=-1)


def test_owner_book_mends_a_missed_event_unless_an_event_came_since():
    b = OwnerBook()
    b.world("g1", True)
    b.owner("a", True)
    b.claim("sme/v1/alive/claim/g1/a", True)
    assert b.tokens() == {
        "sme/v1/alive/world/*": {"sme/v1/alive/world/g1"},
        "sme/v1/alive/owner/*": {"sme/v1/alive/owner/a"},
        "sme/v1/alive/claim/*/*": {"sme/v1/alive/claim/g1/a"},
    }
    t = b.touched("sme/v1/alive/claim/g1/a")
    assert t > float("-inf") and b.touched("sme/v1/alive/world/g2") == float("-inf")
    # the claim's event came after the disagreement was seen: the events have spoken, nothing changes
    assert not b.mend("sme/v1/alive/claim/*/*", "sme/v1/alive/claim/g1/a", False, since=t - 1.0)
    assert b.claimants("g1") == {"a"}
    assert b.mend("sme/v1/alive/claim/*/*", "sme/v1/alive/claim/g1/a", False, since=t)
    assert b.mend("sme/v1/alive/world/*", "sme/v1/alive/world/g2", True, since=0.0)
    assert b.mend("sme/v1/alive/owner/*", "sme/v1/alive/owner/a", False, since=t)
    assert b.view() == View(frozenset({"g1", "g2"}), frozenset(), {})
    # what it remembers of events is bounded: the older half goes, the newest stay
    b.TOUCHED_MAX = 8
    for i in range(20):
        b.world(f"w{i}", True)
    assert b.touched("sme/v1/alive/world/w19") >= b.touched("sme/v1/alive/world/w15") > float("-inf")
    assert b.touched("sme/v1/alive/world/w0") == float("-inf") and len(b._touched) <= 8


@pytest.mark.integration
def test_the_daemon_mends_a_book_whose_liveliness_events_went_missing(endpoint):
    # CI saw it (1 run in ~15 here): after a router died, a world that reconnected through the
    # other one stayed booked as gone, so nobody claimed it again. Here the events are lost by hand.
    from sensorimotor.agent.daemon import AgentDaemon
    from sensorimotor.protocol import keys
    from sensorimotor.protocol.bus import Bus, BusConfig

    with Bus(BusConfig.for_role("agent", endpoint)) as bus, Bus(BusConfig.for_role("tool", endpoint)) as other:
        d = AgentDaemon(bus, agent_id="m")
        d.start()
        try:
            other.token(keys.alive_world("g9"))
            assert wait_for(lambda: "g9" in d.book.view().worlds, 10)
            d.book.world("g9", False)  # its appearance never reported
            d.book.world("ghost", True)  # a world whose disappearance never was
            assert wait_for(lambda: d.counters["liveliness_mended"] == 2, 10), d.counters  # after ~1.5 s
            assert d.book.view().worlds == {"g9"}
            changes = []
            while not d._changes.empty():
                changes.append(d._changes.get_nowait())
            assert ("g9", True) in changes and ("ghost", False) in changes, changes
            time.sleep(5 * d.AUDIT_EVERY)
            assert d.counters["liveliness_mended"] == 2  # nothing else to mend
        finally:
            d.stop()


@pytest.mark.integration
def test_two_agents_share_four_worlds_then_one_is_killed_and_the_other_resumes_its_worlds(procs, tmp_path):
    e1, e2 = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    # one process per agent (the machine is shared); the default checkpoint period (30 s): what a takeover
    # resumes from is the checkpoint shared after each new embedding version
    # b logs at info level: on a failure the test shows what b did after the kill. Every stderr is
    # drained as it comes: a full pipe would block a process on its next log line.
    a = procs.start("agent", "--id", "a", "--listen", e1, "--workers", "1", "-q")
    b = procs.start("agent", "--id", "b", "--listen", e2, "--connect", e1, "--workers", "1")
    logs = {"a": Lines(a.stderr), "b": Lines(b.stderr)}
    assert wait_for(lambda: status(e1, "a") and status(e2, "b"), 40)
    watch = procs.start("watch", "--json", "--no-events", "--timeout", "170", "--connect", e2)
    rows = Lines(watch.stdout)
    worlds = [f"g{i}" for i in range(1, 5)]
    ws = {
        w: procs.start(
            "world", "gridworld", "--id", w, "--connect", e1, "--connect", e2, "--stats-json", str(tmp_path / w), "-q"
        )
        for w in worlds
    }
    logs.update({w: Lines(p.stderr) for w, p in ws.items()})

    def embeddings():
        return [json.loads(x) for x in list(rows.lines) if x.startswith("{")]

    def good(w, agent=None):
        return [r for r in embeddings() if r["world"] == w and (agent is None or r["agent"] == agent)]

    # every world reaches a good embedding, each from one agent, two worlds per agent
    assert wait_for(lambda: all(any(r["procrustes_error"] < 0.05 for r in good(w)) for w in worlds), 240), [
        (r["agent"], r["world"], r["version"], r["procrustes_error"]) for r in embeddings()
    ]
    owners = {w: {r["agent"] for r in good(w)} for w in worlds}
    assert all(len(o) == 1 for o in owners.values()), owners
    of_a = sorted(w for w in worlds if owners[w] == {"a"})
    assert len(of_a) == 2, owners
    # `sme status` without --agent: both agents, who owns what, nothing unowned
    st = procs.start("status", "--json", "--connect", e2)
    out, _ = st.communicate(timeout=60)
    bus = json.loads(out)
    assert [d["agent"] for d in bus["agents"]] == ["a", "b"] and bus["unowned"] == [], bus
    assert bus["owners"] == {w: sorted(owners[w]) for w in worlds}, bus
    time.sleep(3.0)  # the kill comes 3 s after the last world reached < 0.05 (well inside the 30 s period)
    last_before = {w: good(w, "a")[-1] for w in of_a}
    a.send_signal(signal.SIGKILL)
    a.wait()
    killed = time.monotonic()

    def answered_by_b():
        st = status(e2, "b")
        return st and all((ln := link(st, w)) is not None and ln.state == "attached" and ln.steps > 0 for w in of_a)

    def after_kill() -> str:
        st = status(e2, "b")
        seen = {w: None if (ln := link(st, w)) is None else (ln.state, ln.steps) for w in of_a} if st else None
        # what b did, leaving out its embedding lines; the worlds log warnings only
        tails = {
            k: [x.rstrip() for x in v.lines if ": embedding v" not in x][-40:] for k, v in logs.items() if k != "a"
        }
        tool = procs.start("status", "--json", "--connect", e2)
        bus_view = tool.communicate(timeout=60)[0]
        return json.dumps(
            {"b_links": seen, "b_counters": dict(st.counters) if st else None, "status": bus_view, "stderr": tails},
            indent=1,
        )

    assert wait_for(answered_by_b, 15, every=0.05), after_kill()
    took = time.monotonic() - killed
    assert took <= 5.0, took
    st = status(e2, "b")
    assert st.counters["taken_over"] >= 2, st.counters  # resumed from a's shared checkpoints, not fresh
    assert wait_for(lambda: all(good(w, "b") for w in of_a), 60)
    for w in of_a:
        first_after = good(w, "b")[0]
        before = last_before[w]
        # resumed from what a learned (not relearned), and numbered after a's versions (none repeated)
        assert first_after["procrustes_error"] <= 1.5 * before["procrustes_error"], (w, first_after, before)
        assert first_after["version"] > before["version"], (w, first_after, before)
        print(
            f"takeover {w}: last before v{before['version']} {before['procrustes_error']:.4f}, first after "
            f"v{first_after['version']} {first_after['procrustes_error']:.4f}, answered again after {took:.2f} s"
        )
    print("stderr bytes:", {k: sum(map(len, v.lines)) for k, v in logs.items()})
    for p in ws.values():
        assert procs.stop(p) == 0
    for w in worlds:
        s = json.loads((tmp_path / w).read_text())
        # every step answered, and answered once: one answer per observation published (the last one
        # may be unanswered when the world stops), no answer by a second agent
        assert s["steps"] <= s["actions_received"] <= s["steps"] + s["resends"] + 1, (w, s)
        # leased: the world applied one owner per lease, the last lease is b's, a's before it on a's worlds
        assert s["max_owners_per_lease"] == 1 and s["actions_unleased"] == 0, (w, s)
        by_epoch = [s["lease_owners"][e] for e in sorted(s["lease_owners"], key=int)]
        assert by_epoch[-1] == ["b"] and (w not in of_a or by_epoch[-2] == ["a"]), (w, s)
    assert procs.stop(b) == 0


@pytest.mark.integration
def test_workers_share_the_worlds_of_one_agent(procs, endpoint, tmp_path):
    agent = procs.start("agent", "--listen", endpoint, "--workers", "2", "-q")
    assert wait_for(lambda: (st := status(endpoint, "a0.w1")) is not None and st, 90)
    ws = [
        procs.start("world", "bench", "--id", w, "--connect", endpoint, "--stats-json", str(tmp_path / w), "-q")
        for w in ("b1", "b2")
    ]

    def owners():
        st = procs.start("status", "--json", "--connect", endpoint)
        out, _ = st.communicate(timeout=60)
        return json.loads(out)["owners"] if st.returncode == 0 else {}

    # one world per worker, each answered by its owner only
    assert wait_for(lambda: sorted(owners().values()) == [["a0"], ["a0.w1"]], 60, every=1.0), owners()
    agg = status(endpoint, "a0")  # the agent's own status adds its worker's links
    assert agg.counters["workers"] == 2 and {ln.world_id for ln in agg.links if ln.state == "attached"} == {
        "b1",
        "b2",
    }, agg
    for p in ws:
        assert procs.stop(p) == 0
    for w in ("b1", "b2"):
        s = json.loads((tmp_path / w).read_text())
        assert s["steps"] > 100 and s["steps"] <= s["actions_received"] <= s["steps"] + s["resends"] + 1, (w, s)
    assert procs.stop(agent, timeout=30) == 0
