"""ROS 2 messages as CDR bytes, without ROS: `rosbags`' type stores per distribution, RIHS01 type
hashes, message definitions (the ``ros2msg`` schema text of MCAP), numeric field paths, and images
as arrays. Serialised bytes start with the 4-byte encapsulation header ``00 01 00 00`` (CDR, little
endian), as rmw_zenoh sends them."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any, TypeAlias

import numpy as np
from rosbags.typesys import Stores, get_typestore

from sensorimotor.worlds.ros2.names import HASH_NOT_SUPPORTED

Numbers: TypeAlias = Sequence[float] | np.ndarray

#: the ROS 2 distributions whose rmw_zenoh releases we speak, and rosbags' type store for each
DISTROS = {
    "humble": Stores.ROS2_HUMBLE,
    "jazzy": Stores.ROS2_JAZZY,
    "kilted": Stores.ROS2_KILTED,
    "rolling": Stores.LATEST,
}
_NUMERIC = {"bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64"}
_NUMERIC |= {"float32", "float64"}
_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4  # rosbags' Nodetype values

#: image encodings we read, with their channels and numpy dtype
IMAGE_ENCODINGS = {
    "mono8": (1, np.uint8),
    "8UC1": (1, np.uint8),
    "rgb8": (3, np.uint8),
    "bgr8": (3, np.uint8),
    "rgba8": (4, np.uint8),
    "bgra8": (4, np.uint8),
    "mono16": (1, np.uint16),
    "32FC1": (1, np.float32),
}
_LUMA = np.array([0.2125, 0.7154, 0.0721], dtype=np.float32)  # the arm world's grey weights


class FieldPathError(ValueError):
    """A field path that the message type does not have; the message names the fields it does."""


def check_distro(distro: str) -> str:
    """`distro` if we know it; a ValueError naming the known ones otherwise."""
    if distro not in DISTROS:
        raise ValueError(f"ROS 2 distribution {distro!r}; valid: {', '.join(DISTROS)}")
    return distro


@cache
def _store(distro: str) -> Any:
    return get_typestore(DISTROS[check_distro(distro)])


@dataclass(frozen=True)
class Codec:
    """CDR (de)serialisation, type hashes and definitions of one distribution's message types."""

    distro: str = "jazzy"

    @property
    def store(self) -> Any:
        """rosbags' type store."""
        return _store(self.distro)

    def known(self, ros_type: str) -> bool:
        """Whether the type store has `ros_type` (``pkg/msg/Name``)."""
        return ros_type in self.store.types

    def type_hash(self, ros_type: str) -> str:
        """The type hash rmw_zenoh writes in keys and tokens: RIHS01_<sha256 hex>, or Humble's
        ``TypeHashNotSupported``."""
        if self.distro == "humble":
            return HASH_NOT_SUPPORTED
        return str(self.store.hash_rihs01(ros_type))

    def msgdef(self, ros_type: str) -> str:
        """The concatenated message definition (the ``ros2msg`` schema text rosbag2 writes)."""
        return str(self.store.generate_msgdef(ros_type, ros_version=2)[0])

    def new(self, ros_type: str, **fields: Any) -> Any:
        """A message object of `ros_type`."""
        return self.store.types[ros_type](**fields)

    def serialize(self, msg: Any, ros_type: str) -> bytes:
        """CDR bytes (with the encapsulation header)."""
        return bytes(self.store.serialize_cdr(msg, ros_type))

    def deserialize(self, data: bytes, ros_type: str) -> Any:
        """The message of CDR bytes (with the encapsulation header)."""
        return self.store.deserialize_cdr(data, ros_type)

    # building the messages our worlds send --------------------------------------------------------
    def header(self, stamp_ns: int | None = None, frame_id: str = "") -> Any:
        """A std_msgs/Header stamped `stamp_ns` (now when None)."""
        ns = time.time_ns() if stamp_ns is None else stamp_ns
        t = self.new("builtin_interfaces/msg/Time", sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        return self.new("std_msgs/msg/Header", stamp=t, frame_id=frame_id)

    def joint_state(
        self,
        names: Sequence[str],
        position: Numbers = (),
        velocity: Numbers = (),
        stamp_ns: int | None = None,
    ) -> Any:
        """A sensor_msgs/JointState."""
        f64 = np.float64
        return self.new(
            "sensor_msgs/msg/JointState",
            header=self.header(stamp_ns),
            name=list(names),
            position=np.asarray(position, dtype=f64),
            velocity=np.asarray(velocity, dtype=f64),
            effort=np.zeros(0, dtype=f64),
        )

    def image(self, pixels: np.ndarray, encoding: str, stamp_ns: int | None = None, frame_id: str = "camera") -> Any:
        """A sensor_msgs/Image of `pixels` ([H, W] or [H, W, C], the dtype `encoding` declares)."""
        ch, dtype = IMAGE_ENCODINGS[encoding]
        px = np.ascontiguousarray(pixels, dtype=dtype)
        h, w = px.shape[:2]
        return self.new(
            "sensor_msgs/msg/Image",
            header=self.header(stamp_ns, frame_id),
            height=h,
            width=w,
            encoding=encoding,
            is_bigendian=0,
            step=w * ch * px.dtype.itemsize,
            data=px.reshape(-1).view(np.uint8),
        )

    def float64_multi_array(self, values: Numbers, labels: Sequence[tuple[str, int, int]] = ()) -> Any:
        """A std_msgs/Float64MultiArray; `labels` are its layout's (label, size, stride) dimensions."""
        dims = [self.new("std_msgs/msg/MultiArrayDimension", label=lb, size=s, stride=st) for lb, s, st in labels]
        layout = self.new("std_msgs/msg/MultiArrayLayout", dim=dims, data_offset=0)
        return self.new("std_msgs/msg/Float64MultiArray", layout=layout, data=np.asarray(values, dtype=np.float64))

    def twist(self, linear: Numbers, angular: Numbers) -> Any:
        """A geometry_msgs/Twist."""
        v3 = "geometry_msgs/msg/Vector3"
        return self.new(
            "geometry_msgs/msg/Twist",
            linear=self.new(v3, x=float(linear[0]), y=float(linear[1]), z=float(linear[2])),
            angular=self.new(v3, x=float(angular[0]), y=float(angular[1]), z=float(angular[2])),
        )

    # reading numbers out of messages ----------------------------------------------------------------
    def numeric_paths(self, ros_type: str, prefix: str = "") -> list[str]:
        """Every numeric field path of `ros_type` (``linear.x``, ``position``...), for error messages."""
        out = []
        for name, (node, arg) in self.store.fielddefs[ros_type][1]:
            path = f"{prefix}{name}"
            if node == _NAME:
                out += self.numeric_paths(arg, path + ".")
            elif node == _BASE and arg[0] in _NUMERIC:
                out.append(path)
            elif node in (_ARRAY, _SEQUENCE) and arg[0][0] == _BASE and arg[0][1][0] in _NUMERIC:
                out.append(path)
        return out

    def check_path(self, ros_type: str, path: str) -> None:
        """Raise a FieldPathError unless `path` names a numeric field (or numeric array) of `ros_type`."""
        if path not in self.numeric_paths(ros_type):
            valid = ", ".join(self.numeric_paths(ros_type)) or "(none)"
            raise FieldPathError(f"{ros_type} has no numeric field {path!r}; valid: {valid}")


def read_path(msg: Any, path: str) -> np.ndarray:
    """The numbers at a checked field path of a message, as a float64 vector."""
    v = msg
    for part in path.split("."):
        v = getattr(v, part)
    return np.atleast_1d(np.asarray(v, dtype=np.float64)).reshape(-1)


def image_array(msg: Any, grey: bool = True) -> np.ndarray:
    """A sensor_msgs/Image as float32 in [0, 1] (32FC1 as it is): [H, W] grey (RGB by the arm
    world's weights), or [H, W, C] with `grey` False. A ValueError names the encodings we read."""
    enc = str(msg.encoding)
    if enc not in IMAGE_ENCODINGS:
        raise ValueError(f"image encoding {enc!r}; readable: {', '.join(IMAGE_ENCODINGS)}")
    ch, dtype = IMAGE_ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    raw = np.asarray(msg.data, dtype=np.uint8)
    row = w * ch * np.dtype(dtype).itemsize
    if step < row or raw.size < h * step:
        raise ValueError(f"image {w}x{h} {enc}: step {step}, data {raw.size} bytes (need {h * row})")
    rows = raw[: h * step].reshape(h, step)[:, :row]
    px = np.ascontiguousarray(rows).view(dtype).reshape(h, w, ch)
    scale = {np.uint8: 255.0, np.uint16: 65535.0, np.float32: 1.0}[dtype]
    img = px.astype(np.float32) / np.float32(scale)
    if enc in ("bgr8", "bgra8"):
        img[..., :3] = img[..., 2::-1]
    if not grey:
        return img
    if ch == 1:
        return img[..., 0]
    return img[..., :3] @ _LUMA
