"""ROS 2 on the wire: a separate process publishes ROS 2-typed samples through Cyclone DDS
(tests/live/ros2_peer.py, its own hand-written IDL types); redrive records them and publishes its
results back. Each test has its own DDS domain on loopback only (CYCLONEDDS_URI), so parallel
runs never mix. Skips when cyclonedds is not installed (the ``ros2`` extra).
"""

from __future__ import annotations

import importlib.util
import itertools
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

pytest.importorskip("cyclonedds", reason="the ros2 extra (cyclonedds) is not installed")

from redrive.io import open_log
from redrive.io.ros.typestore import typestore_for
from redrive.live.ros2_dds import (
    DEFAULT,
    SENSOR_DATA,
    TF_STATIC,
    QosProfile,
    dds_topic,
    dds_type,
    idl_struct,
    ros_topic,
    ros_type,
)

PEER = Path(__file__).with_name("ros2_peer.py")
TOPICS = ["/points", "/camera/image_raw", "/imu"]
LOOPBACK = """<CycloneDDS><Domain id="any"><General><Interfaces>
<NetworkInterface address="127.0.0.1"/></Interfaces><AllowMulticast>false</AllowMulticast>
</General><Discovery><ParticipantIndex>auto</ParticipantIndex>
<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers>
</Discovery></Domain></CycloneDDS>"""
_DOMAINS = itertools.count()


def _load_peer() -> ModuleType:
    spec = importlib.util.spec_from_file_location("ros2_peer", PEER)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def domain(monkeypatch: pytest.MonkeyPatch) -> int:
    """A DDS domain of this test alone (1–232), on loopback, for this process and its children."""
    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK)
    return 1 + (os.getpid() * 7 + next(_DOMAINS)) % 232


@pytest.fixture
def peer_factory(domain: int) -> Iterator[list[subprocess.Popen[str]]]:
    started: list[subprocess.Popen[str]] = []
    yield started
    for proc in started:
        proc.terminate()
        try:
            proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()


def _start_peer(started: list[subprocess.Popen[str]], *args: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        [sys.executable, str(PEER), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    started.append(proc)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "ADVERTISED", proc.stderr.read() if proc.stderr else ""
    return proc


# -- names, QoS, types (no processes) ----------------------------------------------------------
def test_ros2_names_map_both_ways() -> None:
    assert dds_topic("/points") == "rt/points"
    assert ros_topic("rt/camera/image_raw") == "/camera/image_raw"
    assert ros_topic("rq/node/get_parametersRequest") is None
    assert dds_type("sensor_msgs/msg/PointCloud2") == "sensor_msgs::msg::dds_::PointCloud2_"
    assert ros_type("sensor_msgs::msg::dds_::PointCloud2_") == "sensor_msgs/msg/PointCloud2"
    assert ros_type("DDS::ParticipantBuiltinTopicData") is None


def test_qos_profiles_are_rclcpps_and_round_trip_through_dds() -> None:
    assert (SENSOR_DATA.reliability, SENSOR_DATA.durability, SENSOR_DATA.depth) == (
        "best_effort", "volatile", 5
    )  # fmt: skip
    assert (DEFAULT.reliability, DEFAULT.durability, DEFAULT.depth) == ("reliable", "volatile", 10)
    assert TF_STATIC.durability == "transient_local"
    for profile in (SENSOR_DATA, DEFAULT, TF_STATIC):
        assert QosProfile.from_dds(profile.to_dds()) == profile
    assert "reliability: 2\n  durability: 2" in SENSOR_DATA.to_yaml()
    assert "reliability: 1\n  durability: 1" in TF_STATIC.to_yaml()


def test_generated_type_serialises_as_rosbags_does() -> None:
    store = typestore_for(2)[0]
    types = store.types
    header = types["std_msgs/msg/Header"](
        stamp=types["builtin_interfaces/msg/Time"](sec=3, nanosec=4), frame_id="imu"
    )
    vec = types["geometry_msgs/msg/Vector3"](x=1.0, y=2.0, z=3.0)
    cov = np.arange(9, dtype=np.float64)
    msg = types["sensor_msgs/msg/Imu"](
        header=header,
        orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.6, w=0.8),
        orientation_covariance=cov,
        angular_velocity=vec,
        angular_velocity_covariance=cov,
        linear_acceleration=vec,
        linear_acceleration_covariance=cov,
    )
    cdr = bytes(store.serialize_cdr(msg, "sensor_msgs/msg/Imu"))
    cls = idl_struct(store, "sensor_msgs/msg/Imu")
    assert cls.__idl_typename__ == "sensor_msgs::msg::dds_::Imu_"
    sample = cls.deserialize(cdr)
    assert sample.header.frame_id == "imu"
    assert sample.orientation.z == 0.6
    assert list(sample.angular_velocity_covariance) == cov.tolist()
    assert sample.serialize()[: len(cdr)] == cdr


# -- on the wire --------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "count",
    [25, pytest.param(600, marks=pytest.mark.slow, id="60s")],  # 2.5 s / 60 s at 10 Hz
)
def test_ros2_topics_are_recorded_without_loss_and_read_back_equal(
    domain: int, peer_factory: list[subprocess.Popen[str]], tmp_path: Path, count: int
) -> None:
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    from redrive.live.recorder import DataLogger
    from redrive.live.ros2 import ros2_session

    _start_peer(peer_factory, "--domain", str(domain), "--count", str(count), "--points", "2000")
    out = tmp_path / "ros2.mcap"
    with ros2_session(TOPICS, domain_id=domain, wait_for_topics_s=15.0) as session:
        assert {s.payload for s in session.specs} == {"cdr"}
        recorder = DataLogger(session.specs, out)
        deadline = time.monotonic() + 40.0 + count / 10
        while min(recorder.recorded.values()) < count and time.monotonic() < deadline:
            time.sleep(0.05)
        recorder.stop()
    assert recorder.recorded == dict.fromkeys(TOPICS, count)
    assert recorder.errors == []

    with out.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}

    peer = _load_peer()
    got: dict[str, list[object]] = {t: [] for t in TOPICS}
    with AnyReader([out]) as reader:
        qos = {
            c.topic: c.ext.offered_qos_profiles[0]  # type: ignore[union-attr]
            for c in reader.connections
        }
        assert {c.topic: c.msgtype for c in reader.connections} == {
            "/points": "sensor_msgs/msg/PointCloud2",
            "/camera/image_raw": "sensor_msgs/msg/Image",
            "/imu": "sensor_msgs/msg/Imu",
        }
        for conn, _, raw in reader.messages():
            got[conn.topic].append(reader.deserialize(raw, conn.msgtype))
    assert qos["/points"].reliability.name == "BEST_EFFORT"  # the sensor-data profile offered
    assert qos["/imu"].reliability.name == "RELIABLE"
    assert all(q.durability.name == "VOLATILE" for q in qos.values())
    for i in range(count):
        sent_cloud, cloud = peer.cloud(i, 2000), got["/points"][i]
        assert cloud.header.stamp.sec == sent_cloud.header.stamp.sec  # type: ignore[attr-defined]
        assert cloud.header.stamp.nanosec == sent_cloud.header.stamp.nanosec  # type: ignore[attr-defined]
        assert cloud.header.frame_id == "lidar"  # type: ignore[attr-defined]
        assert [f.name for f in cloud.fields] == ["x", "y", "z", "intensity"]  # type: ignore[attr-defined]
        assert (cloud.width, cloud.point_step) == (2000, 16)  # type: ignore[attr-defined]
        assert cloud.data.tobytes() == bytes(sent_cloud.data)  # type: ignore[attr-defined]
        image, sent_image = got["/camera/image_raw"][i], peer.image(i)
        assert (image.height, image.width, image.encoding) == (24, 32, "rgb8")  # type: ignore[attr-defined]
        assert image.data.tobytes() == bytes(sent_image.data)  # type: ignore[attr-defined]
        imu = got["/imu"][i]
        assert imu.angular_velocity.x == pytest.approx(0.01 * i)  # type: ignore[attr-defined]
        assert imu.linear_acceleration.z == 9.81  # type: ignore[attr-defined]


def test_redrive_live_ros2_runs_the_pipeline_and_publishes_results(
    domain: int, peer_factory: list[subprocess.Popen[str]], tmp_path: Path
) -> None:
    from redrive.cli.main import main
    from redrive.results import open_run

    result_topic = "/redrive/cluster_detector/detections"
    peer = _start_peer(
        peer_factory, "--domain", str(domain), "--count", "0", "--points", "600",
        "--only", "/points", "/imu", "--listen", result_topic, "vision_msgs/msg/Detection3DArray",
    )  # fmt: skip
    argv = [
        "live", "--ros2", "--domain", str(domain), "--topics", "/points", "/imu",
        "--perception", "cluster-detector", "--frames", "3", "--wait", "15", "--duration", "60",
        "--out", str(tmp_path / "run"), "--record", str(tmp_path / "rec.mcap"),
    ]  # fmt: skip
    assert main(argv) == 0
    time.sleep(0.5)  # the last results on their way to the peer (counted below, not timed)
    peer.terminate()
    stdout, stderr = peer.communicate(timeout=10)
    results = [json.loads(line[7:]) for line in stdout.splitlines() if line.startswith("RESULT ")]
    frames = open_run(tmp_path / "run").table("frames").to_pydict()
    assert 1 <= len(results) <= len(frames["stamp_ns"]), stderr
    assert {r["type"] for r in results} == {"vision_msgs::msg::dds_::Detection3DArray_"}
    assert {r["frame_id"] for r in results} == {"base_link"}
    stamps = set(frames["stamp_ns"])
    assert all(r["stamp_ns"] in stamps for r in results)
    assert (tmp_path / "rec.mcap").stat().st_size > 0


def test_a_topic_nobody_publishes_is_an_error_naming_it_and_the_domain(
    domain: int, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    from redrive.cli.main import main

    argv = ["live", "--ros2", "--domain", str(domain), "--topics", "/nothing", "--wait", "0",
            "--out", str(tmp_path / "run")]  # fmt: skip
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "no publisher of /nothing on ROS 2 (DDS) domain" in err
    assert "Traceback" not in err
    assert not (tmp_path / "run").exists()


def test_record_only_on_ros2_stops_at_max_size(
    domain: int, peer_factory: list[subprocess.Popen[str]], tmp_path: Path
) -> None:
    """`redrive live --ros2 /imu --record …` without a pipeline records only, in the ros2 MCAP
    profile, and ends on a count (--max-size), not on a clock."""
    from mcap.reader import make_reader

    from redrive.cli.main import main

    _start_peer(peer_factory, "--domain", str(domain), "--count", "0", "--only", "/imu")
    out = tmp_path / "imu.mcap"
    argv = ["live", "--ros2", "--domain", str(domain), "/imu", "--record", str(out),
            "--max-size", "4K", "--wait", "15", "--duration", "120"]  # fmt: skip
    assert main(argv) == 0
    with out.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        (channel,) = summary.channels.values()
        assert channel.topic == "/imu"
        assert channel.message_encoding == "cdr"
        assert "reliability" in channel.metadata["offered_qos_profiles"]
        assert summary.schemas[channel.schema_id].name == "sensor_msgs/msg/Imu"
        sizes = [len(message.data) for _, _, message in reader.iter_messages()]
    assert sum(sizes) >= 4 * 1024  # it stopped once --max-size of messages were recorded
    assert sum(sizes[:-1]) < 4 * 1024 + 100 * max(sizes)  # soon after (messages in flight)
    assert not list(tmp_path.glob(".*.part"))


def test_record_only_on_ros2_needs_topics_or_a_selection() -> None:
    from redrive.cli.main import main

    assert main(["live", "--ros2", "--record", "x.mcap"]) == 2


def _counts(path: Path) -> dict[str, int]:
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert summary.statistics is not None
    return {
        c.topic: summary.statistics.channel_message_counts.get(c.id, 0)
        for c in summary.channels.values()
    }


def test_record_all_on_ros2_records_every_message_and_ends_when_the_publishers_leave(
    domain: int,
    peer_factory: list[subprocess.Popen[str]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """-a: the topics the scraper finds on the domain are recorded, every message of them (the
    peer publishes once redrive's readers matched, and exits once its reliable samples are
    acknowledged), and the session ends by itself (--idle-timeout 1) once it left the domain.
    With -a every topic joins through discovery, as a topic appearing later does."""
    from redrive.cli.main import main

    peer = _start_peer(peer_factory, "--domain", str(domain), "--count", "15", "--rate", "30",
                       "--only", "/camera/image_raw", "/imu", "--exit")  # fmt: skip
    out = tmp_path / "rec.mcap"
    argv = ["live", "--ros2", "--domain", str(domain), "-a", "--record", str(out),
            "--idle-timeout", "1", "--duration", "120"]  # fmt: skip
    assert main(argv) == 0
    assert peer.wait(timeout=10) == 0
    captured = capsys.readouterr()
    assert "stopped: every publisher of the recorded topics has been gone for 1 s" in " ".join(
        captured.out.split()
    )
    assert "recording /imu (published on the DDS domain)" in captured.err
    assert _counts(out) == {"/camera/image_raw": 15, "/imu": 15}
    assert not list(tmp_path.glob(".*.part"))


def test_record_regex_and_exclude_on_ros2_pick_their_topics(
    domain: int, peer_factory: list[subprocess.Popen[str]], tmp_path: Path
) -> None:
    from redrive.cli.main import main

    peer = _start_peer(peer_factory, "--domain", str(domain), "--count", "10", "--rate", "30",
                       "--points", "100", "--match", "/camera/image_raw", "--exit")  # fmt: skip
    out = tmp_path / "rec.mcap"
    argv = ["live", "--ros2", "--domain", str(domain), "-e", "/camera/.*", "-e", "/im.*",
            "-x", "/imu", "--record", str(out), "--idle-timeout", "1", "--duration", "120",
            "--split-size", "4K"]  # fmt: skip
    assert main(argv) == 0
    assert peer.wait(timeout=10) == 0
    # split as ROS 1 recordings split: numbered files, each complete with the channel and its
    # QoS, together every message once; redrive reads the set as one log
    files = sorted(tmp_path.glob("rec_*.mcap"))
    assert len(files) > 1
    per_file = [_counts(f) for f in files]
    assert all(set(c) == {"/camera/image_raw"} for c in per_file)
    assert sum(c["/camera/image_raw"] for c in per_file) == 10
    with open_log(tmp_path / "rec_*.mcap") as log:
        stamps = [m.log_time_ns for m in log.messages()]
    assert len(stamps) == 10
    assert stamps == sorted(stamps)
    assert not list(tmp_path.glob(".*.part"))


def test_the_scraper_ends_when_redrive_live_is_killed(
    domain: int, peer_factory: list[subprocess.Popen[str]], tmp_path: Path
) -> None:
    """SIGKILL of `redrive live --ros2` (no chance to clean up): its DDS scraper process notices
    its parent is gone and ends, instead of reading the domain on for ever."""
    import psutil

    _start_peer(peer_factory, "--domain", str(domain), "--count", "0", "--only", "/imu")
    argv = [sys.executable, "-m", "redrive", "live", "--ros2", "--domain", str(domain), "/imu",
            "--record", str(tmp_path / "imu.mcap"), "--wait", "15", "--duration", "300"]  # fmt: skip
    live = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    scraper = None
    try:
        assert live.stderr is not None
        for line in live.stderr:
            if "live: recording" in line:
                break
        else:
            pytest.fail(f"redrive live --ros2 ended before recording (exit {live.wait()})")
        (scraper,) = (
            child for child in psutil.Process(live.pid).children(recursive=True)
            if "redrive.live.ros2_scraper" in " ".join(child.cmdline())
        )  # fmt: skip
        live.kill()
        live.wait(timeout=10)
        # the scraper looks at its parent at least every 0.1 s; 60 s leaves room for a loaded machine
        deadline = time.monotonic() + 60
        while _still_runs(scraper) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _still_runs(scraper), f"the ROS 2 scraper {scraper.pid} outlived redrive live"
    finally:
        if live.poll() is None:
            live.kill()
            live.wait(timeout=10)
        if live.stderr is not None:
            live.stderr.close()
        if scraper is not None and _still_runs(scraper):
            scraper.kill()  # not left behind when the test fails


def _still_runs(process: Any) -> bool:
    """Whether a psutil process runs (an orphan that ended may stay a zombie until reaped)."""
    import psutil

    try:
        return bool(process.status() != psutil.STATUS_ZOMBIE)
    except psutil.NoSuchProcess:
        return False
