"""The locked-down bus (`sme secure init`, `--secure DIR`): mutual TLS and the router's access control,
over real zenoh on loopback (explicit tls/ endpoints on free ports; every process stopped by the test)."""

from __future__ import annotations

import json
import re
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sensorimotor.protocol import codec, keys, security
from sensorimotor.protocol.bus import Bus, BusConfig, BusError, BusMessage, Inbox
from sensorimotor.protocol.messages import Action, Control, Observation, WorldEvent
from sensorimotor.tools.commands.secure import init
from tests.conftest import ROOT, wait_for
from tests.conftest import agent_status as status
from tests.test_integration_bus import read_json_lines

pytestmark = pytest.mark.integration

WID = "g1"


def _sme(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.fixture(scope="module")
def secure_dir(tmp_path_factory: pytest.TempPathFactory) -> str:
    d = tmp_path_factory.mktemp("secure") / "creds"
    init(d)
    return str(d)


@pytest.fixture
def tls(endpoint: str) -> str:
    return endpoint.replace("tcp/", "tls/", 1)


def client(ep: str, secure_dir: str, credential: str) -> Bus:
    """A plain (non-retrying) client session presenting `credential`'s certificate."""
    return Bus(BusConfig(mode="client", connect=(ep,), credential=credential, secure_dir=secure_dir))


def drain(box: Inbox, seconds: float) -> list[BusMessage]:
    out, end = [], time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        m = box.get(timeout=left)
        if m is not None:
            out.append(m)
    return out


def obs_steps(msgs: list[BusMessage]) -> set[int]:
    return {codec.decode(Observation, m.payload).step for m in msgs}


def test_secure_init_makes_one_credential_per_role_and_refuses_to_overwrite(tmp_path: Path) -> None:
    from cryptography import x509

    d = tmp_path / "creds"
    out = _sme("secure", "init", str(d))
    assert out.returncode == 0, out.stderr
    assert stat.S_IMODE(d.stat().st_mode) == 0o700
    ca = x509.load_pem_x509_certificate((d / "ca.pem").read_bytes())
    assert stat.S_IMODE((d / "ca.key").stat().st_mode) == 0o600
    names = set()
    for role in security.CREDENTIALS:
        assert stat.S_IMODE((d / f"{role}.key").stat().st_mode) == 0o600, role
        cert = x509.load_pem_x509_certificate((d / f"{role}.pem").read_bytes())
        cert.verify_directly_issued_by(ca)
        cn = cert.subject.get_attributes_for_oid(x509.NameOID.COMMON_NAME)[0].value
        assert cn == security.common_name(role)
        names.add(cn)
    assert len(names) == 4
    agent = x509.load_pem_x509_certificate((d / "agent.pem").read_bytes())
    sans = agent.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "127.0.0.1" in {str(ip) for ip in sans.get_values_for_type(x509.IPAddress)}
    before = (d / "agent.pem").read_bytes()
    again = _sme("secure", "init", str(d))
    assert again.returncode == 2 and "--force" in again.stderr
    assert (d / "agent.pem").read_bytes() == before
    assert _sme("secure", "init", str(d), "--force").returncode == 0
    assert (d / "agent.pem").read_bytes() != before


def test_only_the_right_credential_reaches_a_world(procs, tls: str, secure_dir: str, tmp_path: Path) -> None:
    # The test holds the router (agent credential) and answers nothing: the world republishes its
    # observation k and waits. Only an Action that reaches it can move it to k + 1.
    with Bus(BusConfig.for_role("agent", tls, secure_dir)) as router:
        obs = router.inbox(keys.world_obs(WID))
        events = router.inbox(keys.world_event(WID))
        procs.start("world", "gridworld", "--id", WID, "--secure", secure_dir, "--connect", tls, "-q")
        first = obs.get(timeout=60)
        assert first is not None, "the world never published on the secure bus"
        k = codec.decode(Observation, first.payload).step
        bogus = codec.encode(Action(WID, k, (0.0,), timestamp=time.time()))
        control = codec.encode(Control(WID, "lesion", {}, id=666, timestamp=time.time()))
        perturb_control = codec.encode(Control(WID, "lesion", {}, id=7, timestamp=time.time()))

        # no certificate, or plain tcp to the tls port: no session at all
        no_cert = tmp_path / "no-cert.json5"
        no_cert.write_text(
            json.dumps({"transport": {"link": {"tls": {"root_ca_certificate": f"{secure_dir}/ca.pem"}}}})
        )
        with pytest.raises(BusError):
            Bus(BusConfig(mode="client", connect=(tls,), config_file=str(no_cert)))
        with pytest.raises(BusError):
            Bus(BusConfig(mode="client", connect=(tls.replace("tls/", "tcp/", 1),)))
        # a certificate from another CA: refused by mutual TLS
        other = tmp_path / "other"
        init(other)
        with pytest.raises(BusError):
            client(tls, str(other), "agent")

        # tool (read-only), perturb and world credentials cannot act; tool cannot perturb
        with client(tls, secure_dir, "tool") as tool, client(tls, secure_dir, "perturb") as perturb:
            with client(tls, secure_dir, "world") as fake_world:
                emb_world = fake_world.inbox(keys.ALL_EMBEDDINGS)
                emb_tool = tool.inbox(keys.ALL_EMBEDDINGS)
                # a read-only tool cannot pose as a world or as the agent's status
                alive: list[tuple[str, bool]] = []
                router.watch_alive(keys.ALL_ALIVE_WORLDS, lambda key, up: alive.append((key, up)))
                tool.token(keys.alive_world("fake"))
                tool.queryable(keys.agent_status("a9"), lambda key, payload: b"forged")
                time.sleep(1.0)  # declarations settle
                for bus in (tool, perturb, fake_world):
                    bus.put(keys.world_act(WID), bogus, codec.schema_name(Action))
                tool.put(keys.world_ctl(WID), control, codec.schema_name(Control))
                seen = drain(obs, 2.5)  # >= 4 resends of step k
                assert seen and obs_steps(seen) == {k}, obs_steps(seen)
                assert drain(events, 0.1) == [], "a control from the tool credential reached the world"
                assert keys.alive_world("fake") not in {key for key, _ in alive}
                assert router.get(keys.agent_status("a9"), timeout=1.0) == []

                # the agent's embeddings reach the tool, not a world credential
                router.put(keys.agent_embedding("a0", WID), b"embedding bytes")
                assert wait_for(lambda: len(emb_tool) > 0, 5)
                time.sleep(0.5)
                assert len(emb_world) == 0, "the world credential received an embedding"

            # the perturb credential may perturb (applied between steps, so reported after the next one)
            # and hears the world's answer (`sme perturb` waits for it)
            answers = perturb.inbox(keys.world_event(WID))
            perturb.put(keys.world_ctl(WID), perturb_control, codec.schema_name(Control))
            assert drain(events, 1.0) == []

            # the agent credential may act (a second agent connecting as a client): the world steps,
            # applies the queued controls and reports each: only the perturb credential's one is there
            with client(tls, secure_dir, "agent") as agent:
                time.sleep(0.5)
                agent.put(keys.world_act(WID), bogus, codec.schema_name(Action))
                assert wait_for(lambda: max(obs_steps(drain(obs, 0.5)), default=k) > k, 10), (
                    "the agent's action was lost"
                )
            reported = [codec.decode(WorldEvent, m.payload) for m in drain(events, 3.0)]
            controls = [e for e in reported if e.kind in ("control_applied", "control_refused")]
            assert len(controls) == 1 and controls[0].control_id == 7, reported
            heard = [codec.decode(WorldEvent, m.payload) for m in drain(answers, 1.0)]
            assert [e.control_id for e in heard if e.kind in ("control_applied", "control_refused")] == [7], heard


def test_agent_and_world_learn_on_the_secure_bus(procs, tls: str, secure_dir: str) -> None:
    s = ("--secure", secure_dir)
    agent = procs.start("agent", "--listen", tls, *s, "-q")
    world = procs.start("world", "gridworld", "--id", WID, "--connect", tls, *s, "-q")
    watch = procs.start("watch", "--json", "--no-events", "--count", "9", "--timeout", "120", "--connect", tls, *s)
    rows = read_json_lines(watch, 9, 130)
    assert [r["version"] for r in rows] == list(range(1, 10)), rows
    errs = [r["procrustes_error"] for r in rows]
    assert errs[0] > 0.5 and min(errs[-2:]) < 0.05, errs
    st = _sme("status", "--json", "--connect", tls, *s)
    assert st.returncode == 0, st.stderr
    # the perturb credential sees the world alive and reads its spec: a gridworld declares no
    # perturbations of its own (and `heal` is not a generic one), so `sme perturb` refuses the
    # control before sending it
    pt = _sme("perturb", "heal", "--world", WID, "--connect", tls, *s)
    assert pt.returncode == 1 and "gridworld has no perturbation 'heal'" in pt.stderr, pt.stderr
    # the same tool without the credential cannot even connect
    assert _sme("status", "--connect", tls).returncode == 2
    assert status(tls) is None  # a plain client on the tls port gets nothing
    assert procs.stop(world) == 0
    assert procs.stop(agent) == 0


def test_demo_runs_on_the_secure_bus(tls: str, secure_dir: str) -> None:
    out = _sme("demo", "--secure", secure_dir, "--listen", tls, "--steps", "12000", "--seconds", "120", timeout=180)
    assert out.returncode == 0, out.stderr
    assert "mutual TLS" in out.stdout
    m = re.search(r"Procrustes error against truth ([0-9.]+)", out.stdout)
    assert m and float(m.group(1)) < 0.05, out.stdout


@pytest.mark.parametrize("cmd", ["agent", "world", "perturb", "record", "watch", "status", "view", "replay", "demo"])
def test_every_bus_command_takes_secure(cmd: str) -> None:
    out = _sme(cmd, "--help")
    assert out.returncode == 0 and "--secure DIR" in out.stdout, out.stdout


def test_secure_refuses_plain_endpoints_and_missing_credentials(endpoint: str, tmp_path: Path) -> None:
    out = _sme("status", "--secure", str(tmp_path), "--connect", endpoint.replace("tcp/", "tls/", 1))
    assert out.returncode == 2 and "sme secure init" in out.stderr
    init(tmp_path / "c")
    out = _sme("agent", "--secure", str(tmp_path / "c"), "--listen", endpoint, "--seconds", "1")
    assert out.returncode == 2 and "tls/" in out.stderr


def test_an_agent_listening_beyond_loopback_without_secure_warns() -> None:
    assert security.exposure_warning("router", ("tcp/127.0.0.1:7447",), False) is None
    assert security.exposure_warning("router", ("tcp/0.0.0.0:7447",), True) is None
    assert security.exposure_warning("client", ("tcp/0.0.0.0:7447",), False) is None
    w = BusConfig.for_role("agent", "tcp/0.0.0.0:7447").exposure_warning()
    assert w and "steer every world" in w and "read every embedding" in w and "perturbations" in w
    # through the command, on an address this host does not have (TEST-NET-1): warned, then refused
    out = _sme("agent", "--listen", "tcp/192.0.2.1:7447", "--seconds", "1")
    assert "WARNING" in out.stderr and "steer every world" in out.stderr
