import re
import subprocess
import sys

import pytest

from tests.conftest import ROOT

COMMANDS = [["agent"], ["world"], ["watch"], ["status"], ["demo"], ["bench"], ["bench", "loop"]]


@pytest.mark.parametrize("cmd", COMMANDS, ids=[" ".join(c) for c in COMMANDS])
def test_every_command_explains_itself(cmd):
    out = subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", *cmd, "--help"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert "usage: sme" in out.stdout
    if cmd[0] not in ("bench",) or len(cmd) > 1:
        assert len(out.stdout) > 300


def test_zenoh_flags_on_bus_commands():
    for cmd in ("agent", "world", "watch", "status"):
        out = subprocess.run(
            [sys.executable, "-m", "sensorimotor.tools.cli", cmd, "--help"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=60,
        ).stdout
        for flag in ("--mode", "--connect", "--listen", "--config", "--no-multicast-scouting"):
            assert flag in out, (cmd, flag)


def test_unknown_world_is_a_clear_error():
    out = subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", "world", "nowhere"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "unknown world 'nowhere'" in out.stderr


@pytest.mark.integration
@pytest.mark.parametrize("params,bound", [([], 0.05), (["--param", "barrier=true"], 0.10)], ids=["plain", "barrier"])
def test_demo_ends_with_a_good_gridworld_embedding(endpoint, params, bound):
    # bounded by steps, not time: on a loaded machine 10 s may be too few LSPI iterations
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "sensorimotor.tools.cli",
            "demo",
            "--world",
            "gridworld",
            "--steps",
            "12000",
            "--seconds",
            "120",
            "--listen",
            endpoint,
            *params,
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert out.returncode == 0, out.stderr
    m = re.search(r"Procrustes error against truth ([0-9.]+)", out.stdout)
    assert m, out.stdout
    assert float(m.group(1)) < bound
    assert "summary" in out.stdout and "embedding v1 " in out.stdout


def _sme(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", *args], cwd=ROOT, capture_output=True, text=True, timeout=60
    )


def test_world_refuses_an_unknown_param_naming_the_valid_keys(endpoint):
    out = _sme("world", "gridworld", "--param", "sise=5", "--connect", endpoint, "--steps", "1")
    assert out.returncode == 2, out.stderr
    assert "unknown parameter 'sise'" in out.stderr and "did you mean 'size'?" in out.stderr
    assert "size, barrier, actions, goal, max_episode_steps" in out.stderr


@pytest.mark.parametrize(
    "param,message",
    [
        ("size=abc", "gridworld: size='abc' is not an int"),
        ("actions=5", "gridworld: actions='5' is not one of 4, 8"),
        ("size", "--param expects key=value"),
    ],
)
def test_world_refuses_a_bad_value(endpoint, param, message):
    out = _sme("world", "gridworld", "--param", param, "--connect", endpoint, "--steps", "1")
    assert out.returncode == 2 and message in out.stderr, out.stderr


def test_world_lists_its_params():
    out = _sme("world", "gridworld", "--list-params")
    assert out.returncode == 0, out.stderr
    for text in ("size", "int", "9", "side of the square grid", "goal", "int,int | none", "max_episode_steps"):
        assert text in out.stdout
    every = _sme("world", "--list-params")
    assert every.returncode == 0 and all(name in every.stdout for name in ("retina:", "mountaincar:", "stereo:"))
    assert _sme("world", "nowhere", "--list-params").returncode == 2


@pytest.mark.parametrize(
    "param,message",
    [
        ("retna.embed_every=5", "unknown program 'retna' (did you mean 'retina'?)"),
        ("retina.embed_evry=5", "retina: unknown parameter 'embed_evry' (did you mean 'embed_every'?)"),
        ("retina.embed_every=abc", "retina: embed_every='abc' is not an int"),
        ("retina.rule=fancy", "retina: rule='fancy' is not one of basic, robust"),
        ("retina", "--program-param expects PROGRAM.KEY=VALUE"),
    ],
)
def test_agent_validates_program_params_at_start_up(endpoint, param, message):
    out = _sme("agent", "--listen", endpoint, "--seconds", "5", "--program-param", param)
    assert out.returncode == 2 and message in out.stderr, out.stderr


def test_agent_lists_program_params():
    out = _sme("agent", "--list-params")
    assert out.returncode == 0, out.stderr
    assert all(f"{name}:" in out.stdout for name in ("gridworld", "retina", "vergence", "mountaincar", "echo"))
    one = _sme("agent", "--list-params", "retina")
    assert one.returncode == 0 and "embed_every" in one.stdout and "gridworld:" not in one.stdout
    assert "float | none" in one.stdout
    bad = _sme("agent", "--list-params", "retna")
    assert bad.returncode == 2 and "did you mean 'retina'?" in bad.stderr


def test_demo_refuses_an_unknown_param(endpoint):
    out = _sme("demo", "--world", "gridworld", "--param", "sise=5", "--listen", endpoint, "--steps", "10")
    assert out.returncode == 2 and "did you mean 'size'?" in out.stderr, out.stderr


# --- the same behaviour in every command --------------------------------------------------------

# the least each command needs to parse (its positional arguments)
MINIMAL_ARGS = {
    "world": ["gridworld"],
    "perturb": ["heal", "--world", "g1"],
    "record": ["x.mcap"],
    "replay": ["x.mcap"],
    "recover": ["a.mcap", "b.mcap"],
    "reproduce": ["gridworld"],
    "secure init": ["DIR"],
}


def all_commands() -> list[list[str]]:
    """Every subcommand path of `sme` (e.g. ["bench", "loop"]), found by walking the parser."""
    import argparse

    from sensorimotor.tools.cli import build_parser

    def walk(p: argparse.ArgumentParser, path: list[str]):
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, child in a.choices.items():
                    yield path + [name], child
                    yield from walk(child, path + [name])

    return [path for path, _ in walk(build_parser(), [])]


def subparser(path: list[str]):
    import argparse

    from sensorimotor.tools.cli import build_parser

    p = build_parser()
    for name in path:
        p = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices[name]
    return p


def test_the_walk_finds_every_command():
    names = {" ".join(c) for c in all_commands()}
    assert {
        "agent",
        "world",
        "perturb",
        "watch",
        "status",
        "record",
        "replay",
        "recover",
        "view",
        "demo",
        "reproduce",
        "bench",
        "bench loop",
        "bench detectors",
    } <= names


@pytest.mark.parametrize("path", all_commands(), ids=lambda c: " ".join(c))
def test_every_command_documents_exit_codes_and_takes_q_and_v(path):
    from sensorimotor.tools.cli import build_parser
    from sensorimotor.tools.common import verbosity

    text = " ".join(subparser(path).format_help().split())
    for code in ("0 ok", "1 runtime failure", "2 usage error", "130 interrupted"):
        assert code in text, (path, code)
    argv = path + MINIMAL_ARGS.get(" ".join(path), [])
    assert verbosity(build_parser().parse_args(argv + ["-q"])) == -1
    assert verbosity(build_parser().parse_args(argv + ["-v"])) == 1
    assert verbosity(build_parser().parse_args(argv + ["-vv"])) == 2
    assert verbosity(build_parser().parse_args(argv + ["--quiet"])) == -1


def test_a_flag_given_to_a_parent_command_survives_its_subcommand():
    from sensorimotor.tools.cli import build_parser
    from sensorimotor.tools.common import verbosity

    assert verbosity(build_parser().parse_args(["bench", "-q", "loop"])) == -1
    assert verbosity(build_parser().parse_args(["-v", "status"])) == 1
    assert verbosity(build_parser().parse_args(["demo"])) == -1  # the demo prints its own progress
    assert verbosity(build_parser().parse_args(["agent"])) == 0


def test_record_accepts_q_on_the_real_command_line():
    out = subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", "record", "--help", "-q"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0 and "130 interrupted" in " ".join(out.stdout.split()), out.stderr


def test_usage_errors_exit_2_with_a_message(capsys):
    from sensorimotor.tools.cli import main

    assert main(["perturb", "heal", "--world", "g1", "--param", "novalue"]) == 2
    assert "sme perturb: --param expects key=value" in capsys.readouterr().err
    assert main(["world"]) == 2  # a NAME is required unless --list-params
    with pytest.raises(SystemExit) as e:  # argparse's own errors
        main(["world", "gridworld", "--steps", "many"])
    assert e.value.code == 2


def test_require_names_the_extra_to_install(monkeypatch, capsys, tmp_path):
    from sensorimotor.tools.cli import main
    from sensorimotor.tools.common import MissingExtra, require

    assert require("json").dumps([]) == "[]"
    with pytest.raises(MissingExtra, match=r"pip install 'sensorimotor-embedding\[experiments\]'"):
        require("sme_no_such_module", extra="experiments")
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as if it were not installed
    with pytest.raises(MissingExtra, match=r"'matplotlib'.*pip install 'sensorimotor-embedding\[experiments\]'"):
        require("matplotlib")
    # a command that needs it fails at once, with exit status 1 and the install line
    assert main(["reproduce", "gridworld", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "sme reproduce: this command needs 'matplotlib'" in err
    assert "pip install 'sensorimotor-embedding[experiments]'" in err
    assert not any(tmp_path.iterdir())  # nothing ran


def stops_cleanly_after_one_line(proc: subprocess.Popen, timeout: float = 30.0) -> tuple[int, str]:
    """Read one line of `proc`'s stdout, close the pipe as `head -1` would, and wait for the exit."""
    first = proc.stdout.readline()
    assert first, proc.stderr.read()
    proc.stdout.close()
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        pytest.fail(f"still running {timeout} s after its reader went away")
    return proc.returncode, proc.stderr.read()


@pytest.mark.integration
def test_watch_json_into_a_reader_that_closes_after_one_line(procs, endpoint):
    procs.start("agent", "--listen", endpoint, "-q")
    procs.start("world", "gridworld", "--id", "g1", "--connect", endpoint, "-q")
    watch = procs.start("watch", "--json", "--connect", endpoint)
    code, err = stops_cleanly_after_one_line(watch, timeout=120)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    assert code == 1  # the output was cut short: as the Python docs' recipe for EPIPE


def test_demo_into_a_reader_that_closes_after_one_line(endpoint):
    demo = subprocess.Popen(
        [sys.executable, "-m", "sensorimotor.tools.cli", "demo", "--seconds", "120", "--listen", endpoint],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    code, err = stops_cleanly_after_one_line(demo, timeout=60)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    assert code == 1


@pytest.mark.parametrize("path", all_commands(), ids=lambda c: " ".join(c))
def test_every_help_page_has_the_same_layout(path, monkeypatch):
    """usage, description, options (zenoh flags in their group), exit statuses; every paragraph
    wrapped to the terminal's width (no raw layout of its own)."""
    monkeypatch.setenv("COLUMNS", "100")
    text = subparser(path).format_help()
    assert text.startswith(f"usage: sme {' '.join(path)}"), text[:80]
    assert "\noptions:\n" in text and text.rstrip().split("\n\n")[-1].startswith("exit status: 0 ok")
    too_long = [ln for ln in text.splitlines() if len(ln) > 100]
    assert not too_long, too_long


def test_status_prints_a_table_not_a_dict():
    from sensorimotor.tools.commands.status import agent_lines

    d = {
        "agent": "a0",
        "uptime": 12.5,
        "owns": ["g1"],
        "counters": {"owned": 1, "claimed": 1, "dropped": 0, "released": 0},
        "links": [
            {
                "world": "g1",
                "kind": "gridworld",
                "program": "gridworld",
                "state": "attached",
                "steps": 12345,
                "episodes": 1234,
                "embedding_version": 27,
                "last_procrustes_error": 0.0102,
                "reward_mean": 0.41,
                "rejected": {"malformed": 2},
                "dropped": 0,
            }
        ],
    }
    lines = agent_lines(d)
    text = "\n".join(lines)
    assert "{" not in text and "}" not in text, text
    assert lines[0] == "agent a0: up 12.5 s; owns g1"
    assert "counters: claimed 1, owned 1 (zeros not shown)" in lines[1]
    header, row = lines[2], lines[3]
    assert header.split() == [
        "world",
        "kind",
        "program",
        "state",
        "steps",
        "episodes",
        "embedding",
        "procrustes",
        "reward",
        "dropped",
        "rejected",
    ]
    assert row.split()[:8] == ["g1", "gridworld", "gridworld", "attached", "12,345", "1,234", "v27", "0.0102"]
    assert header.index("embedding") == row.index("v27")  # columns line up
    assert row.rstrip().endswith("malformed 2")
