"""The reader registry: formats recognised by content, capabilities asked instead of format names,
and a reader plugin (entry-point group redrive.readers) that open_log uses like a built-in one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from redrive.errors import LogError
from redrive.io import detect_format, open_log, reader_formats
from redrive.io.readers import reader_format, reload_readers
from redrive.io.ros.decoders import DecodedKind, decode, topic_kind
from redrive.types import PointCloud, SensorType
from tests.algorithms.test_discovery import site, unique, write_dist  # noqa: F401 (fixture)

CAPABILITIES = [
    # path, has_tf, has_ground_truth, has_ego_pose
    ("rosbag_fixtures/evo_nav2_turtlebot_sim.mcap", True, False, True),
    ("rosbag_fixtures/evo_tf_example_ros2", True, False, False),
    ("velodyne_nebula_ros2/vlp16/1673400471837873222", False, False, False),
    ("rosbag1_real/robot_localization_test1_husky.bag", False, False, True),
]


@pytest.mark.parametrize(("rel", "tf", "gt", "ego"), CAPABILITIES, ids=[c[0] for c in CAPABILITIES])
def test_capabilities_of_real_logs(
    shared_data: Path, rel: str, tf: bool, gt: bool, ego: bool
) -> None:
    with open_log(shared_data / rel) as log:
        caps = log.capabilities
        assert caps.message_typed
        assert not caps.calibration_per_frame
        assert (caps.has_tf, caps.has_ground_truth, caps.has_ego_pose) == (tf, gt, ego)


def test_builtin_formats_and_their_names() -> None:
    assert [cls.format for cls in reader_formats()][:11] == [
        "ros2",
        "kitti",
        "nuscenes",
        "nuscenes-mmdet3d",
        "kitti-mmdet3d",
        "ros1",
        "mcap",
        "mcap-set",
        "av2-sensor",
        "womd",
        "commonroad",
    ]
    assert all(cls.description for cls in reader_formats())
    with pytest.raises(LogError, match=r"no reader for format 'ros2-sqlite3'; redrive reads ros2"):
        reader_format("ros2-sqlite3")


def test_a_ros2_bag_by_directory_metadata_or_db3(shared_data: Path) -> None:
    bag = shared_data / "rosbag_fixtures/evo_tf_example_ros2"
    db3 = next(bag.glob("*.db3"))
    for path in (bag, bag / "metadata.yaml", db3):
        assert detect_format(path) == "ros2"
        with open_log(path) as log:
            assert log.path == bag
            assert log.format == "ros2"
            assert log.storage == "sqlite3"  # type: ignore[attr-defined]


def test_not_a_log_lists_what_redrive_reads(tmp_path: Path) -> None:
    junk = tmp_path / "notes.bag"
    junk.write_text("hello")
    with pytest.raises(
        LogError, match=r"notes\.bag: not a log redrive reads \(starts with b'hello'\)"
    ):
        detect_format(junk)
    with pytest.raises(LogError, match=r"kitti: a KITTI.*ros1: a ROS 1 bag"):
        open_log(junk)
    (tmp_path / "empty").mkdir()
    with pytest.raises(LogError, match="this directory is not a log"):
        open_log(tmp_path / "empty")


XYZ_READER = '''
from pathlib import Path
from types import MappingProxyType

import numpy as np

from redrive.io.base import DecodedKind, LogMessage, ReaderCapabilities, TopicInfo
from redrive.io.ros.decoders import Decoded
from redrive.types import PointCloud, SensorType

MAGIC = b"#XYZLOG 1\\n"


class XyzLog:
    """A text log: a magic line, then one scan per line: stamp_ns x y z x y z ..."""

    format = "xyz"
    description = "an XYZ text log (#XYZLOG 1)"

    @classmethod
    def recognises(cls, path: Path) -> bool:
        if not path.is_file():
            return False
        with path.open("rb") as fh:
            return fh.read(len(MAGIC)) == MAGIC

    def __init__(self, path: Path, *, strict: bool = True) -> None:
        self.path = Path(path)
        lines = self.path.read_text().splitlines()[1:]
        self._scans = [[float(v) for v in line.split()] for line in lines if line.strip()]
        self._topics = MappingProxyType({"/xyz": TopicInfo(
            topic="/xyz", msgtype="xyz/Scan", count=len(self._scans), encoding="native",
            kind=DecodedKind.SENSOR, sensor_type=SensorType.LIDAR)})

    @property
    def capabilities(self) -> ReaderCapabilities:
        return ReaderCapabilities(
            message_typed=False, has_tf=False, has_ground_truth=False, has_ego_pose=False
        )

    @property
    def topics(self):
        return self._topics

    @property
    def start_ns(self) -> int:
        return int(self._scans[0][0])

    @property
    def end_ns(self) -> int:
        return int(self._scans[-1][0])

    @property
    def message_count(self) -> int:
        return len(self._scans)

    def messages(self, *, topics=None, start_ns=None, stop_ns=None):
        for row in self._scans:
            stamp = int(row[0])
            if (start_ns is not None and stamp < start_ns) or (stop_ns is not None and stamp >= stop_ns):
                continue
            xyz = np.asarray(row[1:], dtype=np.float32).reshape(-1, 3)
            cloud = PointCloud(xyz=xyz)
            yield LogMessage(topic="/xyz", msgtype="xyz/Scan", log_time_ns=stamp,
                             encoding="native",
                             payload=Decoded(stamp_ns=stamp, frame_id="lidar", value=cloud))

    def deserialize(self, message):
        raise NotImplementedError("native")

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
'''


def test_a_reader_plugin_opens_its_format(site: Path, tmp_path: Path) -> None:  # noqa: F811
    pkg = unique("xyzpkg")
    write_dist(
        site,
        unique("xyz-reader"),
        entry_points={"xyz": f"{pkg}.reader:XyzLog"},
        modules={f"{pkg}/reader.py": XYZ_READER},
        group="redrive.readers",
    )
    log_path = tmp_path / "drive.txt"
    log_path.write_text("#XYZLOG 1\n100 1 2 3 4 5 6\n200 7 8 9\n")
    reload_readers()
    try:
        assert [cls.format for cls in reader_formats()][-1] == "xyz"
        assert detect_format(log_path) == "xyz"
        with open_log(log_path) as log:
            assert log.format == "xyz"
            assert not log.capabilities.message_typed
            assert topic_kind(log.topics["/xyz"]) == (DecodedKind.SENSOR, SensorType.LIDAR)
            clouds = [decode(m, log.deserialize).value for m in log.messages()]
        assert isinstance(clouds[0], PointCloud)
        np.testing.assert_array_equal(clouds[1].xyz, [[7, 8, 9]])
    finally:
        reload_readers()


def test_what_recognising_found_reaches_the_constructor(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reader with ``recognised(path)`` gets its value as ``recognised=``; one without gets no
    such keyword; ``recognised`` returning None means "not this format"."""
    from redrive.io import readers

    seen: list[object] = []

    class Probing:
        format, description = "probing", "a file starting with PROBE"

        @classmethod
        def recognised(cls, path: Path) -> tuple[str, bytes] | None:
            head = path.read_bytes()[:5]
            return ("head", head) if head == b"PROBE" else None

        @classmethod
        def recognises(cls, path: Path) -> bool:
            return cls.recognised(path) is not None

        def __init__(self, path: Path, *, strict: bool = True, recognised: object = None) -> None:
            seen.append(recognised)

        def __enter__(self) -> Probing:
            return self

        def __exit__(self, *exc: object) -> None:
            pass

    class Plain:
        format, description = "plain", "a file starting with PLAIN"

        @classmethod
        def recognises(cls, path: Path) -> bool:
            return path.read_bytes()[:5] == b"PLAIN"

        def __init__(self, path: Path, *, strict: bool = True) -> None:
            seen.append("plain")

    monkeypatch.setattr(readers, "reader_formats", lambda: (Probing, Plain))
    probed, plain, neither = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    probed.write_bytes(b"PROBE 1")
    plain.write_bytes(b"PLAIN 1")
    neither.write_bytes(b"OTHER 1")
    open_log(probed, packets="raw")
    open_log(plain, packets="raw")
    assert seen == [("head", b"PROBE"), "plain"]
    assert detect_format(probed) == "probing"
    assert readers.recognised_format(plain) == "plain"
    assert readers.recognised_format(neither) is None
    with pytest.raises(LogError, match="not a log redrive reads"):
        open_log(neither)
