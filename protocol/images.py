"""Camera frames as `foxglove.RawImage`, so that recordings open as images in Foxglove and Rerun."""

from __future__ import annotations

import numpy as np
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from google.protobuf.message import DecodeError

from sensorimotor.protocol import errors

SCHEMA = "foxglove.RawImage"


def encode_image(frame: np.ndarray, frame_id: str, timestamp: float) -> bytes:
    """Serialize a camera frame as a foxglove.RawImage.

    Parameters
    ----------
    frame : ndarray
        uint8 ``[H, W]`` (mono8) or ``[H, W, 3]`` (rgb8).
    frame_id : str
        The image's frame id (the world id).
    timestamp : float
        Seconds since the epoch.

    Returns
    -------
    bytes
        The serialized message.

    Raises
    ------
    ValueError
        If `frame` is not one of the two layouts.
    """
    a = np.ascontiguousarray(frame)
    if a.dtype != np.uint8 or a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] != 3):
        raise ValueError(f"frames are uint8 [H, W] or [H, W, 3], got {a.dtype}{list(a.shape)}")
    m = RawImage(
        width=a.shape[1],
        height=a.shape[0],
        encoding="mono8" if a.ndim == 2 else "rgb8",
        step=a.shape[1] * (1 if a.ndim == 2 else 3),
        data=a.tobytes(),
        frame_id=frame_id,
    )
    m.timestamp.FromNanoseconds(int(timestamp * 1e9))
    return m.SerializeToString()


def decode_image(payload: bytes | bytearray | memoryview) -> np.ndarray:
    """Serialized foxglove.RawImage (mono8 or rgb8) -> uint8 [H, W] or [H, W, 3].

    Raises a `ProtocolError` (a ValueError): `MalformedMessage` for bytes that are not a RawImage
    or an encoding other than mono8/rgb8, `ShapeMismatch` when the data is not height x width x
    channels bytes (or `step` disagrees with the width).
    """
    m = RawImage()
    try:
        m.ParseFromString(bytes(payload))
    except (DecodeError, RuntimeError, ValueError) as e:
        raise errors.MalformedMessage(f"RawImage: not a valid protobuf message ({e})") from None
    ch = {"mono8": 1, "rgb8": 3}.get(m.encoding)
    if ch is None:
        raise errors.MalformedMessage(f"unsupported image encoding {m.encoding!r}")
    if m.height * m.width * ch != len(m.data) or (m.height and m.step != m.width * ch):
        raise errors.ShapeMismatch(
            f"image data ({len(m.data)} bytes, step {m.step}) does not match {m.width} x {m.height} x {ch}"
        )
    a = np.frombuffer(m.data, dtype=np.uint8)
    return a.reshape((m.height, m.width) if ch == 1 else (m.height, m.width, 3))
