"""The CLI as a user runs it: `redrive info`, `python -m redrive`, --help texts."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.testing.demo_log import write_demo_bag


def test_info_json_on_a_real_bag(shared_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = shared_data / "rosbag1_real/robot_localization_test1_husky.bag"
    assert main(["info", str(bag), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "ros1"
    assert info["messages"] == 16806
    topics = {t["topic"]: t for t in info["topics"]}
    assert topics["/imu/data"]["count"] == 11865
    assert topics["/imu/data"]["decoder"] == "imu"
    assert topics["/fix"]["type"] == "sensor_msgs/msg/NavSatFix"
    assert topics["/husky_velocity_controller/odom"]["maps_to"] == "vehicle state"
    assert 390 < info["duration_s"] < 400  # "395 s"
    assert 25 < topics["/imu/data"]["rate_hz"] < 35
    assert info["capabilities"] == {
        "message_typed": True,
        "has_tf": False,
        "has_ground_truth": False,
        "has_ego_pose": True,
        "calibration_per_frame": False,
        "road_map": False,
        "traffic_lights": False,
    }


def test_info_table_on_kitti(shared_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(shared_data / "kitti_object")]) == 0
    out = capsys.readouterr().out
    assert "kitti" in out
    assert "driver" in out
    assert "provides:  tf, ground truth, native values, a calibration per frame" in out
    assert "redrive/PointCloud" in out


def test_info_reports_damage_and_exit_status(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_demo_bag(tmp_path / "demo.bag", duration_s=1.0)
    cut = tmp_path / "cut.bag"
    cut.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    assert main(["info", str(cut), "--json"]) == 5  # damaged: read past it (docs/exit_status.md)
    info = json.loads(capsys.readouterr().out)
    assert "cut off" in info["damage"]
    assert info["messages"] > 0
    cut_at = [d for d in info["damage_report"] if d["start_byte"] is not None]
    assert cut_at
    assert cut_at[-1]["stop_byte"] == cut.stat().st_size
    assert main(["info", str(cut), "--strict"]) == 1
    err = capsys.readouterr().err
    assert "cut.bag" in err
    assert "--strict" in err
    assert "Traceback" not in err


def test_bad_input_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "empty.bag").write_bytes(b"")
    assert main(["info", str(tmp_path / "empty.bag")]) == 1
    err = capsys.readouterr().err
    assert "redrive: error:" in err
    assert "empty.bag" in err
    assert "Traceback" not in err


def test_python_dash_m_and_help_texts() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "redrive", "--help"], capture_output=True, text=True, check=True
    ).stdout
    assert "info" in out
    assert "convert" in out
    for command in ("info", "convert"):
        text = subprocess.run(
            [sys.executable, "-m", "redrive", command, "--help"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        assert "examples:" in text


def test_convert_then_info(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = write_demo_bag(tmp_path / "demo.bag", duration_s=1.0)
    out = tmp_path / "demo.mcap"
    assert main(["convert", str(bag), str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "mcap"
    assert {t["topic"]: t["count"] for t in info["topics"]} == {
        "/gnss/fix": 10,
        "/imu/data": 100,
        "/odom": 50,
        "/velodyne_points": 10,
    }


def test_convert_a_cut_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = write_demo_bag(tmp_path / "demo.bag", duration_s=1.0)
    cut = tmp_path / "cut.bag"
    cut.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    out = tmp_path / "saved.mcap"
    assert main(["convert", str(cut), str(out)]) == 1  # strict: stops at the damage
    assert "--skip-damaged" in capsys.readouterr().err
    assert not out.exists()  # no half-written output
    assert main(["convert", str(cut), str(out), "--skip-damaged"]) == 0
    assert out.exists()
