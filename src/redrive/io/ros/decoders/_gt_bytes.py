"""``redrive_msgs/msg/GroundTruthObjectArray`` read straight from its CDR bytes.

What ``redrive synth`` writes as ground truth, once per LiDAR sweep: deserialising it builds a
message object per detection, hypothesis and pose, and a 36-element covariance array per
hypothesis that nothing reads.  This reader takes the values the decoder uses (header, each
detection's hypotheses, box and id, the parallel velocities, point counts and visible flags) in
one pass over the bytes.  It returns None for anything that is not exactly the layout of
``src/redrive/io/ros/msgs`` (another encoding, a string that is not UTF-8, bytes left over or
missing), and the caller deserialises the message as before; both give the same values.
"""

from __future__ import annotations

import struct
from typing import NamedTuple

from redrive.io.base import LogMessage

__all__ = ["GroundTruthBytes", "ObjectBytes", "read_ground_truth"]


class ObjectBytes(NamedTuple):
    """One detection's fields as the decoder uses them (float64s as Python floats)."""

    results: tuple[tuple[str, float], ...]  # (class_id, score) per hypothesis
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]
    size: tuple[float, float, float]
    raw_id: str


class GroundTruthBytes(NamedTuple):
    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    objects: tuple[ObjectBytes, ...]
    velocities: tuple[tuple[float, float, float], ...]
    num_lidar_points: tuple[int, ...]
    visible: tuple[int, ...]


_ORDER = {0: ">", 1: "<"}  # CDR representation identifier byte 1: 0 big, 1 little endian
_STRUCTS = {
    order: (
        struct.Struct(f"{order}iI"),  # stamp
        struct.Struct(f"{order}I"),  # lengths
        struct.Struct(f"{order}d"),  # score
        struct.Struct(f"{order}3d"),  # vector3
        struct.Struct(f"{order}10d"),  # bbox: pose (7) + size (3)
    )
    for order in ("<", ">")
}
_HYPOTHESIS_POSE = (7 + 36) * 8  # PoseWithCovariance: pose and covariance, skipped


def read_ground_truth(message: LogMessage) -> GroundTruthBytes | None:
    """The fields of a CDR GroundTruthObjectArray, or None when the bytes are not its plain
    layout (see the module text)."""
    if message.encoding != "cdr":
        return None
    buf = message.raw
    try:
        return _read(buf)
    except (struct.error, IndexError, UnicodeDecodeError, ValueError):
        return None


def _read(buf: memoryview | bytes) -> GroundTruthBytes | None:
    if len(buf) < 4 or buf[0] != 0 or buf[1] not in _ORDER:
        return None
    stamp, u32, f64, vec3, bbox = _STRUCTS[_ORDER[buf[1]]]
    end = len(buf)
    pos = 4  # CDR alignment counts from here

    def align(at: int, to: int) -> int:
        return at + (-(at - 4) % to)

    def string(at: int) -> tuple[str, int]:
        at = align(at, 4)
        (size,) = u32.unpack_from(buf, at)
        at += 4
        if size == 0 or at + size > end or buf[at + size - 1] != 0:
            raise ValueError("not a CDR string")
        return str(buf[at : at + size - 1], "utf-8"), at + size

    def count(at: int) -> tuple[int, int]:
        at = align(at, 4)
        (n,) = u32.unpack_from(buf, at)
        if n > end:
            raise ValueError("a sequence longer than the message")
        return n, at + 4

    sec, nanosec = stamp.unpack_from(buf, pos)
    frame_id, pos = string(pos + 8)
    n, pos = count(pos)
    objects = []
    for _ in range(n):
        pos = align(pos, 4) + 8  # the detection's own header: stamp ...
        _, pos = string(pos)  # ... and frame id, not used
        k, pos = count(pos)
        results = []
        for _ in range(k):
            class_id, pos = string(pos)
            pos = align(pos, 8)
            (score,) = f64.unpack_from(buf, pos)
            pos += 8 + _HYPOTHESIS_POSE
            results.append((class_id, score))
        pos = align(pos, 8)
        v = bbox.unpack_from(buf, pos)
        raw_id, pos = string(pos + bbox.size)
        objects.append(
            ObjectBytes(
                tuple(results),
                (v[0], v[1], v[2]),
                (v[3], v[4], v[5], v[6]),
                (v[7], v[8], v[9]),
                raw_id,
            )
        )
    n, pos = count(pos)
    velocities = []
    if n:
        pos = align(pos, 8)
    for _ in range(n):
        velocities.append(vec3.unpack_from(buf, pos))
        pos += vec3.size
    n, pos = count(pos)
    points = struct.unpack_from(f"{'<' if buf[1] else '>'}{n}i", buf, pos)
    pos += 4 * n
    n, pos = count(pos)
    visible = struct.unpack_from(f"{n}b", buf, pos)
    pos += n
    if pos > end or end - pos >= 4:  # CDR pads the end to 4 at most
        return None
    if any(buf[pos:end]):
        return None
    return GroundTruthBytes(
        sec, nanosec, frame_id, tuple(objects), tuple(velocities), points, visible
    )
