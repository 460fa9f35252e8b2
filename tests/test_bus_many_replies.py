"""Liveliness queries with more replies than zenoh's default reply channel holds (256).

Issue 41: `sme bench fuzz` declares ~800 fake worlds; the agent's liveliness audit then asked its
router session for every world token, the session pushed its answers into a 256-place channel
inside the query call, with its state locked, and waited forever for room: the agent stopped
answering its status (and, through the lock, its worlds). Real zenoh on loopback; each scenario
runs in a child process, so that a session that locks up fails the test instead of hanging it.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from tests.conftest import ROOT

N = 300  # more than the 256 replies zenoh's default channel holds


def _run(code: str, endpoint: str, seconds: float = 45.0) -> dict:
    """Run `code` (which prints one JSON line) in a child process; fail if it does not end in time."""
    script = textwrap.dedent(code).replace("ENDPOINT", endpoint).replace("N_TOKENS", str(N))
    try:
        p = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=seconds)
    except subprocess.TimeoutExpired:
        pytest.fail(f"no answer in {seconds:.0f} s: a session waits for room for its own replies")
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


@pytest.mark.integration
def test_liveliness_queries_list_more_tokens_than_the_reply_channel_holds(endpoint):
    out = _run(
        """
        import json, os, time
        from sensorimotor.protocol import keys
        from sensorimotor.protocol.bus import Bus, BusConfig
        router = Bus(BusConfig.for_role("agent", "ENDPOINT"))
        client = Bus(BusConfig.for_role("tool", "ENDPOINT"))
        held = [client.token(keys.alive_world(f"w{i}")) for i in range(N_TOKENS)]
        own = [router.token(keys.alive_owner(f"o{i}")) for i in range(N_TOKENS)]
        end = time.monotonic() + 10
        while len(router.alive(keys.ALL_ALIVE_WORLDS, timeout=0.5)) < N_TOKENS and time.monotonic() < end:
            time.sleep(0.1)
        print(json.dumps({
            "router_worlds": router.alive(keys.ALL_ALIVE_WORLDS, complete=True),  # its clients' tokens
            "router_owners": router.alive(keys.ALL_ALIVE_OWNERS, complete=True),  # its own
            "client_worlds": client.alive(keys.ALL_ALIVE_WORLDS, complete=True),  # its own (and the router's answer)
        }), flush=True)
        client.close(); router.close()
        """,
        endpoint,
    )
    worlds = sorted(f"sme/v1/alive/world/w{i}" for i in range(N))
    assert sorted(out["router_worlds"]) == worlds
    assert sorted(out["router_owners"]) == sorted(f"sme/v1/alive/owner/o{i}" for i in range(N))
    assert sorted(out["client_worlds"]) == worlds  # each listed once


@pytest.mark.integration
def test_the_daemon_audits_and_answers_beside_hundreds_of_worlds_it_does_not_own(endpoint):
    out = _run(
        """
        import json, time
        from sensorimotor.agent.daemon import AgentDaemon
        from sensorimotor.protocol import codec, keys
        from sensorimotor.protocol.bus import Bus, BusConfig
        from sensorimotor.protocol.messages import AgentStatus

        def wait(pred, seconds=20):
            end = time.monotonic() + seconds
            while not pred() and time.monotonic() < end:
                time.sleep(0.1)
            return bool(pred())

        bus = Bus(BusConfig.for_role("agent", "ENDPOINT"))
        other = Bus(BusConfig.for_role("tool", "ENDPOINT"))
        d = AgentDaemon(bus, agent_id="m")
        d.start()
        other.token(keys.alive_owner("a1"))  # another owner holds N worlds (the daemon none)
        for i in range(N_TOKENS):
            other.token(keys.alive_world(f"w{i}"))
            other.token(keys.alive_claim(f"w{i}", "a1"))
        booked = wait(lambda: len(d.book.view().worlds) == N_TOKENS)
        d.book.world("ghost", True)  # a disappearance never reported: only a whole audit sees it
        mended = wait(lambda: d.counters["liveliness_mended"] >= 1)
        replies = other.get(keys.agent_status("m"), timeout=5.0)
        st = codec.decode(AgentStatus, replies[0].payload) if replies else None
        print(json.dumps({
            "booked": booked,
            "mended": mended,
            "ghost": "ghost" in d.book.view().worlds,
            "status": None if st is None else [st.agent_id, st.counters["owned"], st.counters["claimed"]],
        }), flush=True)
        d.stop(); other.close(); bus.close()
        """,
        endpoint,
    )
    assert out == {"booked": True, "mended": True, "ghost": False, "status": ["m", 0, 0]}


class _LossyBus:
    """A bus whose liveliness answers to the audited expressions lose replies (as zenoh's did under
    load), while a query for one token alone finds it."""

    def __init__(self, alive: set[str], answers: dict[str, list[str]]) -> None:
        self.alive_tokens, self.answers = alive, answers
        self.calls: list[float] = []
        self.closed = False

    def alive(self, key: str, timeout: float = 1.0, complete: bool = False) -> list[str]:
        import time

        self.calls.append(time.monotonic())
        if key in self.answers:
            return list(self.answers[key])
        return [key] if key in self.alive_tokens else []


def test_the_audit_does_not_book_as_gone_what_a_lossy_answer_left_out():
    import threading
    import time

    from sensorimotor.agent.daemon import AgentDaemon
    from sensorimotor.protocol import keys
    from tests.conftest import wait_for

    w1, c_mine, c_other = keys.alive_world("w1"), keys.alive_claim("w1", "m"), keys.alive_claim("w2", "a1")
    c_new = keys.alive_claim("w3", "a2")
    bus = _LossyBus(
        alive={w1, c_other},  # w1 and a1's claim of w2 are alive; the audited answers lose them
        answers={
            keys.ALL_ALIVE_WORLDS: [keys.alive_world("w9")],  # w9 came, its event did not
            keys.ALL_ALIVE_OWNERS: [keys.alive_owner("m")],
            keys.ALL_CLAIMS: [c_new],  # lacks this owner's own claim: the whole answer is not used
        },
    )
    d = AgentDaemon(bus, agent_id="m")  # type: ignore[arg-type]
    d.AUDIT_EVERY = 0.05
    d._claims["w1"] = (None, time.monotonic() - 5.0)  # this owner's own claim, held for 5 s
    d.book.owner("m", True)
    d.book.world("w1", True)
    d.book.claim(c_other, True)
    d.book.claim(c_mine, True)
    d.book.world("ghost", True)  # booked, but nowhere on the bus: this one is mended
    t0 = time.monotonic()
    th = threading.Thread(target=d._audit_liveliness, daemon=True)
    th.start()
    try:
        assert wait_for(lambda: bus.calls and bus.calls[-1] - t0 > 3.0, 20)  # twice the audit's patience
    finally:
        d.stop()
        th.join(5)
    view = d.book.view()
    assert view.worlds == {"w1", "w9"}  # w1 left out of the answer but found alone; ghost gone; w9 came
    assert view.claimants("w2") == {"a1"} and view.claimants("w3") == frozenset()  # that answer not used
    assert d.counters["liveliness_mended"] == 2


def test_a_client_audit_books_only_what_it_finds_alive():
    """A worker (a client session) sees empty answers while its link to the router is re-made under
    load: its audit books appearances, never disappearances (those come with the events)."""
    import threading
    import time
    from types import SimpleNamespace

    from sensorimotor.agent.daemon import AgentDaemon
    from sensorimotor.protocol import keys
    from tests.conftest import wait_for

    bus = _LossyBus(
        alive=set(),  # nothing found, not even alone
        answers={
            keys.ALL_ALIVE_WORLDS: [keys.alive_world("back")],
            keys.ALL_ALIVE_OWNERS: [keys.alive_owner("m.w1")],
            keys.ALL_CLAIMS: [],
        },
    )
    bus.config = SimpleNamespace(mode="client")  # type: ignore[attr-defined]
    d = AgentDaemon(bus, agent_id="m", owner_id="m.w1")  # type: ignore[arg-type]
    d.AUDIT_EVERY = 0.05
    d.book.owner("m.w1", True)
    d.book.world("w1", True)  # absent from every answer
    t0 = time.monotonic()
    th = threading.Thread(target=d._audit_liveliness, daemon=True)
    th.start()
    try:
        assert wait_for(lambda: bus.calls and bus.calls[-1] - t0 > 3.0, 20)
    finally:
        d.stop()
        th.join(5)
    assert d.book.view().worlds == {"w1", "back"} and d.counters["liveliness_mended"] == 1
