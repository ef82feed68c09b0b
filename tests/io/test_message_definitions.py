"""Message definitions that cannot be deserialised (issue 37): a type that contains itself, or
one nesting hundreds of levels deep, is said once per type (not once per message) and its
messages stay raw; ``convert`` leaves its topic out."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from rosbags.typesys import get_types_from_msg

from redrive.cli.main import main
from redrive.io.ros.typestore import MAX_TYPE_NESTING, typestore_for, unreadable_types
from redrive.io.rosbag1.reader import Ros1BagReader
from tests.hostile.generator import _RECURSIVE_MSGDEF, _deep_msgdef, _write_bag_with_msgdef


def _warnings(caplog: pytest.LogCaptureFixture, logger: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == logger]


def test_a_recursive_type_is_said_once_and_its_messages_stay_raw(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    bag = tmp_path / "recursive.bag"
    _write_bag_with_msgdef(bag, "rec/msg/Node", _RECURSIVE_MSGDEF)
    with caplog.at_level(logging.WARNING), Ros1BagReader(bag) as log:
        raw = [bytes(m.raw) for m in log.messages()]
        assert not log.topics["/hostile"].has_definition
    assert raw == [b"\x00" * 64] * 5
    (said,) = _warnings(caplog, "redrive.io.ros.typestore")
    assert "rec/msg/Node contains itself" in said
    assert str(bag) in said


@pytest.mark.parametrize(
    ("name", "msgtype", "definition", "said"),
    [
        ("recursive.bag", "rec/msg/Node", _RECURSIVE_MSGDEF, "rec/msg/Node contains itself"),
        ("deep.bag", "deep/msg/L0", _deep_msgdef(), "nests 401 message types deep"),
    ],
)
def test_convert_says_it_once_and_leaves_the_topic_out(
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
    capsys: pytest.CaptureFixture[str],
    *,
    name: str,
    msgtype: str,
    definition: str,
    said: str,
) -> None:
    bag = tmp_path / name
    _write_bag_with_msgdef(bag, msgtype, definition)
    with caplog.at_level(logging.WARNING):
        assert main(["convert", str(bag), str(tmp_path / "out.mcap")]) == 0
    (warning,) = _warnings(caplog, "redrive.io.ros.typestore")  # once, not per message or open
    assert said in warning
    assert not any("message skipped" in w for w in _warnings(caplog, "redrive.io.convert"))
    assert "left out /hostile" in capsys.readouterr().out


def test_messages_that_do_not_convert_are_said_once_per_topic(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 40-level type is read, but the 64 zero bytes of each message are too short for it:
    one warning for the topic, the five messages counted."""
    bag = tmp_path / "short.bag"
    _write_bag_with_msgdef(bag, "deep/msg/L0", _deep_msgdef(levels=40))
    with caplog.at_level(logging.WARNING):
        assert main(["convert", str(bag), str(tmp_path / "out.mcap")]) == 0
    (warning,) = _warnings(caplog, "redrive.io.convert")
    assert "further failures on this topic are counted, not logged" in warning
    assert "5 messages did not convert" in capsys.readouterr().out


def test_unreadable_types() -> None:
    store, _ = typestore_for(1)
    typs = dict(store.fielddefs)
    assert unreadable_types(typs, ["sensor_msgs/msg/PointCloud2", "nav_msgs/msg/Odometry"]) == {}
    store, failed = typestore_for(
        1,
        {"rec/msg/Node": ("msg", _RECURSIVE_MSGDEF), "deep/msg/L0": ("msg", _deep_msgdef(80))},
        needed=["rec/msg/Node", "deep/msg/L0"],
    )
    assert {"rec/msg/Node", "deep/msg/L0"} <= failed
    assert "rec/msg/Node" not in store.fielddefs
    assert "deep/msg/L0" not in store.fielddefs
    # a type holding an unreadable one is unreadable too, and says why
    wrapper = "int32 a\nrec/Node inner\n" + "=" * 80 + "\nMSG: rec/Node\nrec/Node[] more\n"
    typs.update(get_types_from_msg(wrapper, "wrap/msg/W"))
    bad = unreadable_types(typs, ["wrap/msg/W"])
    assert bad["rec/msg/Node"] == "rec/msg/Node contains itself"
    assert bad["wrap/msg/W"] == (
        "wrap/msg/W contains rec/msg/Node, which cannot be read: rec/msg/Node contains itself"
    )
    found = typestore_for(1, {"deep/msg/L0": ("msg", _deep_msgdef(MAX_TYPE_NESTING + 1))})[1]
    assert "deep/msg/L0" in found
    ok_store, ok_failed = typestore_for(1, {"deep/msg/L0": ("msg", _deep_msgdef(20))})
    assert not ok_failed
    assert "deep/msg/L0" in ok_store.fielddefs
