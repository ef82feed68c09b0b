"""A log format redrive does not know, added from a file outside the repository: one reader
class, one registration (``REDRIVE_READERS=path/to/toy_reader.py:ToyReader``), and ``redrive
info``, ``redrive run`` and ``redrive batch DIR`` all open it — the registry, not a folder name or a
file suffix, decides what a log is."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from redrive.results import RunStatus, open_run

REDRIVE = [sys.executable, "-m", "redrive"]

#: The whole plugin: a text log of LiDAR sweeps and ego poses, read into redrive's data model.
TOY_READER = textwrap.dedent(
    '''
    from __future__ import annotations

    from pathlib import Path

    import numpy as np

    from redrive.io import LogMessage, ReaderCapabilities, TopicInfo
    from redrive.io.ros.decoders import Decoded, DecodedKind
    from redrive.types import PointCloud, SensorType, VehicleState

    MAGIC = b"TOYLOG 1\\n"
    LIDAR, ODOM = "/toy/lidar", "/toy/odom"


    class ToyReader:
        """Lines ``stamp_ns speed_mps x y z x y z ...`` after the magic line."""

        format = "toy"
        description = "a toy text log (TOYLOG 1)"

        @classmethod
        def recognises(cls, path: Path) -> bool:
            if not path.is_file():
                return False
            with path.open("rb") as fh:
                return fh.read(len(MAGIC)) == MAGIC

        def __init__(self, path: Path, *, strict: bool = True) -> None:
            self.path = Path(path)
            lines = self.path.read_text().splitlines()[1:]
            self._rows = [[float(v) for v in line.split()] for line in lines if line.strip()]
            n = len(self._rows)
            self.topics = {
                LIDAR: TopicInfo(topic=LIDAR, msgtype="toy/Points", count=n, encoding="native",
                                 kind=DecodedKind.SENSOR, sensor_type=SensorType.LIDAR),
                ODOM: TopicInfo(topic=ODOM, msgtype="toy/Odom", count=n, encoding="native",
                                kind=DecodedKind.VEHICLE_STATE),
            }
            self.capabilities = ReaderCapabilities(
                message_typed=False, has_tf=False, has_ground_truth=False, has_ego_pose=True
            )

        @property
        def start_ns(self) -> int:
            return int(self._rows[0][0])

        @property
        def end_ns(self) -> int:
            return int(self._rows[-1][0])

        @property
        def message_count(self) -> int:
            return 2 * len(self._rows)

        def messages(self, *, topics=None, start_ns=None, stop_ns=None):
            for row in self._rows:
                stamp = int(row[0])
                if (start_ns is not None and stamp < start_ns) or (
                    stop_ns is not None and stamp >= stop_ns
                ):
                    continue
                speed = row[1]
                xyz = np.array(row[2:], dtype=np.float32).reshape(-1, 3)
                state = VehicleState(stamp_ns=stamp, position=np.array([speed * stamp / 1e9, 0, 0]),
                                     velocity=np.array([speed, 0.0, 0.0]))
                values = {
                    ODOM: Decoded(stamp_ns=stamp, frame_id="map", value=state),
                    LIDAR: Decoded(stamp_ns=stamp, frame_id="base_link", value=PointCloud(xyz=xyz)),
                }
                for topic, decoded in values.items():
                    if topics is None or topic in topics:
                        yield LogMessage(topic=topic, msgtype=self.topics[topic].msgtype,
                                         log_time_ns=stamp, encoding="native", payload=decoded)

        def deserialize(self, message):
            raise TypeError("native messages need no deserialising")

        def close(self) -> None:
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.close()
    '''
)


def _write_toy_log(path: Path, *, frames: int = 20) -> Path:
    rng = np.random.default_rng(7)
    lines = ["TOYLOG 1"]
    for i in range(frames):
        car = rng.normal([12.0, 0.0, 0.5], 0.3, size=(40, 3))  # something ahead to cluster
        ground = rng.uniform([-20, -20, -1.7], [20, 20, -1.6], size=(60, 3))
        points = np.concatenate([car, ground]).ravel()
        lines.append(" ".join([str(1_000_000_000 + i * 100_000_000), "5.0", *map(str, points)]))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def user(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """A user's folder (outside the repository) with the reader file; the env that names it."""
    (tmp_path / "toy_reader.py").write_text(TOY_READER)
    env = {**os.environ, "REDRIVE_READERS": f"{tmp_path / 'toy_reader.py'}:ToyReader"}
    return tmp_path, env


def _redrive(*args: str, cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*REDRIVE, *args],
        check=False,
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_info_run_and_batch_open_a_format_from_a_user_file(
    user: tuple[Path, dict[str, str]],
) -> None:
    folder, env = user
    drives = folder / "drives"
    drives.mkdir()
    first = _write_toy_log(drives / "monday.toy")
    _write_toy_log(drives / "tuesday.txt")  # the content decides, not the suffix
    (drives / "notes.md").write_text("not a log\n")

    info = _redrive("info", str(first), cwd=folder, env=env)
    assert info.returncode == 0, info.stderr
    assert "toy" in info.stdout
    assert "/toy/lidar" in info.stdout

    run = _redrive("run", str(first), "-o", "run", "--no-progress", cwd=folder, env=env)
    assert run.returncode == 0, run.stderr
    manifest = open_run(folder / "run").manifest
    assert manifest.status is RunStatus.COMPLETE
    assert manifest.log.format == "toy"
    assert open_run(folder / "run").table("frames").num_rows == 20

    batch = _redrive(
        "batch", str(drives), "-o", "batch", "--workers", "1", "--no-progress", cwd=folder, env=env
    )
    assert batch.returncode == 0, batch.stderr
    runs = sorted((folder / "batch" / "runs").glob("*/*/*/manifest.json"))
    logs = {json.loads(m.read_text())["log"]["path"] for m in runs}
    assert logs == {str(first.resolve()), str((drives / "tuesday.txt").resolve())}


def test_without_the_registration_batch_finds_no_log(user: tuple[Path, dict[str, str]]) -> None:
    folder, env = user
    drives = folder / "drives"
    drives.mkdir()
    _write_toy_log(drives / "monday.toy")
    env = {k: v for k, v in env.items() if k != "REDRIVE_READERS"}
    batch = _redrive("batch", str(drives), "-o", "batch", "--no-progress", cwd=folder, env=env)
    assert batch.returncode != 0
    assert "no logs in it" in batch.stderr
