"""Recorded traffic through the CLI (issue 34 item 3): `redrive info` (table and --json) lists
what an Argoverse 2 log, a Waymo Open Motion scenario and a CommonRoad scenario hold, and
`redrive run` replays each open loop with the reference stages its inputs allow."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.results import RunStatus, open_run

pytestmark = pytest.mark.shared_data

AV2 = "av2_sensor_val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede"
WOMD = "womd/motion_data_one_scenario.tfrecord"
COMMONROAD = "commonroad/USA_Peach-4_8_T-1.xml"
_HAS_COMMONROAD = importlib.util.find_spec("commonroad") is not None


def _path(shared_data: Path, rel: str) -> Path:
    path = shared_data / rel
    if not path.exists():
        pytest.skip(f"{rel} is not in ../shared/data")
    if rel == COMMONROAD and not _HAS_COMMONROAD:
        pytest.skip("commonroad-io is not installed")
    return path


_MAP_LANES = {AV2: 183, WOMD: 198, COMMONROAD: 79}


@pytest.mark.parametrize(
    ("rel", "fmt", "expected"),
    [
        (AV2, "av2-sensor", {"annotated sweeps": 156, "tracks": 114, "lane segments": 183}),
        (WOMD, "womd", {"agents": 83, "steps": 91, "SDC": "track 2406 (index 82)"}),
        (COMMONROAD, "commonroad", {"dynamic obstacles": 9, "lanelets": 79}),
    ],
)
def test_info_lists_the_content_and_the_map(
    shared_data: Path,
    capsys: pytest.CaptureFixture[str],
    rel: str,
    fmt: str,
    expected: dict[str, object],
) -> None:
    path = _path(shared_data, rel)
    assert main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == fmt
    assert expected.items() <= info["contents"].items()
    assert info["capabilities"]["road_map"]
    assert info["capabilities"]["has_ground_truth"]
    lanes = _MAP_LANES[rel]
    assert info["map"]["lanes"] == lanes
    assert info["map"]["source"].startswith(fmt.split("-", maxsplit=1)[0] + ":")
    assert main(["info", str(path)]) == 0
    table = capsys.readouterr().out
    assert f"map lanes:     {lanes} (" in table
    for name, value in expected.items():
        line = f"{value} {name}" if isinstance(value, int) else f"{name}: {value}"
        assert f"contains:  {line}" in table


@pytest.mark.parametrize(
    ("rel", "frames", "algorithms"),
    [
        (AV2, 2, {"clusters", "tracker", "planner", "controller"}),  # 2 of 156 sweeps present
        (WOMD, 91, {"oracle", "tracker", "planner", "controller"}),
        (COMMONROAD, 61, {"oracle", "tracker"}),  # the ego's start only: nothing to plan from
    ],
)
def test_run_replays_open_loop(
    shared_data: Path, tmp_path: Path, rel: str, frames: int, algorithms: set[str]
) -> None:
    path = _path(shared_data, rel)
    out = tmp_path / "run"
    assert main(["run", str(path), "-o", str(out), "--no-progress"]) == 0
    run = open_run(out)
    assert run.manifest.status is RunStatus.COMPLETE
    assert run.table("frames").num_rows == frames
    steps = run.table("steps").to_pydict()
    assert set(steps["algorithm"]) == algorithms
    assert set(steps["status"]) == {"ok"}


def test_closed_loop_on_a_scenario_without_sensors_is_paced_by_its_ground_truth(
    shared_data: Path, tmp_path: Path
) -> None:
    path = _path(shared_data, WOMD)
    out = tmp_path / "loop"
    args = ["run", str(path), "--closed-loop", "--planning", "idm-planner", "-o", str(out)]
    assert main([*args, "--no-progress"]) == 0
    run = open_run(out)
    assert run.manifest.status is RunStatus.COMPLETE
    assert run.table("frames").num_rows == 90  # of the 91 steps (as redrive counts a log replay)


def test_the_gui_session_steps_through_a_scenario_without_sensors(shared_data: Path) -> None:
    from redrive.gui.session import LogSession

    session = LogSession(_path(shared_data, WOMD))
    try:
        assert session.driver_topic == "/objects"
        assert list(session.index())[-1] == session.expected_frames == 91
        frame = session.frame(50)
    finally:
        session.close()
    assert frame.vehicle_state is not None
    assert frame.ground_truth
    assert frame.traffic.traffic_lights
