"""A rosbag2 sqlite3 bag with a damaged page: only the rows on it are lost (issue 37).

rosbags cannot open such a database (its open counts the rows of the whole messages table);
redrive reads its rows one by one by id. What SQLite itself still reads, row by row, is what
``open_log(strict=False)``, ``redrive info``, ``run`` and ``repair`` must read.
"""

from __future__ import annotations

import shutil
import sqlite3
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_typestore

from redrive.cli.main import main
from redrive.errors import LogDamagedError
from redrive.io import open_log
from redrive.io.repair import repair_log

_EXIT_DAMAGED = 5


def _write_cloud_bag(path: Path, *, messages: int = 60, points: int = 64) -> None:
    """A ROS 2 sqlite3 bag of PointCloud2 at 10 Hz (a message or so per page)."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    t: Any = store.types
    fields = [
        t["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=7, count=1)
        for n, o in (("x", 0), ("y", 4), ("z", 8), ("intensity", 12))
    ]
    msgtype = "sensor_msgs/msg/PointCloud2"
    rng = np.random.default_rng(7)
    with Ros2Writer(path, version=8, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conn = writer.add_connection("/points", msgtype, typestore=store)
        for i in range(messages):
            stamp = 1_000_000_000 + i * 100_000_000
            xyz = rng.uniform(-20, 20, (points, 4)).astype(np.float32)
            header = t["std_msgs/msg/Header"](
                stamp=t["builtin_interfaces/msg/Time"](sec=stamp // 10**9, nanosec=stamp % 10**9),
                frame_id="lidar",
            )
            cloud = t[msgtype](
                header=header,
                height=1,
                width=points,
                fields=fields,
                is_bigendian=False,
                point_step=16,
                row_step=16 * points,
                data=xyz.view(np.uint8).reshape(-1),
                is_dense=True,
            )
            writer.write(conn, stamp, store.serialize_cdr(cloud, msgtype))


def _page_size(data: bytes) -> int:
    (size,) = struct.unpack_from(">H", data, 16)
    return 65536 if size == 1 else size


def _damage_middle_leaf(db: Path) -> None:
    """Overwrite the table-leaf page in the middle of the database (a page of message rows)."""
    data = bytearray(db.read_bytes())
    size = _page_size(data)
    leaves = [p for p in range(1, len(data) // size) if data[p * size] == 0x0D]
    page = leaves[len(leaves) // 2]
    data[page * size : (page + 1) * size] = b"\xa5" * size
    db.write_bytes(bytes(data))


def _readable_rows(db: Path) -> dict[int, bytes]:
    """What SQLite itself still reads of the messages table, row by row: id → data."""
    con = sqlite3.connect(f"file:{db}?mode=ro&immutable=1", uri=True)
    out = {}
    for mid in range(1, 10_000):
        try:
            row = con.execute("SELECT data FROM messages WHERE id = ?", (mid,)).fetchone()
        except sqlite3.DatabaseError:
            continue
        if row is not None:
            out[mid] = bytes(row[0])
    con.close()
    return out


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    for path in [dst, *dst.iterdir()]:
        path.chmod(0o755 if path.is_dir() else 0o644)
    return dst


@pytest.fixture
def damaged_bag(tmp_path: Path) -> tuple[Path, list[bytes]]:
    """A damaged bag and the data of every message of it before the damage, in time order."""
    bag = tmp_path / "bag"
    _write_cloud_bag(bag)
    with RosbagsReader(bag) as reader:
        original = [bytes(raw) for _, _, raw in reader.messages()]
    _damage_middle_leaf(next(bag.glob("*.db3")))
    return bag, original


def test_a_damaged_page_loses_only_its_rows(damaged_bag: tuple[Path, list[bytes]]) -> None:
    bag, original = damaged_bag
    readable = _readable_rows(next(bag.glob("*.db3")))
    assert 0 < len(readable) < len(original)
    with pytest.raises(Exception, match="malformed"), RosbagsReader(bag):  # rosbags: refused
        pass
    with open_log(bag, strict=False) as log:
        got = [bytes(m.raw) for m in log.messages()]
        damage = log.damage_report  # type: ignore[attr-defined]
    assert got == [raw for raw in original if raw in readable.values()]  # in time order
    assert len(got) == len(readable)
    assert sum(d.messages_lost for d in damage) == len(original) - len(readable)
    assert all(d.message_index is not None for d in damage)
    with open_log(bag) as log, pytest.raises(LogDamagedError, match="unreadable"):
        for _ in log.messages():
            pass


def test_cli_info_run_and_repair_read_the_intact_rows(
    damaged_bag: tuple[Path, list[bytes]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    bag, original = damaged_bag
    readable = len(_readable_rows(next(bag.glob("*.db3"))))
    assert main(["info", str(bag)]) == _EXIT_DAMAGED
    said = capsys.readouterr().out
    assert f"messages:  {readable} " in said
    assert f"{len(original) - readable} messages lost" in said
    assert main(["info", str(bag), "--strict"]) == 1
    capsys.readouterr()
    out = tmp_path / "run"
    main(["run", str(bag), "--perception", "cluster-detector", "-o", str(out), "--no-progress"])
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err
    from redrive.results import open_run

    assert open_run(out).table("frames").num_rows == readable
    stats = repair_log(bag, tmp_path / "fixed.mcap")
    assert stats.messages_written == readable
    with open_log(tmp_path / "fixed.mcap") as log:
        assert [bytes(m.raw) for m in log.messages()] == [
            raw for raw in original if raw in _readable_rows(next(bag.glob("*.db3"))).values()
        ]


@pytest.mark.parametrize(
    "name",
    ["rosbag_fixtures/evo_tf_example_ros2", "velodyne_nebula_ros2/vlp16/1673400471837873222"],
)
def test_real_ros2_bags_with_a_damaged_page(shared_data: Path, tmp_path: Path, name: str) -> None:
    bag = _copy(shared_data / name, tmp_path / "bag")
    db = next(bag.glob("*.db3"))
    with RosbagsReader(bag) as reader:
        total = reader.message_count
    data = bytearray(db.read_bytes())
    size = _page_size(data)
    middle = len(data) // size // 2 - 1  # a page of message rows (or of a row's overflow)
    data[middle * size : (middle + 1) * size] = b"\xa5" * size
    db.write_bytes(bytes(data))
    readable = _readable_rows(db)
    assert len(readable) < total  # the page held message bytes
    with open_log(bag, strict=False) as log:
        got = sorted(bytes(m.raw) for m in log.messages())
        damage = log.damage_report  # type: ignore[attr-defined]
    assert got == sorted(readable.values())
    assert sum(d.messages_lost for d in damage) == total - len(readable)
    stats = repair_log(bag, tmp_path / "fixed.mcap")
    assert stats.messages_written == len(readable)
