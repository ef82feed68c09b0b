"""GroundTruthObjectArray read straight from its bytes equals it deserialised by rosbags."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from redrive.errors import UnsupportedMessageError
from redrive.io.base import LogMessage
from redrive.io.ros.decoders import GroundTruthObjectArrayDecoder
from redrive.io.ros.decoders import objects as objects_module
from redrive.io.ros.decoders._gt_bytes import read_ground_truth
from tests.io._decoder_helpers import deserializer, header, log_message

DESERIALIZE = deserializer()
_TYPE = "redrive_msgs/msg/GroundTruthObjectArray"
_FLOATS = st.floats(allow_nan=False, allow_infinity=False, width=64, min_value=-1e4, max_value=1e4)
_NAMES = st.sampled_from(["vehicle", "pedestrian", "Truck", "", "ünïcode", "7"])


def _detection(values: dict[str, Any]) -> dict[str, Any]:
    p, q, s = values["position"], values["orientation"], values["size"]
    return {
        "header": header(2, 3, values["frame"]),
        "results": [
            {"hypothesis": {"class_id": name, "score": score}, "pose": {"covariance": np.ones(36)}}
            for name, score in values["results"]
        ],
        "bbox": {
            "center": {
                "position": dict(zip("xyz", p, strict=True)),
                "orientation": dict(zip("xyzw", q, strict=True)),
            },
            "size": dict(zip("xyz", s, strict=True)),
        },
        "id": values["id"],
    }


_OBJECT = st.fixed_dictionaries(
    {
        "frame": st.text(max_size=4),
        "results": st.lists(st.tuples(_NAMES, _FLOATS), max_size=3),
        "position": st.tuples(_FLOATS, _FLOATS, _FLOATS),
        "orientation": st.sampled_from([(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.3, 0.9), (1, 2, 3, 4)]),
        "size": st.tuples(_FLOATS, _FLOATS, _FLOATS),
        "id": st.sampled_from(["", "12", "car-3", "ß"]),
        "velocity": st.tuples(_FLOATS, _FLOATS, _FLOATS),
        "points": st.integers(-1, 2**31 - 1),
        "visible": st.sampled_from([-1, 0, 1]),
    }
)


def _message(objects: list[dict[str, Any]], *, little_endian: bool, stamp_ns: int) -> LogMessage:
    return log_message(
        2,
        _TYPE,
        little_endian=little_endian,
        header=header(2, stamp_ns, "base_link"),
        detections=[_detection(o) for o in objects],
        velocities=[dict(zip("xyz", o["velocity"], strict=True)) for o in objects],
        num_lidar_points=[o["points"] for o in objects],
        visible=[o["visible"] for o in objects],
    )


def _flat(value: Any) -> Any:
    """Every field, arrays as (dtype, shape, bytes): equality without numpy's elementwise ==."""
    if dataclasses.is_dataclass(value):
        return tuple((f.name, _flat(getattr(value, f.name))) for f in dataclasses.fields(value))
    if isinstance(value, np.ndarray):
        return (value.dtype.str, value.shape, value.tobytes())
    if isinstance(value, tuple | list):
        return tuple(_flat(v) for v in value)
    return (type(value).__name__, value)


def _deserialised(message: LogMessage, monkeypatch: pytest.MonkeyPatch) -> Any:
    with monkeypatch.context() as patch:
        patch.setattr(objects_module, "read_ground_truth", lambda m: None)
        return GroundTruthObjectArrayDecoder().decode(message, DESERIALIZE)


@settings(max_examples=15, deadline=None)
@given(
    objects=st.lists(_OBJECT, max_size=3),
    little_endian=st.booleans(),
    stamp_ns=st.sampled_from([0, 1_650_000_000_250_000_000]),
)
def test_bytes_equal_deserialisation(
    objects: list[dict[str, Any]], little_endian: bool, stamp_ns: int
) -> None:
    message = _message(objects, little_endian=little_endian, stamp_ns=stamp_ns)
    assert read_ground_truth(message) is not None  # the byte reader takes it
    got = GroundTruthObjectArrayDecoder().decode(message, lambda m: pytest.fail("deserialised"))
    with pytest.MonkeyPatch.context() as patch:
        want = _deserialised(message, patch)
    assert _flat(got) == _flat(want)


def test_unusual_bytes_are_deserialised_and_broken_arrays_refused(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    one = {"frame": "", "results": [("car", 0.5)], "position": (1.0, 2.0, 3.0)}
    one |= {"orientation": (0.0, 0.0, 0.0, 1.0), "size": (4.0, 2.0, 1.5), "id": "5"}
    one |= {"velocity": (1.0, 0.0, 0.0), "points": 3, "visible": 1}
    good = _message([one], little_endian=True, stamp_ns=5)
    raw = bytes(good.raw)
    for bad in (raw + b"\x01", raw + bytes(4), raw[:-1], raw[:40]):
        odd = dataclasses.replace(good, raw=bad)
        assert read_ground_truth(odd) is None
    seen: list[LogMessage] = []
    odd = dataclasses.replace(good, raw=raw + b"\x01")

    def deserialize(message: LogMessage) -> object:
        seen.append(message)
        return DESERIALIZE(good)

    (obj,) = GroundTruthObjectArrayDecoder().decode(odd, deserialize).value
    assert seen == [odd]
    assert (obj.object_id, obj.num_lidar_points, obj.visible) == (5, 3, True)
    unparallel = log_message(
        2, _TYPE, header=header(2, 5, "base_link"), detections=[_detection(one)], visible=[1]
    )
    with pytest.raises(UnsupportedMessageError, match="1 detections but 0 velocities"):
        GroundTruthObjectArrayDecoder().decode(unparallel, DESERIALIZE)
    with pytest.raises(UnsupportedMessageError, match="1 detections but 0 velocities"):
        _deserialised(unparallel, monkeypatch)


def test_columns_equal_deserialisation_for_any_quaternion(monkeypatch: pytest.MonkeyPatch) -> None:
    """The byte path builds its objects as columns (its own Euler angles): bit-equal to the
    deserialised path's ``euler_from_quaternion`` for random, gimbal-locked and unnormalised
    quaternions; an unusable box is refused with the same error either way."""
    rng = np.random.default_rng(15)
    quats = [tuple(q) for q in rng.normal(size=(60, 4)).tolist()]
    h = 0.5**0.5
    quats += [
        (0.0, h, 0.0, h),
        (0.0, -h, 0.0, h),
        (0.1, 0.7, -0.1, 0.7),
        (0, 0, 0, 0),
        (0, 0, 0, 3),
    ]
    one = {"frame": "", "results": [("car", 0.5), ("truck", 0.9)], "id": "car-3"}
    one |= {"position": (1.0, 2.0, 3.0), "velocity": (1.0, 0.0, -2.0), "points": 3, "visible": 0}
    objects = [one | {"orientation": q, "size": (4.0, -2.0, 1.5)} for q in quats]
    message = _message(objects, little_endian=True, stamp_ns=5)
    got = GroundTruthObjectArrayDecoder().decode(message, lambda m: pytest.fail("deserialised"))
    assert _flat(got) == _flat(_deserialised(message, monkeypatch))
    assert got.value[-1].orientation.flags.writeable is False
    for bad in ({"orientation": (0.0, 0.0, 1e-13, 0.0)}, {"size": (1.0, float("inf"), 1.0)}):
        broken = _message([objects[0], objects[1] | bad], little_endian=True, stamp_ns=5)
        with pytest.raises(UnsupportedMessageError) as by_bytes:
            GroundTruthObjectArrayDecoder().decode(broken, lambda m: pytest.fail("deserialised"))
        with pytest.raises(UnsupportedMessageError) as by_rosbags:
            _deserialised(broken, monkeypatch)
        assert "object box is invalid" in str(by_bytes.value)
        assert str(by_bytes.value) == str(by_rosbags.value)
