"""A synthetic log's frames as REP-105 has them, and the QoS ``ros2 bag play`` replays with."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from redrive.geometry.se3 import compose, matrix_from_transform
from redrive.io import open_log
from redrive.io.mcap.qos import LATCHED_QOS, VOLATILE_QOS
from redrive.io.ros.decoders import decode
from redrive.sim.scenario import load_scenario
from redrive.sim.synth import synthesize
from redrive.types import Transform, VehicleState
from tests.sim.test_synth import SMALL_RIG


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("rep105") / "u.mcap"
    synthesize(dataclasses.replace(load_scenario("urban"), rig=SMALL_RIG), out, duration_s=0.5)
    return out


def _transforms(log: Path, topic: str) -> list[tuple[int, tuple[Transform, ...]]]:
    with open_log(log) as reader:
        return [
            (m.log_time_ns, decode(m, reader.deserialize).value)  # type: ignore[misc]
            for m in reader.messages(topics=[topic])
        ]


def _states(log: Path, topic: str) -> dict[int, VehicleState]:
    with open_log(log) as reader:
        out = {}
        for m in reader.messages(topics=[topic]):
            value = decode(m, reader.deserialize).value
            assert isinstance(value, VehicleState)
            out[value.stamp_ns] = value
        return out


def test_the_tree_is_map_odom_base_link_sensors(log: Path) -> None:
    (static,) = _transforms(log, "/tf_static")
    children = {t.child_frame for t in static[1]}
    assert {t.parent_frame for t in static[1]} == {"base_link"}
    assert "odom" not in children  # odometry is a frame its poses are in, not a mount
    assert {"lidar_top", "camera_front", "imu", "gnss", "lidar_2d"} <= children
    dynamic = _transforms(log, "/tf")
    assert len(dynamic) == 50  # twice the odometry rate (50 Hz), 0.5 s
    for _, transforms in dynamic:
        edges = {(t.parent_frame, t.child_frame) for t in transforms}
        assert edges == {("map", "odom"), ("odom", "base_link")}
    parents: dict[str, str] = {t.child_frame: t.parent_frame for t in static[1]}
    parents.update({t.child_frame: t.parent_frame for t in dynamic[0][1]})
    for frame in children:  # every sensor has one chain up to map
        chain = [frame]
        while chain[-1] in parents:
            chain.append(parents[chain[-1]])
        assert chain[-3:] == ["base_link", "odom", "map"], chain


def test_map_odom_base_link_composes_to_the_true_pose_and_odom_is_the_odometry(
    log: Path,
) -> None:
    truth = _states(log, "/ground_truth/ego_state")
    odometry = _states(log, "/odom")
    drifted = 0
    for stamp, transforms in _transforms(log, "/tf"):
        edge = {(t.parent_frame, t.child_frame): t for t in transforms}
        map_from_odom = matrix_from_transform(edge[("map", "odom")])
        odom_from_base = matrix_from_transform(edge[("odom", "base_link")])
        map_from_base = compose(map_from_odom, odom_from_base)
        state = truth[stamp]
        assert map_from_base[:3, 3] == pytest.approx(state.position, abs=1e-9)
        yaw = np.arctan2(map_from_base[1, 0], map_from_base[0, 0])
        assert np.remainder(yaw - state.heading_rad + np.pi, 2 * np.pi) - np.pi == pytest.approx(
            0.0, abs=1e-9
        )
        earlier = [t for t in odometry if t < stamp]
        if earlier:  # odom → base_link: the last wheel-odometry reading before this pose
            reading = odometry[max(earlier)]
            assert odom_from_base[:2, 3] == pytest.approx(reading.position[:2], abs=1e-9)
            drifted += not np.allclose(map_from_odom, np.eye(4), atol=1e-6)
    assert drifted > 10  # the odometry drifts, the correction is not the identity


def test_ros2_channels_offer_qos_and_tf_static_is_latched(log: Path) -> None:
    with log.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    for channel in summary.channels.values():
        qos = channel.metadata["offered_qos_profiles"]
        assert qos == (LATCHED_QOS if channel.topic == "/tf_static" else VOLATILE_QOS)
    assert "durability: 1" in LATCHED_QOS  # transient local
    assert "durability: 2" in VOLATILE_QOS  # volatile


def test_readers_still_find_the_ego_pose_and_the_mounts(log: Path) -> None:
    from redrive.assembly.frames import iter_frames

    with open_log(log) as reader:
        assert reader.capabilities.has_ego_pose
        frames = list(iter_frames(reader))
    assert frames
    assert all(f.vehicle_state is not None and f.vehicle_state.frame_id == "map" for f in frames)
    lidar = frames[0].sensors["lidar_top"]
    assert lidar.sensor_location == pytest.approx((1.2, 0.0, 1.9))
