"""Versioned checkpoints (agent/checkpoint.py, the daemon's checkpoint and load path): a program
restored from a file continues exactly as the original; anything that is not a readable
checkpoint is refused with CheckpointError, and the daemon sets it aside and starts fresh."""

from __future__ import annotations

import dataclasses
import io
import json
import logging
import os
import pickle
from typing import Any

import numpy as np
import pytest

from sensorimotor.agent.checkpoint import (
    META_ENTRY,
    Checkpoint,
    CheckpointError,
    encode_checkpoint,
    read_checkpoint,
    write_checkpoint,
)
from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.agent.detectors import DETECTORS, make_detector
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol.messages import Action, Control, Embedding, Observation
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.gridworld import GridWorld
from sensorimotor.worlds.mountaincar import MountainCarWorld
from sensorimotor.worlds.retina import RetinaWorld
from sensorimotor.worlds.vergence import VergenceWorld

DETECTOR = "cusum"


def assert_same_tree(a: Any, b: Any, path: str = "state") -> None:
    """Equal snapshots: same keys, same plain values, arrays equal in dtype, shape and bytes."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert isinstance(a, np.ndarray) and isinstance(b, np.ndarray), path
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), path
    elif isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), path
        for k in a:
            assert_same_tree(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same_tree(x, y, f"{path}.{i}")
    else:
        assert a == b or (a != a and b != b), f"{path}: {a!r} != {b!r}"


class Recorder:
    """A link's outputs: actions answered, embeddings and events published."""

    def __init__(self) -> None:
        self.actions: list[Action] = []
        self.outputs: list[Any] = []

    def __call__(self, channel: str, msg: Any) -> None:
        (self.actions if channel == "act" else self.outputs).append(msg)


def lockstep(world, steps: int, links: list[WorldLink]) -> None:
    """Drive `world` with the first link's answers; every link sees every observation."""
    res = world.reset()
    episode, t, start = 0, 0, -1
    for k in range(steps):
        obs = Observation(world.world_id, episode, k, t, res.tensors, float(res.reward), bool(res.done), start)
        acts = [link.answer(obs) for link in links]
        act = acts[0]
        if res.done or act.reset:
            start = act.start if act.reset else -1
            res = world.reset(start=None if start < 0 else start)
            episode, t = episode + 1, 0
        else:
            res = world.step(np.asarray(act.values, dtype=np.float64))
            t += 1


def assert_same_outputs(a: Recorder, b: Recorder) -> int:
    """Identical decisions and outputs (embedding coordinates compared as bytes); returns the
    number of embeddings compared."""
    assert len(a.actions) == len(b.actions)
    for x, y in zip(a.actions, b.actions, strict=True):
        assert (x.step, x.values, x.reset, x.start) == (y.step, y.values, y.reset, y.start)
    assert [type(o) for o in a.outputs] == [type(o) for o in b.outputs]
    n = 0
    for x, y in zip(a.outputs, b.outputs, strict=True):
        if isinstance(x, Embedding):
            n += 1
            assert (x.version, x.trigger, x.ids, x.eigenvalues, x.step, x.metrics) == (
                y.version,
                y.trigger,
                y.ids,
                y.eigenvalues,
                y.step,
                y.metrics,
            )
            assert x.coordinates.dtype == y.coordinates.dtype and x.coordinates.tobytes() == y.coordinates.tobytes()
        else:
            assert (x.kind, x.detail, x.step, x.values) == (y.kind, y.detail, y.step, y.values)
    return n


def grid():
    return GridWorld(seed=0)


def retina():
    return RetinaWorld(seed=0, supersample=1)


def vergence():
    return VergenceWorld(seed=0)


def spot_lag():
    """Camera frames of a lagging spot (tests/spot_env.py): saved in the move-size probe's second half."""
    from sensorimotor.worlds.registry import make_world

    return make_world("gym:tests.spot_env:zoo-test/SpotLag-v0", "spot", 0)


def beacons():
    from tests.test_generic_program import Beacons

    return Beacons()


def mountaincar():
    return MountainCarWorld(seed=0, n_eval=2, n_positions=8, max_car_steps=60)


def arm_turned_late():
    """The arm seen by its camera (LSPI), whose actions act a step late from its 8,000th step: saved
    while relearning with the action sent last in the state."""
    from sensorimotor.tools.bench.changes_families import family

    w = family("Arm Kuka iiwa, 2 joints (sme world arm)").build(2)
    step, n = w.step, [0]

    def late(values):
        n[0] += 1
        if n[0] == 8000:
            w.perturb(Control(w.world_id, "delay", {"steps": "1"}))
        return step(values)

    w.step = late
    return w


# (world factory, program hint override, program params, steps before (or a condition on the program to
# run until), steps after, embeddings expected after)
CASES = {
    "echo": (grid, "echo", {}, 300, 200, 0),
    "gridworld": (grid, None, {"samples_per_iteration": 200}, 1500, 1500, 1),
    # the generic program on raw sensor vectors (PCA + RBF) and on state ids (tabular)
    "generic": (beacons, None, {"samples_per_iteration": 150}, 1200, 1200, 1),
    "generic-ids": (grid, "generic", {"samples_per_iteration": 200, "learner": "tabular"}, 1500, 1500, 1),
    # the model learner, saved while it explores (its counts, plan in flight and way to the untried)
    "generic-model": (grid, "generic", {"samples_per_iteration": 200}, 300, 1500, 1),
    "retina": (retina, None, {"embed_every": 200}, 700, 500, 1),
    # the planner over camera frames, saved while it probes half moves in the motor coordinates
    "generic-frames": (spot_lag, "generic", {"motor_warmup": 1500, "embed_every": 2000}, 2300, 1500, 0),
    "vergence": (vergence, None, {"samples_per_iteration": 100}, 1500, 1500, 1),
    # reaches the driving stage (Sarsa, Kalman filter) before the checkpoint; episodes end, are
    # watched and evaluated after it
    "mountaincar": (
        mountaincar,
        None,
        {"samples_per_iteration": 200, "eval_every": 40, "watch_after": 30, "report_after": 20},
        2500,
        1500,
        0,
    ),
    # LSPI features of the frame with the action sent last, saved while relearning a delayed body
    "generic-history": (arm_turned_late, None, {}, lambda p: p._history and p.new_samples > 100, 1500, 0),
    # saved while the eyes look either side of a fixation (the sub-step reading in flight)
    "mountaincar-aside": (
        mountaincar,
        None,
        {"samples_per_iteration": 200, "eval_every": 40, "watch_after": 30, "report_after": 20},
        lambda p: p.training_steps > 100 and p.reading.goal is not None,
        1500,
        0,
    ),
}


@pytest.mark.parametrize("kind", sorted(CASES))
def test_restored_program_continues_exactly(kind, tmp_path):
    make_world, hint, params, before, after, min_embeddings = CASES[kind]
    world = make_world()
    try:
        spec = world.spec()
        if hint is not None:
            spec = dataclasses.replace(spec, program=hint)
        name = spec.program or spec.kind
        program = make_program(spec, 3, **params)
        detector = make_detector(DETECTOR, **program.detector_params)
        if callable(before):  # run until the program is in the state the case saves it in
            first = run_inprocess(world, program, 10**6, detector=detector, stop_when=lambda r: before(program))
            assert before(program)
        else:
            first = run_inprocess(world, program, before, detector=detector)

        daemon = AgentDaemon(
            bus=None, seed=3, state_dir=str(tmp_path), program_params={name: params}, detector=DETECTOR
        )
        original = Recorder()
        link = WorldLink("a", spec, program, original, detector)
        link.version = len(first.embeddings)
        daemon.links[spec.world_id] = link
        daemon.checkpoint()
        assert os.listdir(tmp_path) == [f"{spec.world_id}.ckpt.npz"]
        saved = daemon._load_checkpoint(spec)
        assert saved is not None and saved.version == link.version
        restored_program = saved.program
        assert restored_program is not program and type(restored_program) is type(program)
        assert_same_tree(restored_program.state(), program.state())
        assert_same_tree(saved.detector.state(), detector.state())

        restored = Recorder()
        twin = WorldLink("a", spec, restored_program, restored, saved.detector)
        twin.version = saved.version
        lockstep(world, after, [link, twin])
        assert len(original.actions) == after
        assert assert_same_outputs(original, restored) >= min_embeddings
        assert_same_tree(restored_program.state(), program.state())
        assert_same_tree(twin.detector.state(), link.detector.state())
        if kind.startswith("mountaincar"):
            assert program.sarsa is not None and program.episodes >= 2 and program.curve
            assert any(o.kind == "evaluation" for o in original.outputs if not isinstance(o, Embedding))
    finally:
        close = getattr(world, "close", None)
        if close:
            close()


@pytest.mark.parametrize("name", sorted(DETECTORS))
@pytest.mark.parametrize("seed", range(6))
def test_detector_restored_midstream_flags_the_same_drops(name, seed):
    rng = np.random.default_rng(seed)
    split = int(rng.integers(0, 450))  # anywhere: in the warm-up, before, during or after the drop
    x = np.concatenate([rng.normal(1.0, 0.1, 250), rng.normal(0.3, 0.1, 200)])
    a = make_detector(name, warmup=30)
    flags_a = [a.update(v) for v in x[:split]]
    b = make_detector(name, warmup=30)
    buf = io.BytesIO(encode_checkpoint(_ckpt({"detector": a.state()})))
    b.restore(_decode(buf)["detector"])
    flags_b = list(flags_a)
    for v in x[split:]:
        flags_a.append(a.update(v))
        flags_b.append(b.update(v))
        assert a.statistic == b.statistic
    assert flags_a == flags_b


def _ckpt(state: dict) -> Checkpoint:
    spec = GridWorld(seed=0).spec()
    return Checkpoint(
        spec.world_id,
        spec.kind,
        spec.program,
        tuple(spec.sensors),
        spec.action_space,
        4,
        "GridworldProgram",
        {"gamma": 0.9, "centres": (0.1, 0.2)},
        state,
        None,
    )


def _decode(buf: io.BytesIO) -> dict:
    from sensorimotor.agent.checkpoint import decode_checkpoint

    return decode_checkpoint(buf.getvalue()).program_state


def test_round_trip_keeps_values_dtypes_and_big_ints(tmp_path):
    rng = np.random.default_rng(7)
    state = {
        "rng": rng.bit_generator.state,
        "w": np.arange(6, dtype=np.float32).reshape(2, 3),
        "ids": np.array([3, 1], dtype=np.int64),
        "flags": np.array([True, False]),
        "none": None,
        "nan": float("nan"),
        "nested": {"list": [1, 2.5, "x", None, [np.zeros(2)]], "empty": np.zeros((0, 4))},
        "np_scalar": np.float64(0.1) * 3,
    }
    path = str(tmp_path / "c.ckpt.npz")
    write_checkpoint(path, _ckpt(state))
    back = read_checkpoint(path)
    assert back.version == 4 and back.program_class == "GridworldProgram" and back.same_body(GridWorld(seed=0).spec())
    assert back.program_params == {"gamma": 0.9, "centres": [0.1, 0.2]}
    s = back.program_state
    assert s["rng"] == rng.bit_generator.state  # 128-bit ints survive JSON
    assert_same_tree(s["w"], state["w"])
    assert_same_tree(s["ids"], state["ids"]) and s["flags"].dtype == bool
    assert s["none"] is None and s["nan"] != s["nan"] and s["np_scalar"] == 0.1 * 3
    assert s["nested"]["list"][:4] == [1, 2.5, "x", None] and s["nested"]["empty"].shape == (0, 4)
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]


@pytest.mark.parametrize(
    "bad", [{"a.b": 1}, {1: 2}, {"__array__": "x"}, {"o": object()}, {"o": np.array([None], dtype=object)}]
)
def test_state_that_is_not_plain_data_is_refused_on_write(bad):
    with pytest.raises(ValueError):
        encode_checkpoint(_ckpt(bad))


def _valid_bytes() -> bytes:
    return encode_checkpoint(_ckpt({"w": np.ones(100)}))


def _with_meta(change) -> bytes:
    buf = io.BytesIO()
    with np.load(io.BytesIO(_valid_bytes()), allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    meta = json.loads(arrays[META_ENTRY].tobytes())
    change(meta)
    arrays[META_ENTRY] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    np.savez(buf, **arrays)
    return buf.getvalue()


BAD_FILES = {
    "garbage": lambda: os.urandom(2000),
    "empty": lambda: b"",
    "truncated": lambda: _valid_bytes()[: len(_valid_bytes()) // 2],
    "future_version": lambda: _with_meta(lambda m: m.update(format_version=99)),
    "old_version": lambda: _with_meta(lambda m: m.update(format_version=0)),
    "foreign_npz": lambda: (lambda b: (np.savez(b, x=np.ones(3)), b.getvalue())[1])(io.BytesIO()),
    "foreign_format": lambda: _with_meta(lambda m: m.update(format="something-else")),
    "missing_entry": lambda: _with_meta(lambda m: m.pop("program_state")),
    "pickle": lambda: pickle.dumps({"spec": None, "program": object(), "version": 3}),
    "pickled_array": lambda: (
        lambda b: (np.savez(b, **{META_ENTRY: np.array([{"a": 1}], dtype=object)}), b.getvalue())[1]
    )(io.BytesIO()),
}


@pytest.mark.parametrize("kind", sorted(BAD_FILES))
def test_bad_files_raise_checkpoint_error(kind, tmp_path):
    path = tmp_path / "x.ckpt.npz"
    path.write_bytes(BAD_FILES[kind]())
    with pytest.raises(CheckpointError) as e:
        read_checkpoint(str(path))
    if kind == "future_version":
        assert "newer" in str(e.value)
    assert str(e.value)


def test_a_pickle_is_never_unpickled(tmp_path):
    marker = tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    path = tmp_path / "x.ckpt.npz"
    path.write_bytes(pickle.dumps(Payload()))
    with pytest.raises(CheckpointError, match="pickle"):
        read_checkpoint(str(path))
    assert not marker.exists()


@pytest.mark.parametrize("kind", ["garbage", "truncated", "future_version", "pickle"])
def test_daemon_sets_a_bad_checkpoint_aside_and_starts_fresh(kind, tmp_path, caplog):
    spec = GridWorld(seed=0).spec()
    path = tmp_path / f"{spec.world_id}.ckpt.npz"
    path.write_bytes(BAD_FILES[kind]())
    daemon = AgentDaemon(bus=None, state_dir=str(tmp_path))
    with caplog.at_level(logging.WARNING, logger="sme.agent"):
        assert daemon._load_checkpoint(spec) is None
    aside = [f for f in os.listdir(tmp_path) if f.startswith(f"{path.name}.bad-")]
    assert not path.exists() and len(aside) == 1
    assert str(path) in caplog.text and "starting fresh" in caplog.text


def test_daemon_sets_aside_a_checkpoint_of_another_body(tmp_path, caplog):
    world = GridWorld(seed=0)
    program = make_program(world.spec(), 0)
    run_inprocess(world, program, 50)
    daemon = AgentDaemon(bus=None, state_dir=str(tmp_path))
    daemon.links[world.world_id] = WorldLink("a", world.spec(), program, Recorder(), None)
    daemon.checkpoint()
    other = GridWorld(seed=0, size=7).spec()  # same id, smaller body
    with caplog.at_level(logging.WARNING, logger="sme.agent"):
        assert daemon._load_checkpoint(other) is None
    assert [f for f in os.listdir(tmp_path) if ".ckpt.npz.other-body-" in f]
    assert "different world body" in caplog.text
    assert daemon._load_checkpoint(world.spec()) is None  # set aside: nothing to load any more


def test_daemon_sets_aside_a_state_that_does_not_fit_the_program(tmp_path, caplog):
    world = GridWorld(seed=0)
    program = make_program(world.spec(), 0)
    daemon = AgentDaemon(bus=None, state_dir=str(tmp_path))
    daemon.links[world.world_id] = WorldLink("a", world.spec(), program, Recorder(), None)
    daemon.checkpoint()
    path = str(tmp_path / f"{world.world_id}.ckpt.npz")
    ckpt = read_checkpoint(path)
    state = dict(ckpt.program_state, lspi={**ckpt.program_state["lspi"], "w": np.zeros(3)})
    write_checkpoint(path, dataclasses.replace(ckpt, program_state=state))
    with caplog.at_level(logging.WARNING, logger="sme.agent"):
        assert daemon._load_checkpoint(world.spec()) is None
    assert "program_state.lspi.w has shape [3]" in caplog.text
    assert [f for f in os.listdir(tmp_path) if ".ckpt.npz.bad-" in f]


def test_a_restored_world_reports_the_steps_it_has_learned(tmp_path):
    """Not "step 0, embedding v27": a link restored from a checkpoint counts the steps learned
    before it, says so in its `attached` event, and saves them again in its next checkpoint."""
    from sensorimotor.agent.attach import AgentConfig, attach

    world = GridWorld(seed=0)
    program = make_program(world.spec(), 0)
    daemon = AgentDaemon(bus=None, state_dir=str(tmp_path))
    link = WorldLink("a", world.spec(), program, Recorder(), None)
    daemon.links[world.world_id] = link
    lockstep(world, 120, [link])
    assert link.learned_steps == 120
    daemon.checkpoint()
    restored = daemon._load_checkpoint(world.spec())
    assert restored is not None and restored.steps == 120
    out = Recorder()
    att = attach(world.spec(), AgentConfig("a"), out, restored=restored)
    assert att.how == "restored" and att.link.counters.steps == 0 and att.link.learned_steps == 120
    (ev,) = [o for o in out.outputs if getattr(o, "kind", "") == "attached"]
    assert "120 steps learned" in ev.detail, ev.detail
    lockstep(world, 30, [att.link])
    daemon.links[world.world_id] = att.link
    daemon.checkpoint()
    assert read_checkpoint(str(tmp_path / f"{world.world_id}.ckpt.npz")).steps == 150


def test_a_program_asking_for_the_cusum_of_failures_gets_its_state_back_and_never_a_z_score_cusums(tmp_path):
    """The mountain car's detector is the "cusum" family's BernoulliCUSUM: its saved state comes
    back; a state saved by the z-score CUSUM (an older checkpoint) gives a fresh detector instead of
    a failure rate read from rewards."""
    from sensorimotor.agent.detectors import CUSUM, BernoulliCUSUM

    spec = MountainCarWorld(seed=0, n_eval=2).spec()
    program = make_program(spec, 0)
    detector = make_detector("cusum", **program.detector_params)
    assert isinstance(detector, BernoulliCUSUM)
    for v in [-0.2] * 40 + [-1.0, -1.0]:
        detector.update(v)
    daemon = AgentDaemon(bus=None, state_dir=str(tmp_path))
    daemon.links[spec.world_id] = WorldLink("a", spec, program, Recorder(), detector)
    daemon.checkpoint()
    restored = daemon._load_checkpoint(spec)
    assert restored is not None and isinstance(restored.detector, BernoulliCUSUM)
    assert restored.detector.statistic == detector.statistic > 0
    old = CUSUM(warmup=20, rate=0.05)
    for v in [-0.3] * 40:
        old.update(v)
    path = str(tmp_path / f"{spec.world_id}.ckpt.npz")
    write_checkpoint(path, dataclasses.replace(read_checkpoint(path), detector_state=old.state()))
    restored = daemon._load_checkpoint(spec)
    assert restored is not None and restored.detector is None  # attach makes a fresh one
