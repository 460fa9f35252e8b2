"""Checkpoint files: one world link's learned state as explicit, versioned arrays and values.

A checkpoint is a single numpy `.npz` file (a zip of `.npy` entries, written with `np.savez`):

- entry `checkpoint.json` (uint8 bytes): UTF-8 JSON with `format` ("sensorimotor-checkpoint"),
  `format_version` (FORMAT_VERSION) and every plain value - the world body it was learned on, the
  embedding version, the program class and params, the program and detector state;
- one entry per numpy array of those states, named by its dotted path (`program_state.lspi.w`);
  in the JSON the array's place holds `{"__array__": "<entry name>"}`.

It is read with `allow_pickle=False` and holds no pickle: loading a file someone else wrote cannot
run their code, and renaming a class does not invalidate it (state is plain data, see the
convention in `sensorimotor.agent.programs.base`). Anything that is not such a file - garbage, a
truncated write, a pickle, another format or an unknown format version - raises CheckpointError.
Files are written atomically (temporary file, fsync, os.replace), so a kill leaves the old
checkpoint or the new one, never half of one.
"""

from __future__ import annotations

import io
import json
import math
import os
import time
import zipfile
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import numpy as np

from sensorimotor.protocol.keys import check_id
from sensorimotor.protocol.limits import EMBEDDING_VERSION_MAX, EPOCH_MAX
from sensorimotor.protocol.messages import ActionSpace, SensorSpec, WorldSpec

FORMAT = "sensorimotor-checkpoint"
FORMAT_VERSION = 1
META_ENTRY = "checkpoint.json"
ARRAY_MARK = "__array__"


MAX_CHECKPOINT_BYTES = 32 * 1024 * 1024  # a checkpoint file (or shared copy) larger than this is refused unread
MAX_INFLATED_BYTES = 256 * 1024 * 1024  # the sum of the zip entries' declared sizes, checked before inflating
MAX_CLOCK_SKEW = 300.0  # seconds a checkpoint may be dated in the future (clocks of other hosts)
MAX_COUNTER = 2**53  # steps above this are not counts any run can reach (nor exact in JSON)
#: a restored embedding version must leave room for the next one on the wire (a uint32 field)
MAX_VERSION = EMBEDDING_VERSION_MAX - 1


class CheckpointError(Exception):
    """A file that is not a checkpoint this code can read (the message says why)."""


@dataclass(frozen=True)
class Checkpoint:
    """What a checkpoint holds: the world body the state was learned on (for the same-body check),
    the link's embedding version, and the program (class name, the params it was made with, its
    `state()`) and drop detector (`state()`, None without one)."""

    world_id: str
    kind: str
    program: str  # the world's program hint (WorldSpec.program), part of the body check
    sensors: tuple[SensorSpec, ...]
    action_space: ActionSpace
    version: int
    program_class: str
    program_params: dict[str, Any] = field(default_factory=dict)
    program_state: dict[str, Any] = field(default_factory=dict)
    detector_state: dict[str, Any] | None = None
    saved_at: float = 0.0  # seconds since the epoch when the state was taken (0: unknown); orders shared copies
    steps: int = 0  # steps the link had answered when the state was taken (informative)
    owner: str = ""  # the owner that answered the world when the state was taken ("" unknown)
    epoch: int = 0  # that owner's lease epoch on the world (0: none or unknown)

    def same_body(self, spec: WorldSpec) -> bool:
        """True when `spec` describes the body this state was learned on (kind, program hint,
        sensors, action space)."""
        return (self.kind, self.program, tuple(self.sensors), self.action_space) == (
            spec.kind,
            spec.program,
            tuple(spec.sensors),
            spec.action_space,
        )


# encoding ----------------------------------------------------------------------------------------
def _flatten(value: Any, path: str, arrays: dict[str, np.ndarray]) -> Any:
    """`value` as JSON-ready plain data, its arrays moved into `arrays` under their dotted path."""
    if isinstance(value, np.ndarray):
        if value.dtype.hasobject:
            raise ValueError(f"{path}: object arrays cannot be saved without pickle")
        arrays[path] = value
        return {ARRAY_MARK: path}
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str) or not k or "." in k or k.startswith("__"):
                raise ValueError(f"{path}: state keys must be non-empty str without '.' or a leading '__', got {k!r}")
            out[k] = _flatten(v, f"{path}.{k}", arrays)
        return out
    if isinstance(value, (list, tuple)):
        return [_flatten(v, f"{path}.{i}", arrays) for i, v in enumerate(value)]
    if isinstance(value, np.generic):
        return _flatten(value.item(), path, arrays)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise ValueError(f"{path}: {type(value).__name__} is not an array or plain value")


def encode_checkpoint(ckpt: Checkpoint) -> bytes:
    """The file's bytes (see the module docstring). Raises ValueError on state that is not arrays
    and plain values."""
    arrays: dict[str, np.ndarray] = {}
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "world_id": ckpt.world_id,
        "kind": ckpt.kind,
        "program": ckpt.program,
        "sensors": [
            {
                "name": s.name,
                "dtype": s.dtype,
                "shape": list(s.shape),
                "low": s.low,
                "high": s.high,
                "description": s.description,
            }
            for s in ckpt.sensors
        ],
        "action_space": {
            "n": ckpt.action_space.n,
            "low": list(ckpt.action_space.low),
            "high": list(ckpt.action_space.high),
            "names": list(ckpt.action_space.names),
        },
        "version": ckpt.version,
        "program_class": ckpt.program_class,
        "program_params": _flatten(ckpt.program_params, "program_params", arrays),
        "program_state": _flatten(ckpt.program_state, "program_state", arrays),
        "detector_state": _flatten(ckpt.detector_state, "detector_state", arrays),
        "saved_at": float(ckpt.saved_at),
        "steps": int(ckpt.steps),
        "owner": ckpt.owner,
        "epoch": int(ckpt.epoch),
    }
    text = json.dumps(meta, allow_nan=True, separators=(",", ":")).encode("utf-8")
    buf = io.BytesIO()
    # numpy's stub types **kwds against `allow_pickle: bool` too; entry names here are dotted state
    # paths and META_ENTRY, never "allow_pickle"
    np.savez(buf, **{META_ENTRY: np.frombuffer(text, dtype=np.uint8)}, **arrays)  # type: ignore[arg-type]
    return buf.getvalue()


def write_atomically(path: str, data: bytes) -> None:
    """Replace `path` by `data` so that a crash leaves either the old file or the new one.

    A write that fails (a full disk: ENOSPC from write, flush, fsync or close) raises its OSError
    with `path` untouched and the temporary file removed, so it does not hold on to the space.
    """
    tmp = f"{path}.tmp"
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    try:  # make the rename itself durable
        fd = os.open(os.path.dirname(os.path.abspath(path)), os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def set_aside_checkpoint(path: str, why: str) -> str:
    """Rename a checkpoint that will not be used to PATH.<why>-<UTC time> (so the next checkpoint
    does not overwrite it and a person can still look at it); returns the new path."""
    aside = f"{path}.{why}-{datetime.now(UTC).strftime('%Y%m%dT%H%M%S.%fZ')}"
    os.replace(path, aside)
    return aside


def write_checkpoint(path: str, ckpt: Checkpoint) -> None:
    """Write `ckpt` to `path` atomically (a crash leaves the old file or the new one).

    Parameters
    ----------
    path : str
        Destination, conventionally `<state_dir>/<world>.ckpt.npz`.
    ckpt : Checkpoint
        What to save; its states must be arrays and plain values.

    Raises
    ------
    ValueError
        If a state holds something other than arrays and plain values.
    OSError
        If the file cannot be written.

    Examples
    --------
    ::

        write_checkpoint("w1.ckpt.npz", ckpt)
        assert read_checkpoint("w1.ckpt.npz").program_class == ckpt.program_class
    """
    write_atomically(path, encode_checkpoint(ckpt))


# decoding ----------------------------------------------------------------------------------------
def _unflatten(value: Any, arrays: dict[str, np.ndarray]) -> Any:
    if isinstance(value, dict):
        if set(value) == {ARRAY_MARK}:
            try:
                return arrays[value[ARRAY_MARK]]
            except (KeyError, TypeError):
                raise CheckpointError(f"the array {value[ARRAY_MARK]!r} is missing") from None
        return {k: _unflatten(v, arrays) for k, v in value.items()}
    if isinstance(value, list):
        return [_unflatten(v, arrays) for v in value]
    return value


def _require(meta: dict, key: str, kind: type | tuple[type, ...]) -> Any:
    if key not in meta:
        raise CheckpointError(f"the entry {key!r} is missing")
    value = meta[key]
    if not isinstance(value, kind) or (isinstance(value, bool) and kind is int):
        raise CheckpointError(f"the entry {key!r} has the wrong type ({type(value).__name__})")
    return value


def _check_sizes(data: bytes) -> None:
    """Refuse, before anything is inflated, a file over MAX_CHECKPOINT_BYTES or whose zip entries
    declare more than MAX_INFLATED_BYTES (a small file that inflates to hundreds of MB)."""
    if len(data) > MAX_CHECKPOINT_BYTES:
        raise CheckpointError(f"too large: {len(data)} bytes, at most {MAX_CHECKPOINT_BYTES}")
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            infos = z.infolist()
    except Exception as e:  # noqa: BLE001 - BadZipFile, NotImplementedError (unknown zip versions), ...
        raise CheckpointError(f"unreadable (truncated or corrupt?): {type(e).__name__}: {e}") from None
    declared = sum(i.file_size for i in infos)
    if declared > MAX_INFLATED_BYTES:
        raise CheckpointError(f"its entries would inflate to {declared} bytes, at most {MAX_INFLATED_BYTES}")


def check_values(ckpt: Checkpoint, now: float | None = None) -> None:
    """Refuse a checkpoint that parses but whose values cannot be right: a world id that is not an
    id, counters out of range (the embedding version and epoch beyond what the wire carries, see
    `protocol.limits`), non-finite arrays, a time in the future (beyond MAX_CLOCK_SKEW)."""
    try:
        check_id(ckpt.world_id, "world id")
    except ValueError as e:
        raise CheckpointError(str(e)) from None
    if not 0 <= ckpt.version <= MAX_VERSION:
        raise CheckpointError(
            f"its version {ckpt.version} is out of range (0 .. {MAX_VERSION}: the next version must fit the "
            "wire's uint32 embedding version)"
        )
    if not 0 <= ckpt.steps < MAX_COUNTER:
        raise CheckpointError(f"its steps {ckpt.steps} is out of range (0 .. 2**53)")
    if not 0 <= ckpt.epoch <= EPOCH_MAX:
        raise CheckpointError(
            f"its epoch {ckpt.epoch} is out of range (0 .. {EPOCH_MAX}: the wire's uint64 lease epoch)"
        )
    now = time.time() if now is None else now
    if not (math.isfinite(ckpt.saved_at) and 0 <= ckpt.saved_at <= now + MAX_CLOCK_SKEW):
        raise CheckpointError(f"it is dated {ckpt.saved_at!r}: not a time up to now (+{MAX_CLOCK_SKEW:g} s)")
    for path, a in _arrays(
        {"program_params": ckpt.program_params, "program_state": ckpt.program_state, "detector": ckpt.detector_state}
    ):
        if a.dtype.kind in "fc" and not np.isfinite(a).all():
            raise CheckpointError(f"the array {path} holds NaN or infinite values")


def check_shapes(saved: Any, fresh: Any, path: str = "program_state") -> None:
    """Refuse a saved state whose arrays do not fit the program it would be restored into.

    `fresh` is the `state()` of a program (or detector) just built for the world's spec with the
    checkpoint's params: every array it holds with at least one element has a shape fixed by that
    spec and those params (weights, tables, filters), and the saved array at the same path must
    have that shape and the same kind of dtype (float, int, bool). Arrays the fresh state holds
    empty grow while learning (sample buffers) and are not compared, nor values the fresh state
    holds as anything but an array. CheckpointError names the first array that does not fit."""
    if isinstance(fresh, np.ndarray):
        if fresh.size == 0:
            return
        if not isinstance(saved, np.ndarray):
            raise CheckpointError(f"{path} is {type(saved).__name__}, the program keeps an array {list(fresh.shape)}")
        if saved.shape != fresh.shape:
            raise CheckpointError(
                f"the array {path} has shape {list(saved.shape)}, the program keeps {list(fresh.shape)} for this world"
            )
        if saved.dtype.kind != fresh.dtype.kind and {saved.dtype.kind, fresh.dtype.kind} != {"i", "u"}:
            raise CheckpointError(f"the array {path} is {saved.dtype.name}, the program keeps {fresh.dtype.name}")
        return
    if isinstance(fresh, dict) and isinstance(saved, dict):
        for k, v in fresh.items():
            if k in saved:
                check_shapes(saved[k], v, f"{path}.{k}")
    elif isinstance(fresh, list) and isinstance(saved, list) and len(fresh) == len(saved):
        for i, (a, b) in enumerate(zip(saved, fresh, strict=True)):
            check_shapes(a, b, f"{path}.{i}")


def _arrays(value: Any, path: str = "") -> list[tuple[str, np.ndarray]]:
    if isinstance(value, np.ndarray):
        return [(path, value)]
    if isinstance(value, dict):
        return [x for k, v in value.items() for x in _arrays(v, f"{path}.{k}" if path else str(k))]
    if isinstance(value, list):
        return [x for i, v in enumerate(value) for x in _arrays(v, f"{path}.{i}")]
    return []


def decode_checkpoint(data: bytes, now: float | None = None) -> Checkpoint:
    """Parse a checkpoint file's bytes and check its values (`check_values`, with `now` as the
    current time); CheckpointError says what is wrong with anything else."""
    if data[:2] != b"PK":
        hint = " (a pickle? those are never loaded)" if data[:1] == b"\x80" else ""
        raise CheckpointError(f"not a checkpoint: not an npz (zip) file{hint}")
    _check_sizes(data)
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            if META_ENTRY not in npz.files:
                raise CheckpointError(f"not a sensorimotor checkpoint: no {META_ENTRY} entry")
            arrays = {name: npz[name] for name in npz.files}
    except CheckpointError:
        raise
    except Exception as e:  # zipfile, npy header, pickled entries, truncation: all unreadable
        raise CheckpointError(f"unreadable (truncated or corrupt?): {type(e).__name__}: {e}") from None
    raw = arrays.pop(META_ENTRY)
    try:
        if raw.dtype != np.uint8 or raw.ndim != 1:
            raise ValueError(f"{META_ENTRY} is {raw.dtype}{list(raw.shape)}, not bytes")
        meta = json.loads(raw.tobytes().decode("utf-8"))
    except (ValueError, UnicodeDecodeError, RecursionError) as e:  # RecursionError: hostile nesting
        raise CheckpointError(f"its {META_ENTRY} entry is not valid JSON: {type(e).__name__}: {e}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise CheckpointError(
            f"not a sensorimotor checkpoint (format {meta.get('format') if isinstance(meta, dict) else None!r})"
        )
    version = meta.get("format_version")
    if version != FORMAT_VERSION:
        if isinstance(version, int) and not isinstance(version, bool) and version > FORMAT_VERSION:
            why = "written by a newer sensorimotor"
        else:
            why = "an old or unknown format this version cannot read"
        raise CheckpointError(f"format version {version!r} is not {FORMAT_VERSION}: {why}")
    try:
        sensors = tuple(
            SensorSpec(
                name=s["name"],
                dtype=s["dtype"],
                shape=tuple(s["shape"]),
                low=s["low"],
                high=s["high"],
                description=s["description"],
            )
            for s in _require(meta, "sensors", list)
        )
        a = _require(meta, "action_space", dict)
        action_space = ActionSpace(n=a["n"], low=tuple(a["low"]), high=tuple(a["high"]), names=tuple(a["names"]))
    except (KeyError, TypeError) as e:
        raise CheckpointError(f"the world body entries are malformed: {type(e).__name__}: {e}") from None
    detector = meta.get("detector_state")
    if detector is not None and not isinstance(detector, dict):
        raise CheckpointError("the entry 'detector_state' has the wrong type")
    try:
        ckpt = _checkpoint(meta, sensors, action_space, detector, arrays)
        check_values(ckpt, now)
    except RecursionError:  # JSON nested just under json's limit, deeper than the stack left here
        raise CheckpointError("the state entries are nested too deeply") from None
    return ckpt


def _checkpoint(
    meta: dict, sensors: tuple[SensorSpec, ...], action_space: ActionSpace, detector: Any, arrays: dict[str, np.ndarray]
) -> Checkpoint:
    return Checkpoint(
        world_id=_require(meta, "world_id", str),
        kind=_require(meta, "kind", str),
        program=_require(meta, "program", str),
        sensors=sensors,
        action_space=action_space,
        version=_require(meta, "version", int),
        program_class=_require(meta, "program_class", str),
        program_params=_unflatten(_require(meta, "program_params", dict), arrays),
        program_state=_unflatten(_require(meta, "program_state", dict), arrays),
        detector_state=None if detector is None else _unflatten(detector, arrays),
        saved_at=_optional_number(meta, "saved_at", float),
        steps=int(_optional_number(meta, "steps", int)),
        owner=_optional_str(meta, "owner"),
        epoch=int(_optional_number(meta, "epoch", int)),
    )


def _optional_str(meta: dict, key: str) -> str:
    """An optional text entry ("" when absent: files written before it existed)."""
    value = meta.get(key, "")
    if not isinstance(value, str) or len(value) > 64:
        raise CheckpointError(f"the entry {key!r} has the wrong type or is over 64 characters")
    return value


def _optional_number(meta: dict, key: str, kind: type) -> float:
    """An optional numeric entry (0 when absent: files written before it existed)."""
    value = meta.get(key, 0)
    if isinstance(value, bool) or not isinstance(value, int | float) or (kind is int and not isinstance(value, int)):
        raise CheckpointError(f"the entry {key!r} has the wrong type")
    return float(value) if kind is float else value


def read_checkpoint(path: str) -> Checkpoint:
    """Load the checkpoint at `path`; no pickle is ever loaded.

    Parameters
    ----------
    path : str
        A file written by `write_checkpoint`.

    Returns
    -------
    Checkpoint
        The saved body, version, program class, params and state, and detector state.

    Raises
    ------
    CheckpointError
        If the file cannot be read or is not a checkpoint this version can read.
    """
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if size > MAX_CHECKPOINT_BYTES:
                raise CheckpointError(f"too large: {size} bytes, at most {MAX_CHECKPOINT_BYTES}")
            data = f.read()
    except OSError as e:
        raise CheckpointError(f"cannot read: {e}") from None
    return decode_checkpoint(data)
