"""Odometry read straight from its bytes equals Odometry deserialised by rosbags, field for field."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from redrive.errors import UnsupportedMessageError
from redrive.io.base import LogMessage
from redrive.io.ros.decoders import OdometryDecoder
from redrive.io.ros.decoders.motion import _read_odometry, _state
from tests.io._decoder_helpers import deserializer, header, log_message

DESERIALIZE = deserializer()
_FLOATS = st.floats(allow_nan=False, allow_infinity=False, width=64, min_value=-1e6, max_value=1e6)


def _by_deserialising(message: LogMessage) -> Any:
    msg: Any = DESERIALIZE(message)
    return _state(message, msg, pose=msg.pose.pose, twist=msg.twist.twist, twist_in_body=True)


def _odometry(
    ros_version: int, *, little_endian: bool, stamp_ns: int, frame: str, child: str, v: list[float]
) -> LogMessage:
    q = v[3:7] if any(v[3:7]) else [0.0, 0.0, 0.0, 0.0]
    return log_message(
        ros_version,  # type: ignore[arg-type]
        "nav_msgs/msg/Odometry",
        little_endian=little_endian,
        header=header(ros_version, stamp_ns, frame),  # type: ignore[arg-type]
        child_frame_id=child,
        pose={
            "pose": {
                "position": dict(zip("xyz", v[0:3], strict=True)),
                "orientation": dict(zip("xyzw", q, strict=True)),
            },
            "covariance": np.full(36, 0.5),
        },
        twist={
            "twist": {
                "linear": dict(zip("xyz", v[7:10], strict=True)),
                "angular": dict(zip("xyz", v[10:13], strict=True)),
            },
            "covariance": np.full(36, -0.5),
        },
    )


@settings(max_examples=150, deadline=None)
@given(
    wire=st.tuples(st.sampled_from([1, 2]), st.booleans()),  # ROS version, little endian
    stamp_ns=st.sampled_from([0, 1, 1_650_000_000_250_000_000]),
    names=st.tuples(st.text(max_size=9), st.text(max_size=9)),
    v=st.lists(_FLOATS, min_size=13, max_size=13),
    q=st.sampled_from([[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], [0.1, -0.2, 0.7, 0.6]]),
)
def test_bytes_equal_deserialisation(
    wire: tuple[int, bool], stamp_ns: int, names: tuple[str, str], v: list[float], q: list[float]
) -> None:
    ros_version, little_endian = wire
    v[3:7] = [qi * (1.0 + abs(v[3])) for qi in q]  # a zero or a usable (unnormalised) quaternion
    frame, child = names
    message = _odometry(
        ros_version, little_endian=little_endian, stamp_ns=stamp_ns, frame=frame, child=child, v=v
    )
    assert _read_odometry(message) is not None  # the byte reader takes it
    got = OdometryDecoder().decode(message, lambda m: pytest.fail("deserialised"))
    want = _by_deserialising(message)
    assert (got.stamp_ns, got.frame_id) == (want.stamp_ns, want.frame_id)
    for name in ("stamp_ns", "frame_id", "heading_rad", "yaw_rate_rad_s"):
        assert getattr(got.value, name) == getattr(want.value, name), name
    for name in ("position", "velocity", "acceleration"):
        np.testing.assert_array_equal(getattr(got.value, name), getattr(want.value, name))


def test_unusual_bytes_are_deserialised_and_bad_values_refused() -> None:
    good = _odometry(2, little_endian=True, stamp_ns=5, frame="odom", child="b", v=[1.0] * 13)
    padded = LogMessage(
        topic="/o", msgtype=good.msgtype, log_time_ns=9, encoding="cdr", raw=bytes(good.raw) + b"\0"
    )
    assert _read_odometry(padded) is None
    seen: list[LogMessage] = []

    def deserialize(message: LogMessage) -> object:
        seen.append(message)
        return DESERIALIZE(good)

    state = OdometryDecoder().decode(padded, deserialize).value
    assert seen == [padded]
    np.testing.assert_array_equal(state.position, [1.0, 1.0, 1.0])
    nan = _odometry(
        1, little_endian=True, stamp_ns=5, frame="odom", child="b", v=[float("nan")] * 13
    )
    with pytest.raises(UnsupportedMessageError, match="not finite"):
        OdometryDecoder().decode(nan, DESERIALIZE)


def test_pending_state_checks_now_and_builds_later() -> None:
    decoder = OdometryDecoder()
    v = [1.0, 2.0, 3.0, 0.0, 0.0, 0.6, 0.8, 4.0, 0.0, 0.0, 0.0, 0.0, 0.1]
    message = _odometry(2, little_endian=True, stamp_ns=7, frame="odom", child="b", v=v)
    pending = decoder.read_pending(message)
    assert pending is not None
    assert pending.stamp_ns == 7
    assert pending.value is pending.value  # built once
    np.testing.assert_array_equal(pending.value.position, _by_deserialising(message).value.position)
    nan = _odometry(2, little_endian=True, stamp_ns=7, frame="o", child="b", v=[float("nan")] * 13)
    with pytest.raises(UnsupportedMessageError, match="not finite"):
        decoder.read_pending(nan)
    tiny = [*v[:3], 1e-13, 0.0, 0.0, 0.0, *v[7:]]  # refused by quaternion_normalized: raised now
    with pytest.raises(ValueError, match="not a usable quaternion"):
        decoder.read_pending(
            _odometry(2, little_endian=True, stamp_ns=7, frame="o", child="b", v=tiny)
        )
