"""The Argoverse 2 sensor log of ../shared/data read as a log: its poses, cuboids, calibration,
LiDAR sweeps and vector map, checked against the conventions of av2-api; damaged tables and maps
give errors that name the file, the element and the byte."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from pyarrow import feather

from redrive.errors import LogError, MapError
from redrive.io import open_log
from redrive.io.content import log_contents, log_road_map
from redrive.io.datasets.av2 import TOPIC_ANNOTATIONS, TOPIC_LIDAR, Av2SensorLogReader
from redrive.maps.index import RoadMapIndex
from redrive.types import DetectedObject, ObjectClass, PointCloud

LOG_ID = "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"


@pytest.fixture(scope="module")
def av2_log(shared_data: Path) -> Path:
    path = shared_data / "av2_sensor_val" / LOG_ID
    if not path.is_dir():
        pytest.skip("the Argoverse 2 log is not in ../shared/data")
    return path


def _copy(av2_log: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(av2_log, tmp_path / LOG_ID))


@pytest.mark.shared_data
def test_the_log_holds_156_annotated_sweeps_of_114_tracks(av2_log: Path) -> None:
    with open_log(av2_log) as log:
        assert log.format == "av2-sensor"
        contents = log_contents(log)
        assert contents["annotated sweeps"] == 156
        assert contents["tracks"] == 114
        assert contents["cuboids"] == 11364
        assert contents["lane segments"] == 183
        assert contents["drivable areas"] == 13
        assert contents["pedestrian crossings"] == 11
        assert log.topics[TOPIC_ANNOTATIONS].count == 156
        assert log.topics[TOPIC_LIDAR].count == 2
        gt = [m.payload.value for m in log.messages(topics=[TOPIC_ANNOTATIONS])]  # type: ignore[attr-defined]
    assert sum(len(objs) for objs in gt) == 11364
    ids = {o.object_id for objs in gt for o in objs}
    assert ids == set(range(114))  # tracks numbered in the order they first appear
    for objs in gt:
        assert len({o.object_id for o in objs}) == len(objs)


@pytest.mark.shared_data
def test_a_bollard_stands_still_in_the_city_frame(av2_log: Path) -> None:
    """Cuboids are in the ego frame of their sweep (av2-api): moved into the city frame by the
    sweep's ego pose, a bollard's centre must not move while the ego drives 75 m."""
    table = feather.read_table(av2_log / "annotations.feather").to_pydict()
    bollard = next(
        u for u, c in zip(table["track_uuid"], table["category"], strict=True) if c == "BOLLARD"
    )
    centres = []
    ego_path = []
    with Av2SensorLogReader(av2_log) as log:
        states = {m.log_time_ns: m.payload.value for m in log.messages(topics=["/ego_pose"])}  # type: ignore[attr-defined]
        bollard_id = _id_of(log, bollard)
        for message in log.messages(topics=[TOPIC_ANNOTATIONS]):
            objs: tuple[DetectedObject, ...] = message.payload.value  # type: ignore[attr-defined]
            state = states[message.log_time_ns]
            ego_path.append(state.position[:2])
            c, s = np.cos(state.heading_rad), np.sin(state.heading_rad)
            for o in objs:
                if o.object_class is ObjectClass.STATIC and o.object_id == bollard_id:
                    x, y = o.box.center[:2]
                    centres.append(state.position[:2] + np.array([c * x - s * y, c * y + s * x]))
                    assert np.linalg.norm(o.velocity) < 0.5
    assert len(centres) > 10
    spread = np.ptp(np.array(centres), axis=0)
    assert np.all(spread < 0.5), spread  # heading-only ego rotation: pitch/roll leave ~cm
    assert np.hypot(*(ego_path[-1] - ego_path[0])) > 50


def _id_of(log: Av2SensorLogReader, uuid: str) -> int:
    table = feather.read_table(log.path / "annotations.feather").to_pydict()
    rows = sorted(zip(table["timestamp_ns"], table["track_uuid"], strict=True))
    order: dict[str, int] = {}
    for _, u in rows:
        order.setdefault(u, len(order))
    return order[uuid]


@pytest.mark.shared_data
def test_the_sweeps_keep_every_point_and_field(av2_log: Path) -> None:
    with open_log(av2_log) as log:
        clouds = [m.payload for m in log.messages(topics=[TOPIC_LIDAR])]
    first = feather.read_table(sorted((av2_log / "sensors" / "lidar").glob("*.feather"))[0])
    cloud = clouds[0].value  # type: ignore[attr-defined]
    assert isinstance(cloud, PointCloud)
    assert clouds[0].frame_id == "base_link"  # type: ignore[attr-defined]
    assert len(cloud.xyz) == first.num_rows == 99229
    np.testing.assert_array_equal(cloud.xyz[:, 0], first["x"].to_numpy().astype(np.float32))
    np.testing.assert_array_equal(cloud.channels["ring"], first["laser_number"].to_numpy())
    np.testing.assert_array_equal(cloud.channels["t_offset_ns"], first["offset_ns"].to_numpy())


@pytest.mark.shared_data
def test_the_calibration_places_every_sensor(av2_log: Path) -> None:
    with open_log(av2_log) as log:
        (tf,) = [m.payload.value for m in log.messages(topics=["/tf_static"])]  # type: ignore[attr-defined]
    names = {t.child_frame for t in tf}
    assert {"up_lidar", "down_lidar", "ring_front_center"} <= names
    assert all(t.parent_frame == "base_link" for t in tf)


@pytest.mark.shared_data
def test_the_map_is_a_lane_graph_the_ego_drives_on(av2_log: Path) -> None:
    with open_log(av2_log) as log:
        road = log_road_map(log)
        states = [m.payload.value for m in log.messages(topics=["/ego_pose"])]  # type: ignore[attr-defined]
    assert road is not None
    assert len(road.lanes) == 183
    assert len(road.crosswalks) == 11
    assert len(road.areas) == 13
    assert road.source is not None
    assert road.source.startswith("av2:")
    assert {lane.kind for lane in road.lanes} == {"vehicle", "bike"}
    assert sum(len(lane.successors) for lane in road.lanes) > 150
    index = RoadMapIndex(road)
    xy = np.array([s.position[:2] for s in states])
    yaw = np.array([s.heading_rad for s in states])
    assert index.on_drivable_area(xy).all()
    lanes = index.lane_of_pose(xy, yaw)
    assert sum(lane is not None for lane in lanes) >= 0.9 * len(lanes)


@pytest.mark.shared_data
def test_a_cut_annotation_table_names_the_file_and_where_it_ends(
    av2_log: Path, tmp_path: Path
) -> None:
    log = _copy(av2_log, tmp_path)
    table = log / "annotations.feather"
    data = table.read_bytes()
    table.chmod(0o644)
    table.write_bytes(data[: len(data) // 2])
    with pytest.raises(
        LogError, match=rf"annotations\.feather: it ends at byte {len(data) // 2}.*cut off"
    ):
        open_log(log)


@pytest.mark.shared_data
def test_a_pose_table_without_a_column_says_which(av2_log: Path, tmp_path: Path) -> None:
    log = _copy(av2_log, tmp_path)
    path = log / "city_SE3_egovehicle.feather"
    path.chmod(0o644)
    feather.write_feather(feather.read_table(path).drop_columns(["qz"]), path)
    with pytest.raises(LogError, match=r"city_SE3_egovehicle\.feather: no column qz"):
        open_log(log)


@pytest.mark.shared_data
def test_a_damaged_map_is_named_and_the_rest_of_the_log_still_listed(
    av2_log: Path, tmp_path: Path
) -> None:
    log = _copy(av2_log, tmp_path)
    (path,) = (log / "map").glob("log_map_archive_*.json")
    doc = json.loads(path.read_text())
    lane_id = next(iter(doc["lane_segments"]))
    del doc["lane_segments"][lane_id]["right_lane_boundary"]
    path.chmod(0o644)
    path.write_text(json.dumps(doc))
    with open_log(log) as opened:
        with pytest.raises(MapError, match=rf"lane_segments\[{lane_id}\].*right_lane_boundary"):
            log_road_map(opened)
        contents = log_contents(opened)
    assert contents["annotated sweeps"] == 156
    assert str(contents["map"]).startswith("unreadable")


def test_a_folder_without_poses_is_not_an_av2_log(tmp_path: Path) -> None:
    (tmp_path / "calibration").mkdir()
    assert not Av2SensorLogReader.recognises(tmp_path)


@pytest.mark.shared_data
def test_frames_from_the_ground_truth_when_the_sweeps_are_not_all_there(av2_log: Path) -> None:
    """The LiDAR drives the frames (2 sweeps here); a sensor map's driver = "ground_truth"
    makes one of every annotated sweep, the sweeps present joining theirs."""
    from redrive.assembly.frames import FrameAssembler
    from redrive.assembly.sensor_map import SensorMapOverrides

    sweeps = sorted(int(p.stem) for p in (av2_log / "sensors" / "lidar").glob("*.feather"))
    with open_log(av2_log) as log:
        assert [f.stamp_ns for f in FrameAssembler(log).frames()] == sweeps
        overrides = SensorMapOverrides(driver="ground_truth", tolerance_ns=50_000_000)
        frames = list(FrameAssembler(log, overrides=overrides).frames())
    assert len(frames) == 156
    assert [f.stamp_ns for f in frames if f.sensors] == sweeps
    assert all(f.vehicle_state is not None and f.ground_truth for f in frames)


@pytest.mark.shared_data
def test_a_cut_sweep_ends_a_strict_read_and_is_skipped_otherwise(
    av2_log: Path, tmp_path: Path
) -> None:
    from redrive.errors import LogDamagedError

    log = _copy(av2_log, tmp_path)
    first, second = sorted((log / "sensors" / "lidar").glob("*.feather"))
    data = second.read_bytes()
    second.chmod(0o644)
    second.write_bytes(data[:1000])
    with (
        open_log(log) as strict,
        pytest.raises(LogDamagedError, match=rf"{second.name}: it ends at byte 1000") as err,
    ):
        list(strict.messages(topics=[TOPIC_LIDAR]))
    assert err.value.messages_read == 1
    with open_log(log, strict=False) as lenient:
        clouds = list(lenient.messages(topics=[TOPIC_LIDAR]))
        assert len(clouds) == 1
        assert lenient.damage is not None
        assert second.name in lenient.damage
    assert clouds[0].log_time_ns == int(first.stem)  # the intact sweep was read


@pytest.mark.shared_data
def test_camera_images_with_their_intrinsics(av2_log: Path, tmp_path: Path) -> None:
    from PIL import Image as PilImage

    from redrive.assembly.calibration import camera_info_topics
    from redrive.types import CameraInfo, Image

    log = _copy(av2_log, tmp_path)
    folder = log / "sensors" / "cameras" / "ring_front_center"
    folder.mkdir(parents=True)
    sweep = min(int(p.stem) for p in (log / "sensors" / "lidar").glob("*.feather"))
    stamps = [sweep + 5_000_000, sweep + 55_000_000]
    for stamp in stamps:
        PilImage.new("RGB", (1550, 2048), (40, 80, 120)).save(folder / f"{stamp}.jpg")
    intrinsics = feather.read_table(log / "calibration" / "intrinsics.feather").to_pydict()
    row = intrinsics["sensor_name"].index("ring_front_center")
    with open_log(log) as opened:
        image_topic, info_topic = (
            "/cameras/ring_front_center/image",
            "/cameras/ring_front_center/camera_info",
        )
        assert opened.topics[image_topic].count == 2
        assert camera_info_topics(opened.topics) == {image_topic: info_topic}
        messages = list(opened.messages(topics=[image_topic, info_topic]))
        assert log_contents(opened)["camera images present"] == 2
    assert [m.log_time_ns for m in messages] == [stamps[0], stamps[0], stamps[1], stamps[1]]
    info = messages[0].payload.value  # type: ignore[attr-defined]
    assert isinstance(info, CameraInfo)
    assert (info.width, info.height) == (1550, 2048)
    assert info.k[0, 0] == pytest.approx(intrinsics["fx_px"][row])
    assert info.k[1, 2] == pytest.approx(intrinsics["cy_px"][row])
    np.testing.assert_allclose(
        info.d, [intrinsics["k1"][row], intrinsics["k2"][row], 0, 0, intrinsics["k3"][row]]
    )
    image = messages[1].payload
    assert image.frame_id == "ring_front_center"  # type: ignore[attr-defined]
    assert isinstance(image.value, Image)
    assert image.value.pixels.shape == (2048, 1550, 3)
