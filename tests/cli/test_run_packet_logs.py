"""``redrive run`` on logs of raw LiDAR packets (issue 35 item 11): the detector gets the clouds
decoded from Velodyne scans and Ouster packets, frame by frame."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.results import RunStatus, open_run
from redrive.types import SensorType

LOGS = [
    # (log, frames, the sensor that drives them)
    ("ouster/512x10_raw.bag", 1, "os_node0_points"),
    ("velodyne_nebula_ros2/vlp16/1673400471837873222", 4, "velodyne_packets"),
    ("velodyne_nebula_ros2/vlp32/1713492677464078412", 5, "sensing_lidar_front_velodyne_packets"),
]


@pytest.mark.parametrize("case", LOGS, ids=[c[0] for c in LOGS])
def test_the_detector_runs_on_packet_clouds(
    shared_data: Path, tmp_path: Path, case: tuple[str, int, str]
) -> None:
    rel, frames, sensor = case
    out = tmp_path / "run"
    code = main(
        [
            "run",
            str(shared_data / rel),
            "--perception",
            "cluster-detector",
            "-o",
            str(out),
            "--no-progress",
        ]
    )
    assert code == 0
    run = open_run(out)
    assert run.manifest.status is RunStatus.COMPLETE
    assert run.table("frames").num_rows == frames
    assert run.table("detections").num_rows > 0  # clusters found in the decoded points
    steps = run.table("steps")
    assert set(steps.column("status").to_pylist()) == {"ok"}
    assert dict(run.manifest.sensors) == {sensor: SensorType.LIDAR}
    assert run.table("frames").column("missing_inputs").to_pylist() == [""] * frames


def test_a_one_frame_run_gives_no_real_time_factor(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The Ouster bag makes one frame: no log time passes, so "0.0x real time (0.0 s of log)"
    would say the run was infinitely slow; the summary says there is no factor instead."""
    bag = shared_data / "ouster" / "512x10_raw.bag"
    out = tmp_path / "run"
    argv = ["run", str(bag), "--perception", "cluster-detector", "-o", str(out), "--no-progress"]
    assert main(argv) == 0
    said = " ".join(capsys.readouterr().out.split())
    assert "x real time" not in said
    assert "one stamp of log, so no real-time factor" in said
