"""The indexed ROS 1 reader's per-message header walk agrees with the full record-header parse."""

from __future__ import annotations

import struct

from hypothesis import given, settings
from hypothesis import strategies as st

from redrive.io.rosbag1.records import DamageError, op_of, parse_header, record_op


def _field(key: bytes, value: bytes) -> bytes:
    body = key + b"=" + value
    return struct.pack("<I", len(body)) + body


_FIELDS = st.one_of(
    st.builds(
        _field, st.just(b"op"), st.sampled_from([b"\x02", b"\x07", b"\x05", b"", b"\x02\x02"])
    ),
    st.builds(_field, st.just(b"conn"), st.binary(min_size=4, max_size=4)),
    st.builds(_field, st.just(b"time"), st.binary(min_size=8, max_size=8)),
    st.builds(_field, st.sampled_from([b"o", b"opx", b"xop", b"topic"]), st.binary(max_size=6)),
    # no '=' at all, or a length that runs past the header
    st.binary(min_size=4, max_size=4).map(lambda b: struct.pack("<I", 4) + b.replace(b"=", b"-")),
    st.binary(min_size=0, max_size=3),
)


def _full(buf: bytes, end: int) -> tuple[str, int, int]:
    try:
        fields, stop = parse_header(buf, 0, end)
        return ("ok", op_of(fields, -7), stop)
    except DamageError as err:
        return (err.reason, err.offset, -1)


def _walk(buf: bytes, end: int) -> tuple[str, int, int]:
    try:
        op, stop = record_op(buf, 0, end)
    except DamageError as err:
        return (err.reason, err.offset, -1)
    if op < 0:
        return ("record has no op field", -7, -1)
    return ("ok", op, stop)


@settings(max_examples=500, deadline=None)
@given(
    fields=st.lists(_FIELDS, max_size=5),
    size_delta=st.integers(-3, 3),
    tail=st.binary(max_size=8),
    cut=st.integers(0, 6),
)
def test_record_op_agrees_with_the_full_header_parse(
    fields: list[bytes], size_delta: int, tail: bytes, cut: int
) -> None:
    body = b"".join(fields)
    buf = struct.pack("<I", max(len(body) + size_delta, 0)) + body + tail
    end = max(len(buf) - cut, 0)
    assert _walk(buf, end) == _full(buf, end)
