"""Drafts (redrive.types._drafts): a frozen slotted dataclass built through its mutable twin is
the object its constructor builds."""

from __future__ import annotations

import pickle
from dataclasses import FrozenInstanceError, dataclass, replace

import pytest

from redrive.io.base import LogMessage
from redrive.types._drafts import draft_class


@dataclass(frozen=True, slots=True, kw_only=True)
class _Point:
    x: float
    label: str = ""


def test_a_draft_becomes_the_frozen_class_equal_to_a_constructed_one() -> None:
    draft = draft_class(_Point)
    obj = draft()
    obj.x = 1.5
    obj.label = "a"
    obj.__class__ = _Point
    assert type(obj) is _Point
    assert obj == _Point(x=1.5, label="a")
    assert hash(obj) == hash(_Point(x=1.5, label="a"))
    assert repr(obj) == "_Point(x=1.5, label='a')"
    assert replace(obj, x=2.0) == _Point(x=2.0, label="a")
    with pytest.raises(FrozenInstanceError):
        obj.x = 3.0  # type: ignore[misc]


def test_a_drafted_log_message_pickles_and_compares_as_one_built_by_init() -> None:
    draft = draft_class(LogMessage)
    msg = draft()
    for name, value in (
        ("topic", "/t"), ("msgtype", "std_msgs/msg/String"), ("log_time_ns", 5),
        ("encoding", "ros1"), ("raw", b"\x01"), ("payload", None), ("batch", None),
    ):  # fmt: skip
        setattr(msg, name, value)
    msg.__class__ = LogMessage
    built = LogMessage(
        topic="/t", msgtype="std_msgs/msg/String", log_time_ns=5, encoding="ros1", raw=b"\x01"
    )
    assert msg == built
    assert pickle.loads(pickle.dumps(msg)) == built


def test_classes_of_another_layout_have_no_draft() -> None:
    class Plain:
        pass

    @dataclass(frozen=True, slots=True)
    class Base:
        a: int

    @dataclass(frozen=True, slots=True)
    class Derived(Base):
        b: int

    for cls in (Plain, Derived, int):
        with pytest.raises(TypeError):
            draft_class(cls)
