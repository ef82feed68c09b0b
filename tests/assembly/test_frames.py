"""The Sensor Dispatcher: frames from real and written logs; the sensor map file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from redrive.assembly.frames import FrameAssembler, interpolate_state
from redrive.assembly.sensor_map import infer_sensor_map, load_sensor_map_overrides
from redrive.errors import ConfigError
from redrive.io import open_log
from redrive.testing.demo_log import write_demo_bag
from redrive.types import Image, PointCloud, SensorType, VehicleState


def test_frames_from_the_real_kitti_bag(shared_data: Path) -> None:
    bag = shared_data / "rosbag1_recorded_here/kitti_3frames_rosbag_record_lz4.bag"
    with open_log(bag) as log:
        frames = list(FrameAssembler(log).frames())
    assert [f.index for f in frames] == [0, 1, 2]
    lidar = "kitti_velo_pointcloud"
    assert [f.sensors[lidar].data.num_points for f in frames  # type: ignore[union-attr]
            ] == [115384, 120268, 126891]  # fmt: skip
    first = frames[0]
    cam = first.sensors["kitti_camera_color_left_image_raw"]
    assert cam.sensor_type is SensorType.CAMERA
    assert isinstance(cam.data, Image)
    assert cam.resolution == (1224, 370)
    # The camera sample attached is the one nearest the LiDAR stamp (within 50 ms).
    assert abs(cam.stamp_ns - first.stamp_ns) <= 50_000_000
    # The same picture through Image and CompressedImage (PNG): identical pixels.
    png = first.sensors["kitti_camera_color_left_image_raw_compressed"].data
    assert isinstance(png, Image)
    assert np.array_equal(png.pixels, cam.data.pixels)


def test_frames_from_the_kitti_folder_carry_ground_truth(shared_data: Path) -> None:
    with open_log(shared_data / "kitti_object") as log:
        frames = list(FrameAssembler(log).frames())
    assert len(frames) == 3
    assert frames[0].ground_truth is not None
    assert len(frames[0].ground_truth) == 1  # one pedestrian
    assert len(frames[1].ground_truth or ()) == 3  # truck, car, cyclist (DontCare skipped)


def test_vehicle_state_is_interpolated_to_the_lidar_stamp(tmp_path: Path) -> None:
    bag = write_demo_bag(tmp_path / "demo.bag", duration_s=2.0)
    with open_log(bag) as log:
        assembler = FrameAssembler(log)
        assert assembler.sensor_map.driver == "velodyne_points"
        assert assembler.sensor_map.vehicle_state_topic == "/odom"
        frames = list(assembler.frames())
    assert len(frames) == 20
    for frame in frames:
        state = frame.vehicle_state
        assert state is not None
        t_s = (frame.stamp_ns - 1_700_000_000_000_000_000) / 1e9
        assert state.position[0] == pytest.approx(5.0 * t_s, abs=1e-9)  # 5 m/s straight
        assert set(frame.sensors) == {"velodyne_points", "imu_data", "gnss_fix"}
        assert isinstance(frame.sensors["velodyne_points"].data, PointCloud)


def test_time_range_of_frames(tmp_path: Path) -> None:
    bag = write_demo_bag(tmp_path / "demo.bag", duration_s=2.0)
    with open_log(bag) as log:
        start = log.start_ns + 500_000_000
        stop = log.start_ns + 1_000_000_000
        frames = list(FrameAssembler(log).frames(start_ns=start, stop_ns=stop))
    assert len(frames) == 5
    assert frames[0].index == 0


def test_interpolate_state_takes_the_short_way_round() -> None:
    a = VehicleState(stamp_ns=0, heading_rad=np.pi - 0.1, position=[0.0, 0.0, 0.0])
    b = VehicleState(stamp_ns=100, heading_rad=-np.pi + 0.1, position=[10.0, 0.0, 0.0])
    mid = interpolate_state(a, b, 50)
    assert abs(abs(mid.heading_rad) - np.pi) < 1e-9
    assert mid.position[0] == pytest.approx(5.0)


def test_sensor_map_file_overrides_and_errors(tmp_path: Path) -> None:
    bag = write_demo_bag(tmp_path / "demo.bag", duration_s=0.5)
    good = tmp_path / "map.toml"
    good.write_text(
        'driver = "top"\ntolerance_ms = 20\nignore = ["/gnss/fix"]\n'
        '[sensors.top]\ntopic = "/velodyne_points"\nlocation = [1.0, 0.0, 1.8]\n'
    )
    with open_log(bag) as log:
        smap = infer_sensor_map(
            log.topics, duration_ns=log.end_ns - log.start_ns,
            overrides=load_sensor_map_overrides(good),
        )  # fmt: skip
        assert smap.driver == "top"
        assert smap.tolerance_ns == 20_000_000
        assert smap.sensor("top").location == (1.0, 0.0, 1.8)
        assert "/gnss/fix" not in {s.topic for s in smap.sensors}
        frame = next(iter(FrameAssembler(log, sensor_map=smap).frames()))
        assert frame.sensors["top"].sensor_location == (1.0, 0.0, 1.8)
    bad = tmp_path / "bad.toml"
    bad.write_text('[sensors.top]\ntopic = "/nope"\n')
    with open_log(bag) as log, pytest.raises(ConfigError, match="/nope"):
        infer_sensor_map(log.topics, duration_ns=1, overrides=load_sensor_map_overrides(bad))
    bad.write_text("drivr = 'x'\n")
    with pytest.raises(ConfigError, match="unknown key"):
        load_sensor_map_overrides(bad)


def _thin_gnss(src: Path, dst: Path, every: int) -> Path:
    """A copy of ``src`` keeping one GNSS fix in ``every`` (a slow input)."""
    from rosbags.rosbag1 import Reader, Writer

    kept = 0
    with Reader(src) as reader, Writer(dst) as writer:
        conns = {
            c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
            for c in reader.connections
        }
        for conn, stamp, raw in reader.messages():
            if conn.topic == "/gnss/fix":
                kept += 1
                if (kept - 1) % every:
                    continue
            writer.write(conns[conn.id], stamp, raw)
    return dst


def test_a_slow_input_gets_a_tolerance_of_half_its_period(tmp_path: Path) -> None:
    """GNSS at 2 Hz beside a 10 Hz LiDAR: by default its tolerance is half its period as the
    log's message count tells it, so the frames have the nearest fix; a sensor map's
    tolerance_ms holds for every input, and then 4 frames in 5 lack the fix, each saying so."""
    bag = _thin_gnss(
        write_demo_bag(tmp_path / "demo.bag", duration_s=2.0), tmp_path / "slow.bag", 5
    )
    with open_log(bag) as log:
        assembler = FrameAssembler(log)
        smap = assembler.sensor_map
        assert smap.tolerance_for("velodyne_points") == 50_000_000  # 10 Hz: the default
        rate = smap.sensor("gnss_fix").rate_hz  # (4 − 1) fixes over the log's ~2 s
        assert 1.4 < rate < 2.1
        assert smap.tolerance_for("gnss_fix") == round(0.5e9 / rate)
        frames = list(assembler.frames())
    assert len(frames) == 20
    # fixes at 0, 0.5, 1.0, 1.5 s: every frame up to 1.8 s is within the tolerance; the last
    # (1.9 s, 0.4 s after the last fix, the log ends) says it has none
    assert all("gnss_fix" in f.sensors for f in frames[:-1])
    assert all(f.missing == () for f in frames[:-1])
    assert frames[-1].missing == ("gnss_fix",)
    fixed = tmp_path / "map.toml"
    fixed.write_text("tolerance_ms = 50\n")
    with open_log(bag) as log:
        smap = infer_sensor_map(
            log.topics, duration_ns=log.end_ns - log.start_ns,
            overrides=load_sensor_map_overrides(fixed),
        )  # fmt: skip
        assert smap.tolerances_ns == {}
        frames = list(FrameAssembler(log, sensor_map=smap).frames())
    lacking = [f.index for f in frames if "gnss_fix" in f.missing]
    assert len(lacking) == 16
    assert all("gnss_fix" not in frames[i].sensors for i in lacking)


def test_ego_states_are_built_only_around_frames_and_equal_the_eager_ones(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from redrive.io.ros.decoders.motion import OdometryDecoder, PendingState

    bag = write_demo_bag(tmp_path / "demo.bag", duration_s=1.0)
    built: list[int] = []
    build = PendingState.decoded

    def counted(self: PendingState) -> object:
        built.append(id(self))
        return build(self)

    with monkeypatch.context() as patch:
        patch.setattr(PendingState, "decoded", counted)
        with open_log(bag) as log:
            lazy = [f.vehicle_state for f in FrameAssembler(log).frames()]
            n_odom = log.topics["/odom"].count
    with monkeypatch.context() as patch:
        patch.setattr(OdometryDecoder, "read_pending", lambda self, message: None)
        with open_log(bag) as log:
            eager = [f.vehicle_state for f in FrameAssembler(log).frames()]
    assert 0 < len(set(built)) < n_odom / 2  # 10 frames, 1 s of odometry
    assert len(lazy) == len(eager) == 10
    for a, b in zip(lazy, eager, strict=True):
        assert a is not None
        assert b is not None
        assert (a.stamp_ns, a.frame_id, a.heading_rad, a.yaw_rate_rad_s) == (
            b.stamp_ns,
            b.frame_id,
            b.heading_rad,
            b.yaw_rate_rad_s,
        )
        for name in ("position", "velocity", "acceleration"):
            assert getattr(a, name).tobytes() == getattr(b, name).tobytes()
