"""redrive synth: scenario → MCAP, read back through redrive.io like any recorded log."""

from __future__ import annotations

import dataclasses
import hashlib
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.assembly.frames import iter_frames
from redrive.cli.main import main
from redrive.errors import SimulationError
from redrive.geometry import points_in_box, transform_points
from redrive.io import open_log
from redrive.sim.rig import rig_from_mapping
from redrive.sim.scenario import Scenario, load_scenario
from redrive.sim.synth import synthesize
from redrive.types import Box3D, ObjectClass, PointCloud

# A small rig keeps the tests fast: every sensor kind, a 16-beam LiDAR and a small camera.
SMALL_RIG: dict[str, Any] = {
    "lidar_top": {"kind": "lidar", "preset": "VLP-16", "xyz": [1.2, 0.0, 1.9], "rate_hz": 10},
    "camera_front": {
        "kind": "camera",
        "xyz": [1.5, 0.0, 1.6],
        "rate_hz": 5,
        "width": 320,
        "height": 180,
        "fx": 250.0,
        "fy": 250.0,
    },
    "imu": {"kind": "imu", "xyz": [0.0, 0.0, 0.5], "rate_hz": 100},
    "gnss": {"kind": "gnss", "xyz": [0.0, 0.0, 1.8], "rate_hz": 10},
    "odom": {"kind": "odometry", "rate_hz": 50},
    "lidar_2d": {"kind": "lidar_2d", "preset": "UTM-30LX", "xyz": [3.7, 0.0, 0.5], "rate_hz": 20},
}


def _small(name: str, rig: dict[str, Any] | None = None) -> Scenario:
    return dataclasses.replace(load_scenario(name), rig=rig or SMALL_RIG)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_same_seed_same_bytes_other_seed_differs(tmp_path: Path) -> None:
    scenario = _small("urban")
    a = synthesize(scenario, tmp_path / "a.mcap", duration_s=1.0)
    b = synthesize(scenario, tmp_path / "b.mcap", duration_s=1.0)
    c = synthesize(scenario, tmp_path / "c.mcap", duration_s=1.0, seed=scenario.seed + 1)
    assert _sha256(a.path) == _sha256(b.path)
    assert _sha256(a.path) != _sha256(c.path)
    assert a.messages > 300


def test_log_reads_back_as_frames_with_ground_truth(tmp_path: Path) -> None:
    scenario = _small("urban")
    synthesize(scenario, tmp_path / "u.mcap", duration_s=1.5)
    rig = rig_from_mapping(SMALL_RIG, source="test")
    base_from_lidar = rig["lidar_top"].base_from_sensor()
    with open_log(tmp_path / "u.mcap") as log:
        assert log.topics["/lidar_top"].count == 15
        assert log.topics["/camera_front/image_raw"].count == 8
        assert log.topics["/imu"].count == 150
        assert log.topics["/lidar_2d"].msgtype == "sensor_msgs/msg/LaserScan"
        frames = list(iter_frames(log))
    assert len(frames) == 15  # driven by the 3D LiDAR, one frame per sweep
    checked = 0
    for frame in frames:
        assert frame.vehicle_state is not None
        assert frame.ground_truth
        cloud = frame.sensors["lidar_top"].data
        assert isinstance(cloud, PointCloud)
        assert set(cloud.channels) == {"intensity", "ring", "t_offset_ns"}
        pts = transform_points(base_from_lidar, cloud.xyz.astype(np.float64))
        speed_mps = float(np.linalg.norm(frame.vehicle_state.velocity))
        for obj in frame.ground_truth:
            assert obj.num_lidar_points is not None
            assert obj.visible is not None
            if obj.visible:
                assert obj.num_lidar_points > 0 or obj.object_class is not None
            if obj.num_lidar_points >= 20:
                # The returns counted for the object lie in its box (at the sweep start), grown
                # by the ego's travel within the 0.1 s sweep (points are in the sensor frame at
                # their firing time: the skew) and the range noise.
                margin = 2 * (speed_mps * 0.1 + 0.1)
                grown = Box3D(
                    center=obj.box.center, size=obj.box.size + margin, yaw_rad=obj.box.yaw_rad
                )
                inside = int(points_in_box(pts, grown).sum())
                assert inside >= 0.9 * obj.num_lidar_points
                checked += 1
    assert checked > 5


def test_pedestrian_is_invisible_behind_the_van_then_visible(tmp_path: Path) -> None:
    lidar_only = {"lidar_top": SMALL_RIG["lidar_top"]}
    synthesize(_small("pedestrian_from_occlusion", lidar_only), tmp_path / "p.mcap")
    with open_log(tmp_path / "p.mcap") as log:
        frames = list(iter_frames(log))
    seen = []
    for frame in frames:
        peds = [o for o in frame.ground_truth or () if o.object_class is ObjectClass.PEDESTRIAN]
        if peds:
            (ped,) = peds
            seen.append(bool(ped.visible))
    assert seen, "the pedestrian is never within ground-truth range"
    first_visible = seen.index(True)
    # Hidden behind the van for a while once in range, then seen for good as it steps out.
    assert first_visible >= 5
    assert not any(seen[:first_visible])
    assert sum(seen[first_visible:]) >= 0.8 * len(seen[first_visible:])


def test_cli_synth_writes_a_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario_file = tmp_path / "mine.toml"
    text = resources.files("redrive.sim").joinpath("scenarios/red_light.toml").read_text()
    # a user's copy with a smaller rig: drop the catalogue's rig, add one LiDAR
    text = text.split("[rig.")[0] + (
        '[rig.lidar_top]\nkind = "lidar"\npreset = "VLP-16"\nxyz = [1.2, 0.0, 1.9]\nrate_hz = 10\n'
    )
    scenario_file.write_text(text)
    out = tmp_path / "mine.mcap"
    assert main(["synth", str(scenario_file), "--duration", "0.5", "-o", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    with open_log(out) as log:
        assert log.topics["/lidar_top"].count == 5
    assert main(["synth", "--list"]) == 0
    assert "pedestrian_from_occlusion" in capsys.readouterr().out


def test_cli_synth_refuses_an_output_that_is_not_mcap(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.txt"
    assert main(["synth", "urban", "--duration", "0.2", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{out}: synth writes an MCAP log, so OUT must end in .mcap" in err
    assert "-o " + str(tmp_path / "x.mcap") in err
    assert not out.exists()


def test_bad_duration_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SimulationError, match="duration"):
        synthesize(_small("urban"), tmp_path / "x.mcap", duration_s=0.0)
    assert not (tmp_path / "x.mcap").exists()


def test_every_message_decodes_with_an_independent_ros2_reader(tmp_path: Path) -> None:
    """mcap-ros2-support (what Foxglove-style tools use) parses every schema and message."""
    decoder = pytest.importorskip("mcap_ros2.decoder")
    from mcap.reader import make_reader

    synthesize(_small("urban"), tmp_path / "u.mcap", duration_s=0.5)
    counts: dict[str, int] = {}
    with (tmp_path / "u.mcap").open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[decoder.DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/ground_truth/objects":
                assert len(msg.detections) == len(msg.num_lidar_points) == len(msg.visible)
            if channel.topic == "/lidar_2d":
                assert len(msg.ranges) == 1081  # UTM-30LX: 270° in 0.25° steps
    assert counts["/lidar_top"] == 5
    assert counts["/imu"] == 50
