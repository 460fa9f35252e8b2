"""`sme bench fuzz`: the hostile messages, from a seeded generator (`Fuzzer`), each built to be
counted by exactly one agent counter, and the local validators that check so before it is sent."""

from collections.abc import Callable
from typing import Any

import numpy as np

from sensorimotor.agent.link import check_against_spec, check_truth
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol import sme_v1_pb2 as pb
from sensorimotor.protocol.errors import ProtocolError, SpecMismatch
from sensorimotor.protocol.messages import Observation, Truth, WorldEvent, WorldSpec
from sensorimotor.tools.bench.fuzz_status import GOOD

# category -> (weight, the agent counter expected to count it; "rejected" = the good link's rejections)
CATEGORIES: dict[str, tuple[float, str]] = {
    "obs_bytes": (8, "rejected"),
    "obs_version": (5, "rejected"),
    "obs_dtype": (5, "rejected"),
    "obs_shape": (5, "rejected"),
    "obs_oversize": (5, "rejected"),
    "obs_nonfinite": (6, "rejected"),
    "obs_spec": (6, "rejected"),
    "obs_wrong_world": (4, "rejected"),
    "obs_duplicate": (3, "rejected"),
    "truth_bad": (12, "bad_truth"),
    "event_bad": (12, "bad_world_event"),
    "unattached": (15, "unattached"),
    "attach": (8, "attach_failed"),
}
BIG_EVERY = 1000  # every BIG_EVERY-th observation message is a real tensor over the 32 MiB limit


class Fuzzer:
    """Hostile payloads from a seeded generator; `spec` is the good world's spec."""

    def __init__(self, spec: WorldSpec, seed: int) -> None:
        self.spec = spec
        self.rng = np.random.default_rng(seed)
        self.n_obs = 0

    def _valid_obs(self, step: int | None = None) -> pb.Observation:
        rng = self.rng
        p = pb.Observation(
            schema_version=1,
            world_id=self.spec.world_id,
            episode=int(rng.integers(0, 1 << 40)),
            step=int(rng.integers(0, 1 << 62)) if step is None else step,
            t=int(rng.integers(0, 100)),
            reward=float(rng.normal()),
            session="fuzz",
        )
        for s in self.spec.sensors:
            a = np.zeros(s.shape, dtype=s.dtype)
            p.tensors.add(name=s.name, dtype=s.dtype, shape=list(s.shape), data=a.tobytes())
        return p

    def garbage(self) -> bytes:
        n = int(self.rng.integers(1, 300))
        raw = self.rng.bytes(n)
        return raw if self.rng.random() < 0.5 else b"\x07" + raw  # field 0: never a valid protobuf

    def observation(self, cat: str) -> bytes:
        rng, p = self.rng, self._valid_obs()
        self.n_obs += 1
        if cat == "obs_bytes":
            return self.garbage()
        if cat == "obs_version":
            p.schema_version = int(rng.choice([0, 2, 3, 99, 2**32 - 1]))
        elif cat == "obs_dtype":
            t = p.tensors[int(rng.integers(len(p.tensors)))] if p.tensors else p.tensors.add(name="x", shape=[1])
            t.dtype = str(rng.choice(["float16", "complex64", "object", "", "U8", "<i4", "int128"]))
        elif cat == "obs_shape":
            t = p.tensors.add(name="extra", dtype="float32", shape=[3, 4], data=b"\0" * int(rng.choice([0, 47, 49])))
            if rng.random() < 0.3:
                t.shape[:] = [1] * 9
                t.data = b"\0" * 4
        elif cat == "obs_oversize":
            if self.n_obs % BIG_EVERY == 0:  # a real one: 33 MiB of data
                n = codec.MAX_TENSOR_BYTES + (1 << 20)
                p.tensors.add(name="big", dtype="uint8", shape=[n], data=bytes(n))
            elif rng.random() < 0.5:
                p.tensors.add(name="big", dtype="float64", shape=[1 << 20, 1 << 20], data=b"")
            else:
                for i in range(codec.MAX_TENSORS + 1):
                    p.tensors.add(name=f"t{i}", dtype="uint8", shape=[1], data=b"\0")
        elif cat == "obs_nonfinite":
            bad = float(rng.choice([np.nan, np.inf, -np.inf]))
            if rng.random() < 0.5:
                p.reward = bad
            else:
                a = rng.normal(size=8)
                a[int(rng.integers(8))] = bad
                p.tensors.add(name="junk", dtype="float64", shape=[8], data=a.tobytes())
        elif cat == "obs_spec":
            s = self.spec.sensors[int(rng.integers(len(self.spec.sensors)))]
            t = next(t for t in p.tensors if t.name == s.name)
            how = rng.integers(3)
            if how == 0:
                p.tensors.remove(t)
            elif how == 1:  # another dtype, same shape
                dt = "float64" if s.dtype != "float64" else "int32"
                t.dtype, t.data = dt, np.zeros(s.shape, dtype=dt).tobytes()
            else:  # another shape
                shape = [*s.shape, 2]
                t.shape[:], t.data = shape, np.zeros(shape, dtype=s.dtype).tobytes()
        elif cat == "obs_wrong_world":
            p.world_id = str(rng.choice(["other", "", "good2", GOOD + "\n"]))
        elif cat == "obs_duplicate":
            t = p.tensors.add()
            t.CopyFrom(p.tensors[0])
        return p.SerializeToString()

    def truth(self) -> bytes:
        rng = self.rng
        p = pb.Truth(schema_version=1, world_id=GOOD, kind="start_states", step=int(rng.integers(1 << 30)))
        pos = rng.normal(size=(81, 2))
        how = int(rng.integers(8))
        if how == 0:
            return self.garbage()
        if how == 1:
            p.schema_version = int(rng.choice([0, 2, 99]))
        elif how == 2:
            pos[int(rng.integers(81)), int(rng.integers(2))] = float(rng.choice([np.nan, np.inf]))
        elif how == 3:
            p.world_id = str(rng.choice(["other", "", "good "]))
        elif how == 4:  # positions that the evaluation cannot use: 1-D, integer
            pos = pos[:, 0] if rng.random() < 0.5 else pos.astype(np.int64)
        elif how == 5:
            p.tensors.add(name="pixels", dtype="float64", shape=list(pos.shape), data=pos.tobytes())
            return p.SerializeToString()  # no positions at all
        elif how == 6:
            p.tensors.add(name="positions", dtype="float64", shape=[1 << 30, 2], data=b"")
            return p.SerializeToString()
        else:
            p.tensors.add(name="positions", dtype="float64", shape=list(pos.shape), data=pos.tobytes())
        p.tensors.add(name="positions", dtype=pos.dtype.name, shape=list(pos.shape), data=pos.tobytes())
        return p.SerializeToString()

    def world_event(self) -> bytes:
        rng = self.rng
        p = pb.WorldEvent(schema_version=1, world_id=GOOD, kind="action_refused", reason="bad_action", step=1)
        how = int(rng.integers(3))
        if how == 0:
            return self.garbage()
        if how == 1:
            p.schema_version = int(rng.choice([0, 2, 99]))
        else:
            p.world_id = str(rng.choice(["other", "", "g00d"]))
        return p.SerializeToString()

    def unattached(self, n: int) -> tuple[str, bytes]:
        """(key, payload) for a world with no link: anything goes, the agent must not even decode it."""
        rng = self.rng
        wid = f"ghost-{n % 7}"
        which = int(rng.integers(3))
        key = (keys.world_obs, keys.world_truth, keys.world_event)[which](wid)
        if rng.random() < 0.5:
            return key, self.garbage()
        if which == 0:
            p = self._valid_obs(step=n)
            p.world_id = wid
            return key, p.SerializeToString()
        if which == 1:
            return key, codec.encode(Truth(wid, "start_states", {"positions": np.zeros((3, 2))}))
        return key, codec.encode(WorldEvent(wid, "control_applied", "lesion"))

    ATTACH_VARIANTS = (
        "garbage",
        "version",
        "bad_dtype",
        "other_world",
        "nan_bound",
        "unknown_program",
        "no_state_sensor",
        "huge_states",
        "box_for_gridworld",
        "error_reply",
        "bad_id",
    )

    def fake_spec(self, wid: str, variant: str) -> bytes:
        """The spec a fake world answers with (the variant says how it is broken)."""
        rng = self.rng
        p = pb.WorldSpec(schema_version=1, world_id=wid, kind="gridworld", program="gridworld", n_starts=81)
        p.sensors.add(name="state", dtype="int32", shape=[1], low=0, high=80)
        p.action_space.discrete_n = 4
        if variant == "garbage":
            return self.garbage()
        if variant == "version":
            p.schema_version = int(rng.choice([0, 2, 99]))
        elif variant == "bad_dtype":
            p.sensors[0].dtype = "float16"
        elif variant == "other_world":
            p.world_id = GOOD  # claims to be the good world
        elif variant == "nan_bound":
            p.reward_max = float("nan")
        elif variant == "unknown_program":
            # an unknown program falls back to the generic one, which needs at least one sensor
            p.program = p.kind = f"nosuch{int(rng.integers(100))}"
            del p.sensors[:]
        elif variant == "no_state_sensor":
            p.sensors[0].name = "pixels"
        elif variant == "huge_states":
            p.sensors[0].high = float(rng.choice([1e12, 1e300]))
        elif variant == "box_for_gridworld":
            p.action_space.discrete_n = 0
            p.action_space.low.append(-1.0)
            p.action_space.high.append(1.0)
        return p.SerializeToString()


def _refused(check: Callable[[], Any]) -> bool:
    try:
        check()
    except ProtocolError:
        return True
    return False


def _obs_kind(payload: bytes, spec: WorldSpec) -> str | None:
    """The rejection kind the agent's link will count for this payload (None: it would be accepted)."""
    try:
        obs = codec.decode(Observation, payload)
        if obs.world_id != spec.world_id:
            raise SpecMismatch("wrong world")
        check_against_spec(obs, spec)
    except ProtocolError as e:
        return e.kind
    return None


def _truth_refused(payload: bytes) -> bool:
    return _refused(lambda: check_truth(codec.decode(Truth, payload), GOOD))


def _event_refused(payload: bytes) -> bool:
    def check() -> None:
        if codec.decode(WorldEvent, payload).world_id != GOOD:
            raise SpecMismatch("wrong world")

    return _refused(check)
