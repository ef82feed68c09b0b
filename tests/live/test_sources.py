"""Replay and synthetic sources: real logs and the real simulator into real shared-memory streams,
read back through :class:`redrive.transport.Reader` and compared with the decoded log."""

from __future__ import annotations

import dataclasses
import itertools
import os
import select
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.errors import ConfigError, TransportError
from redrive.io import open_log
from redrive.io.mcap.writer import McapWriter
from redrive.io.ros.decoders import decode
from redrive.io.ros.decoders.base import Decoded
from redrive.live import sources
from redrive.live.sources import (
    LOOP_GAP_NS,
    ReplayStats,
    SyntheticStats,
    replay_streams,
    run_replay_source,
    run_synthetic_source,
    synthetic_streams,
)
from redrive.live.streams import PAYLOAD_MSGTYPE, StreamSpec, ring_slots, stream_name
from redrive.sim.scenario import Scenario, load_scenario
from redrive.sim.synth import synthesize
from redrive.transport import Policy, ProducerGoneError, Reader, Writer
from redrive.transport.codec import encoded_size
from redrive.types import PointCloud, SensorData, SensorType, VehicleState

ROOT = Path(__file__).resolve().parents[2]

# A small rig (every kind, a 16-beam LiDAR, a small camera) keeps the simulator fast.
SMALL_RIG: dict[str, Any] = {
    "lidar_top": {"kind": "lidar", "preset": "VLP-16", "xyz": [1.2, 0.0, 1.9], "rate_hz": 10},
    "camera_front": {
        "kind": "camera",
        "xyz": [1.5, 0.0, 1.6],
        "rate_hz": 5,
        "width": 160,
        "height": 90,
        "fx": 125.0,
        "fy": 125.0,
    },
    "imu": {"kind": "imu", "xyz": [0.0, 0.0, 0.5], "rate_hz": 100},
    "gnss": {"kind": "gnss", "xyz": [0.0, 0.0, 1.8], "rate_hz": 10},
    "odom": {"kind": "odometry", "rate_hz": 50},
    "lidar_2d": {"kind": "lidar_2d", "preset": "UTM-30LX", "xyz": [3.7, 0.0, 0.5], "rate_hz": 20},
}
# Nothing to render: the simulator runs far faster than real time.
INERTIAL_RIG: dict[str, Any] = {k: SMALL_RIG[k] for k in ("imu", "gnss", "odom")}


def _segments(session: str) -> list[Path]:
    return sorted(Path("/dev/shm").glob(f"redrive.{session}.*"))


@pytest.fixture
def session() -> Iterator[str]:
    """A session name of its own; no segment of it may be left after the test."""
    name = f"tsrc{os.getpid()}-{uuid.uuid4().hex[:8]}"
    yield name
    left = _segments(name)
    for path in left:
        path.unlink(missing_ok=True)
    assert not left, f"segments left behind: {left}"


def _small(rig: dict[str, Any] = SMALL_RIG, name: str = "urban") -> Scenario:
    return dataclasses.replace(load_scenario(name), rig=rig)


class Collector:
    """Attaches a reader to every stream (call :meth:`attach` from ``on_ready``) and reads each in
    its own thread until its writer is gone."""

    def __init__(self, specs: Sequence[StreamSpec], *, until: int | None = None) -> None:
        self.specs = specs
        self.samples: dict[str, list[SensorData]] = {s.topic: [] for s in specs}
        self.errors: list[BaseException] = []
        self.until = until
        self.enough = threading.Event()
        self._threads: list[threading.Thread] = []

    def attach(self) -> None:
        for spec in self.specs:
            reader = Reader(spec.stream)
            thread = threading.Thread(target=self._read, args=(reader, spec.topic), daemon=True)
            thread.start()
            self._threads.append(thread)

    def _read(self, reader: Reader, topic: str) -> None:
        deadline = time.monotonic() + 120
        try:
            while time.monotonic() < deadline:
                try:
                    got = reader.read_sample(timeout_s=0.2)
                except ProducerGoneError:
                    return
                if got is not None:
                    self.samples[topic].append(got[1])
                    if self.until is not None and len(self.samples[topic]) >= self.until:
                        self.enough.set()
        except BaseException as err:  # reported by join()
            self.errors.append(err)
        finally:
            reader.close()

    def join(self) -> dict[str, list[SensorData]]:
        for thread in self._threads:
            thread.join(timeout=60)
        assert not self.errors, self.errors
        return self.samples


def _in_thread(fn: Callable[[], Any]) -> tuple[threading.Thread, dict[str, Any]]:
    out: dict[str, Any] = {}

    def run() -> None:
        try:
            out["result"] = fn()
        except BaseException as err:
            out["error"] = err

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, out


def _assert_value_equal(expected: object, got: object, *, where: str) -> None:
    assert type(expected) is type(got), where
    for field in dataclasses.fields(expected):  # type: ignore[arg-type]
        a, b = getattr(expected, field.name), getattr(got, field.name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype, f"{where}: {field.name}"
            assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f"{where}: {field.name}"
        elif isinstance(a, Mapping):
            assert a.keys() == b.keys(), f"{where}: {field.name}"
            for key in a:
                assert a[key].dtype == b[key].dtype, f"{where}: {field.name}.{key}"
                nan = a[key].dtype.kind == "f"
                assert np.array_equal(a[key], b[key], equal_nan=nan), f"{where}: {field.name}.{key}"
        else:
            assert a == b, f"{where}: {field.name}"


def _decoded(log_path: Path, topics: Sequence[str]) -> dict[str, list[Decoded]]:
    """Every message of ``topics``, decoded, by topic (one pass over the log)."""
    out: dict[str, list[Decoded]] = {t: [] for t in topics}
    with open_log(log_path) as log:
        for message in log.messages(topics=topics):
            out[message.topic].append(decode(message, log.deserialize))
    return out


# -- replay -----------------------------------------------------------------------------------


def test_replay_streams_one_per_sensor_and_state_topic(demo_log: Path, session: str) -> None:
    specs = replay_streams(demo_log, session)
    by_topic = {s.topic: s for s in specs}
    assert set(by_topic) == {
        "/camera_front/image_raw",
        "/gnss",
        "/imu",
        "/lidar_2d",
        "/lidar_top",
        "/odom",
        "/ground_truth/ego_state",
    }  # not /tf, /tf_static, /ground_truth/objects
    assert by_topic["/lidar_top"].msgtype == PAYLOAD_MSGTYPE["PointCloud"]
    assert by_topic["/lidar_2d"].msgtype == "sensor_msgs/msg/LaserScan"  # a 2D scan
    assert by_topic["/odom"].msgtype == PAYLOAD_MSGTYPE["VehicleState"]
    for spec in specs:
        assert spec.payload == "sensor"
        assert spec.stream == stream_name(session, spec.topic)
        assert spec.capacity_bytes % 4096 == 0
    # every message of the variable-size topic fits
    clouds = [d.value for d in _decoded(demo_log, ["/lidar_top"])["/lidar_top"]]
    largest = max(
        encoded_size(SensorData(sensor_id="x", sensor_type=SensorType.LIDAR, stamp_ns=0, data=c))
        for c in clouds
        if isinstance(c, PointCloud)
    )
    assert largest <= by_topic["/lidar_top"].capacity_bytes
    assert by_topic["/camera_front/image_raw"].capacity_bytes >= 1280 * 720 * 3
    assert [s.topic for s in replay_streams(demo_log, session, topics=["/imu"])] == ["/imu"]


def test_replay_publishes_every_message_as_decoded(demo_log: Path, session: str) -> None:
    specs = replay_streams(demo_log, session)
    collector = Collector(specs)
    stats = run_replay_source(
        demo_log, session, rate=None, policy=Policy.LOSSLESS, on_ready=collector.attach
    )
    samples = collector.join()
    assert isinstance(stats, ReplayStats)
    assert not stats.stopped
    assert stats.loops == 1
    assert sum(stats.skipped.values()) == 0
    reference = _decoded(demo_log, [s.topic for s in specs])
    for spec in specs:
        expected = reference[spec.topic]
        got = samples[spec.topic]
        assert stats.published[spec.topic] == len(expected) == len(got), spec.topic
        for i, (d, s) in enumerate(zip(expected, got, strict=True)):
            where = f"{spec.topic}[{i}]"
            assert s.stamp_ns == d.stamp_ns, where
            assert s.frame_id == d.frame_id, where
            _assert_value_equal(d.value, s.data, where=where)
    lidar = samples["/lidar_top"][0]
    assert lidar.sensor_id == "lidar_top"
    assert lidar.sensor_type is SensorType.LIDAR
    assert lidar.sensor_location == pytest.approx((1.2, 0.0, 1.9))  # from /tf_static
    assert samples["/lidar_2d"][0].sensor_type is SensorType.LIDAR_2D
    camera = samples["/camera_front/image_raw"][0]
    assert camera.resolution == (1280, 720)
    assert camera.sensor_type is SensorType.CAMERA
    odom = samples["/odom"][0]
    assert odom.sensor_type is SensorType.ODOMETRY
    assert isinstance(odom.data, VehicleState)


def test_replay_is_paced_by_log_time_over_rate(demo_log: Path, session: str) -> None:
    with open_log(demo_log) as log:
        span_s = (log.end_ns - log.start_ns) / 1e9
    start = time.monotonic()
    stats = run_replay_source(demo_log, session, rate=4.0, topics=["/imu", "/gnss"])
    elapsed = time.monotonic() - start
    assert elapsed >= 0.7 * span_s / 4.0  # paced: never faster than 4x the log
    # (how much slower it runs depends on the machine's load: not asserted)
    assert stats.published == {"/gnss": 100, "/imu": 1000}
    assert stats.max_late_s < 2.0  # lateness itself depends on the machine's load: not asserted


def test_stop_event_ends_replay_promptly(demo_log: Path, session: str) -> None:
    stop = threading.Event()
    ready = threading.Event()
    thread, out = _in_thread(
        lambda: run_replay_source(demo_log, session, rate=1.0, stop=stop, on_ready=ready.set)
    )
    assert ready.wait(30)
    assert _segments(session)  # the writers exist while it runs
    time.sleep(0.3)
    stop.set()
    set_at = time.monotonic()
    thread.join(timeout=5)
    assert not thread.is_alive()
    assert time.monotonic() - set_at < 1.0
    stats = out["result"]
    assert stats.stopped
    assert 0 < sum(stats.published.values()) < 3000
    assert not _segments(session)


def test_loop_replays_with_increasing_stamps(demo_log: Path, session: str) -> None:
    specs = replay_streams(demo_log, session, topics=["/gnss"])
    collector = Collector(specs, until=150)
    stop = threading.Event()
    thread, out = _in_thread(
        lambda: run_replay_source(
            demo_log,
            session,
            rate=None,
            topics=["/gnss"],
            loop=True,
            stop=stop,
            policy=Policy.LOSSLESS,
            on_ready=collector.attach,
        )
    )
    assert collector.enough.wait(30)
    stop.set()
    thread.join(timeout=5)
    assert out["result"].stopped
    assert out["result"].loops >= 1
    stamps = [s.stamp_ns for s in collector.join()["/gnss"]]
    assert all(b > a for a, b in itertools.pairwise(stamps))
    with open_log(demo_log) as log:
        cycle_ns = log.end_ns - log.start_ns + LOOP_GAP_NS
    assert stamps[100] - stamps[0] == cycle_ns


def test_sample_too_large_for_its_stream_is_a_transport_error(
    demo_log: Path, session: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    real_scan = sources.replay._scan

    def undersized(log: Any, topics: Any) -> Any:
        sizes, locations = real_scan(log, topics)
        return dict.fromkeys(sizes, 4096), locations

    monkeypatch.setattr(sources.replay, "_scan", undersized)
    with pytest.raises(TransportError, match=r"/lidar_top does not fit stream .*capacity_bytes"):
        run_replay_source(demo_log, session, rate=None, topics=["/imu", "/lidar_top"])
    assert not _segments(session)


def test_undecodable_messages_are_skipped_and_counted(tmp_path: Path, session: str) -> None:
    path = tmp_path / "bad.mcap"
    rng = np.random.default_rng(0)
    with McapWriter(path) as writer:
        for i in range(5):
            cloud = PointCloud(xyz=rng.normal(size=(100, 3)).astype(np.float32), channels={})
            writer.write("/points", 1_000_000_000 + i * 100_000_000, cloud, frame_id="lidar")
        writer.write_raw("/points", "sensor_msgs/msg/PointCloud2", 1_600_000_000, b"\0\1\0\0junk")
    stats = run_replay_source(path, session, rate=None)
    assert stats.published == {"/points": 5}
    assert stats.skipped == {"/points": 1}


def test_bad_arguments_are_config_errors(demo_log: Path, session: str) -> None:
    with pytest.raises(ConfigError, match="/nope"):
        replay_streams(demo_log, session, topics=["/nope"])
    with pytest.raises(ConfigError, match="/tf"):
        run_replay_source(demo_log, session, topics=["/tf"])
    with pytest.raises(ConfigError, match="rate"):
        run_replay_source(demo_log, session, rate=0.0)
    assert not _segments(session)


# -- synthetic --------------------------------------------------------------------------------


def test_synthetic_streams_follow_the_rig(session: str) -> None:
    specs = synthetic_streams(_small(), session)
    by_topic = {s.topic: s for s in specs}
    assert list(by_topic) == [
        "/lidar_top",
        "/camera_front/image_raw",
        "/imu",
        "/gnss",
        "/odom",
        "/lidar_2d",
    ]  # no ground truth, no transforms
    assert by_topic["/camera_front/image_raw"].msgtype == PAYLOAD_MSGTYPE["Image"]
    assert by_topic["/camera_front/image_raw"].capacity_bytes >= 160 * 90 * 3
    assert by_topic["/odom"].msgtype == PAYLOAD_MSGTYPE["VehicleState"]
    assert by_topic["/lidar_top"].capacity_bytes >= 16 * 1800 * 22  # VLP-16, 22 B/point
    assert synthetic_streams("urban", session)[0].topic == "/lidar_top"


def test_synthetic_samples_equal_the_synthesized_log(tmp_path: Path, session: str) -> None:
    scenario = _small()
    specs = synthetic_streams(scenario, session)
    collector = Collector(specs)
    stats = run_synthetic_source(
        scenario,
        session,
        duration_s=1.0,
        rate=None,
        policy=Policy.LOSSLESS,
        on_ready=collector.attach,
    )
    samples = collector.join()
    assert isinstance(stats, SyntheticStats)
    assert stats.sim_s == pytest.approx(1.0, abs=0.02)
    assert not stats.stopped
    log_path = synthesize(scenario, tmp_path / "same.mcap", duration_s=1.0).path
    reference = _decoded(log_path, [s.topic for s in specs])
    for spec in specs:
        expected = reference[spec.topic]
        got = samples[spec.topic]
        assert stats.published[spec.topic] == len(expected) == len(got), spec.topic
        for i, (d, s) in enumerate(zip(expected, got, strict=True)):
            where = f"{spec.topic}[{i}]"
            assert s.stamp_ns == d.stamp_ns, where
            assert s.frame_id == d.frame_id, where
            if isinstance(d.value, VehicleState):  # Odometry keeps less than the model's state
                assert isinstance(s.data, VehicleState)
                np.testing.assert_allclose(s.data.position, d.value.position, atol=1e-9)
                assert s.data.heading_rad == pytest.approx(d.value.heading_rad, abs=1e-9)
            else:
                _assert_value_equal(d.value, s.data, where=where)
    assert samples["/lidar_top"][0].sensor_location == (1.2, 0.0, 1.9)
    assert samples["/camera_front/image_raw"][0].sensor_id == "camera_front_image_raw"
    assert samples["/lidar_2d"][0].sensor_type is SensorType.LIDAR_2D


def test_synthetic_is_paced_in_real_time_over_rate(session: str) -> None:
    start = time.monotonic()
    stats = run_synthetic_source(_small(INERTIAL_RIG), session, duration_s=4.0, rate=4.0)
    elapsed = time.monotonic() - start
    assert elapsed >= 0.7 * 4.0 / 4.0
    assert stats.wall_s <= 4.0 / 4.0 + 2.0
    assert stats.published == {"/imu": 400, "/gnss": 40, "/odom": 200}
    assert stats.real_time_factor > 1.0  # nothing to render: faster than real time


def test_synthetic_slower_than_real_time_is_late_not_dropped(session: str) -> None:
    rig = {
        "camera_front": {**SMALL_RIG["camera_front"], "width": 640, "height": 360, "rate_hz": 20},
        "imu": SMALL_RIG["imu"],
    }
    stats = run_synthetic_source(_small(rig), session, duration_s=1.0, rate=50.0)
    assert stats.published == {"/camera_front/image_raw": 20, "/imu": 100}
    assert stats.late["/camera_front/image_raw"] > 0
    assert stats.max_late_s > 0.01


def test_stop_event_ends_synthetic_promptly(session: str) -> None:
    stop = threading.Event()
    ready = threading.Event()
    thread, out = _in_thread(
        lambda: run_synthetic_source(
            _small(), session, duration_s=30.0, rate=1.0, stop=stop, on_ready=ready.set
        )
    )
    assert ready.wait(30)
    time.sleep(0.3)
    stop.set()
    thread.join(timeout=5)
    assert not thread.is_alive()
    assert out["result"].stopped
    assert not _segments(session)


# -- as a process -----------------------------------------------------------------------------


def _start(args: Sequence[str]) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    return subprocess.Popen(
        [sys.executable, "-m", "redrive.live.sources", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def _wait_ready(proc: subprocess.Popen[str], timeout_s: float = 60.0) -> None:
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
    line = proc.stdout.readline() if ready else ""
    if line.strip() != "READY":
        proc.kill()
        _, err = proc.communicate(timeout=10)
        pytest.fail(f"no READY (got {line!r}):\n{err}")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_process_replay_stops_on_signal_and_unlinks(
    demo_log: Path, session: str, sig: signal.Signals
) -> None:
    proc = _start(["replay", str(demo_log), "--session", session, "--rate", "1"])
    try:
        _wait_ready(proc)
        assert {p.name for p in _segments(session)} >= {f"redrive.{session}.lidar_top"}
        with Reader(stream_name(session, "/imu")) as reader:
            got = reader.read_sample(timeout_s=5)
        assert got is not None
        assert got[1].sensor_type is SensorType.IMU
        proc.send_signal(sig)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=10)
    assert not _segments(session)


def test_process_synthetic_stops_on_sigterm_and_unlinks(session: str, tmp_path: Path) -> None:
    scenario = tmp_path / "inertial.toml"
    text = (ROOT / "src/redrive/sim/scenarios/urban.toml").read_text()
    rig_at = text.index("[rig.")
    rig = "\n".join(f"[rig.{name}]\n{_toml(table)}" for name, table in INERTIAL_RIG.items())
    scenario.write_text(text[:rig_at] + rig)
    proc = _start(["synthetic", str(scenario), "--session", session, "--duration", "30"])
    try:
        _wait_ready(proc)
        assert len(_segments(session)) == 3
        with Reader(stream_name(session, "/odom")) as reader:
            got = reader.read_sample(timeout_s=5)
        assert got is not None
        assert isinstance(got[1].data, VehicleState)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=10)
    assert not _segments(session)


def _toml(table: Mapping[str, Any]) -> str:
    def value(v: Any) -> str:
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return str(v)

    return "\n".join(f"{key} = {value(v)}" for key, v in table.items()) + "\n"


def test_process_reports_errors_without_traceback(session: str, tmp_path: Path) -> None:
    proc = _start(["replay", str(tmp_path / "missing.mcap"), "--session", session])
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1
    assert "missing.mcap" in err
    assert "Traceback" not in err


# -- rings of small streams --------------------------------------------------------------------


@pytest.mark.parametrize(("slots", "kept"), [(8, 8), (ring_slots(4096, 8), 200)])
def test_a_burst_of_ego_states_reaches_the_dispatcher_when_the_ring_holds_it(
    session: str, slots: int, kept: int
) -> None:
    """A source that fell behind publishes its backlog at once: 200 odometry messages before the
    Sensor Dispatcher (a keep-latest reader, with a backlog for ego states) reads again. A ring
    of 8 slots laps it (the 8 it still holds arrive, 192 are missed); the ring a small stream
    gets (ring_slots) holds them all."""
    from redrive.live.dispatcher import LiveLog

    assert ring_slots(4096, 8) >= 200
    assert ring_slots(32 << 20, 8) == 8  # big messages: the slots asked for
    spec = StreamSpec(
        topic="/odom",
        msgtype=PAYLOAD_MSGTYPE["VehicleState"],
        stream=stream_name(session, "/odom"),
        payload="sensor",
        capacity_bytes=4096,
    )
    stamps = [1_700_000_000_000_000_000 + i * 10_000_000 for i in range(200)]
    with Writer(spec.stream, capacity_bytes=4096, slots=slots, max_readers=2) as writer:
        stop = threading.Event()
        with LiveLog([spec], session, stop=stop) as log:
            for stamp in stamps:
                state = VehicleState(stamp_ns=stamp, velocity=np.array([5.0, 0.0, 0.0]))
                writer.publish_sample(
                    SensorData(
                        sensor_id="odom",
                        sensor_type=SensorType.ODOMETRY,
                        stamp_ns=stamp,
                        data=state,
                    )
                )
            got = []
            for message in log.messages():
                got.append(message)
                if message.payload.stamp_ns == stamps[-1]:  # type: ignore[union-attr]
                    break
            assert [m.payload.stamp_ns for m in got] == stamps[-kept:]  # type: ignore[union-attr]
            assert log.dropped["/odom"] == 200 - kept


def test_the_first_sweep_read_finds_ego_states_on_both_sides_of_its_stamp(session: str) -> None:
    """A source that published for a second before the dispatcher attached: its LiDAR reader
    starts at the newest sweep, the ego states' reader at the oldest state the ring holds (not
    the newest, 40 ms after that sweep), so states before and after the first sweep's stamp
    arrive and its frame is not without an ego state."""
    from redrive.live.dispatcher import LiveLog

    lidar = StreamSpec(
        topic="/points",
        msgtype=PAYLOAD_MSGTYPE["PointCloud"],
        stream=stream_name(session, "/points"),
        payload="sensor",
        capacity_bytes=1 << 16,
    )
    odom = StreamSpec(
        topic="/odom",
        msgtype=PAYLOAD_MSGTYPE["VehicleState"],
        stream=stream_name(session, "/odom"),
        payload="sensor",
        capacity_bytes=4096,
    )
    t0 = 1_700_000_000_000_000_000
    cloud = PointCloud(xyz=np.zeros((10, 3), np.float32))
    with (
        Writer(lidar.stream, capacity_bytes=1 << 16, slots=4, max_readers=2) as points,
        Writer(odom.stream, capacity_bytes=4096, slots=ring_slots(4096, 8), max_readers=2) as ego,
    ):
        for i in range(105):  # odometry at 100 Hz, a sweep every 10th state
            stamp = t0 + i * 10_000_000
            state = VehicleState(stamp_ns=stamp, velocity=np.array([5.0, 0.0, 0.0]))
            ego.publish_sample(
                SensorData(
                    sensor_id="odom", sensor_type=SensorType.ODOMETRY, stamp_ns=stamp, data=state
                )
            )
            if i % 10 == 0:
                points.publish_sample(
                    SensorData(
                        sensor_id="lidar",
                        sensor_type=SensorType.LIDAR,
                        stamp_ns=stamp,
                        data=cloud,
                    )
                )
        stop = threading.Event()
        with LiveLog([lidar, odom], session, stop=stop) as log:
            failsafe = threading.Timer(60.0, stop.set)  # a regression ends the read, not the suite
            failsafe.start()
            got = []
            for message in log.messages():
                got.append(message)
                if len(got) == 105 + 1:  # every state, and the newest sweep
                    break
            failsafe.cancel()
    sweeps = [m.payload.stamp_ns for m in got if m.topic == "/points"]  # type: ignore[union-attr]
    states = [m.payload.stamp_ns for m in got if m.topic == "/odom"]  # type: ignore[union-attr]
    assert sweeps == [t0 + 1_000_000_000]  # the newest
    assert states == [t0 + i * 10_000_000 for i in range(105)]
    assert min(states) < sweeps[0] < max(states)
