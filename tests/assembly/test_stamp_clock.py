"""Frames on bags whose header stamps and record (log) times follow different clocks, as real
bags do (the Luminar bag's stamps are 238 days before its record times): a frame waits for its
inputs by log time, never by comparing a header stamp with a log time."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from redrive.assembly.frames import FrameAssembler
from redrive.io import open_log
from redrive.io.base import LogMessage
from redrive.testing.demo_log import write_demo_bag

_DAY_NS = 86_400 * 10**9


def _reclocked(src: Path, dst: Path, *, offset_ns: int, late_ns: dict[str, int]) -> Path:
    """A copy of ``src`` with every record time moved by ``offset_ns`` (header stamps kept) and
    the topics of ``late_ns`` recorded that much later still."""
    from rosbags.rosbag1 import Reader, Writer

    rows = []
    with Reader(src) as reader:
        for conn, stamp, raw in reader.messages():
            rows.append((stamp + offset_ns + late_ns.get(conn.topic, 0), conn, raw))
        conns = list(reader.connections)
    rows.sort(key=lambda r: r[0])
    with Writer(dst) as writer:
        out = {
            c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
            for c in conns
        }
        for t, conn, raw in rows:
            writer.write(out[conn.id], t, raw)
    return dst


def _summary(path: Path) -> list[tuple[int, tuple[str, ...], tuple[str, ...]]]:
    with open_log(path) as log:
        return [
            (f.stamp_ns, tuple(sorted(f.sensors)), f.missing) for f in FrameAssembler(log).frames()
        ]


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_demo_bag(tmp_path_factory.mktemp("clock") / "demo.bag", duration_s=2.0)


def test_stamps_long_before_the_record_times_still_wait_for_a_late_input(
    demo: Path, tmp_path: Path
) -> None:
    """Record times 238 days after the stamps, the GNSS recorded 150 ms after its stamp (within
    the 200-ms lookahead): every frame still gets the fix of its own stamp, as on the bag whose
    clocks agree."""
    expected = _summary(demo)
    assert all("gnss_fix" in sensors for _, sensors, _ in expected[:-1])
    moved = _reclocked(
        demo, tmp_path / "late.bag", offset_ns=238 * _DAY_NS, late_ns={"/gnss/fix": 150_000_000}
    )
    assert _summary(moved) == expected


def test_stamps_after_the_record_times_give_frames_as_the_log_is_read(
    demo: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Stamps a day after the record times: the frames are the same, and each comes out a
    lookahead after its LiDAR sweep was read, not all at the end of the log (memory)."""
    moved = _reclocked(demo, tmp_path / "early.bag", offset_ns=-_DAY_NS, late_ns={})
    with open_log(moved) as log:
        read: list[int] = []
        messages = log.messages

        def counted(*args: object, **kwargs: object) -> Iterator[LogMessage]:
            for message in messages(*args, **kwargs):  # type: ignore[arg-type]
                read.append(message.log_time_ns)
                yield message

        monkeypatch.setattr(log, "messages", counted)
        frames = FrameAssembler(log).frames()
        first = next(frames)
        assert read[-1] - log.start_ns < 500_000_000  # 0.5 s of a 2-s log read
        rest = list(frames)
    got = [(f.stamp_ns, tuple(sorted(f.sensors)), f.missing) for f in (first, *rest)]
    assert got == _summary(demo)


@pytest.mark.shared_data
def test_an_input_on_another_clock_is_named_once(
    shared_data: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The real Luminar bag: its odometry is stamped in simulated time (near 1970), its clouds
    in 2020 — every frame of `redrive run` misses the ego state, and one warning says why."""
    from redrive.cli.main import main
    from redrive.results import open_run

    bag = shared_data / "rosbag1_real/embag_luminar_test.bag"
    if not bag.exists():
        pytest.skip("the Luminar bag is not in ../shared/data")
    with caplog.at_level("WARNING"):
        main(["run", str(bag), "-o", str(tmp_path / "run"), "--no-progress"])
    frames = open_run(tmp_path / "run").table("frames").to_pydict()
    assert frames["missing_inputs"]
    assert all("vehicle_state" in m for m in frames["missing_inputs"])
    said = [r.getMessage() for r in caplog.records if "another clock" in r.getMessage()]
    named = [m.split("the header stamps of ")[1].split(" lie")[0] for m in said]
    assert named.count("vehicle_state") == 1
    assert len(named) == len(set(named))
    assert all("18333.0 days from the frames'" in m for m in said)
