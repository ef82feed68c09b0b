"""Clouds with NaN / ±inf points are counted per topic and said once (issue 37): a warning with
the count and fraction, the run's summary (``non_finite_points``) and ``redrive run``'s report;
the points reach the algorithms unchanged."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest

from redrive.assembly.non_finite import (
    NON_FINITE_WARN_FRACTION,
    NonFiniteCounter,
    non_finite_points,
)
from redrive.cli.main import main
from redrive.types import PointCloud
from tests.hostile.generator import inject_non_finite

KITTI_BAG = "rosbag1_recorded_here/kitti_3frames_rosbag_record_lz4.bag"
CLOUD_TOPIC = "/kitti/velo/pointcloud"


def _cloud(n: int, bad: int) -> PointCloud:
    xyz = np.ones((n, 3), dtype=np.float32)
    xyz[:bad:3, 0] = np.nan
    xyz[1:bad:3, 1] = np.inf
    xyz[2:bad:3, 2] = -np.inf
    return PointCloud(xyz=xyz)


def test_non_finite_points_are_counted_exactly() -> None:
    assert non_finite_points(_cloud(100, 0)) == 0
    assert non_finite_points(_cloud(100, 67)) == 67
    assert non_finite_points(_cloud(100, 100)) == 100
    assert non_finite_points(PointCloud(xyz=np.zeros((0, 3), dtype=np.float32))) == 0
    for at in (0, 1, 6, 7, 8, 9999):  # one bad point anywhere, in any coordinate, strided
        for axis in range(3):
            for bad in (np.nan, np.inf, -np.inf):
                rows = np.ones((10_000, 5), dtype=np.float32)
                rows[at, axis] = bad
                cloud = PointCloud(xyz=rows[:, :3])
                assert non_finite_points(cloud) == 1, (at, axis, bad)
    # finite values whose float32 sum would overflow are not counted
    big = np.full((10, 3), np.finfo(np.float32).max, dtype=np.float32)
    assert non_finite_points(PointCloud(xyz=big)) == 0


def test_a_topic_is_warned_about_once_and_counted(caplog: pytest.LogCaptureFixture) -> None:
    counter = NonFiniteCounter("log.mcap")
    with caplog.at_level(logging.WARNING, logger="redrive.assembly.non_finite"):
        for _ in range(5):
            counter.check("/points", "lidar", _cloud(300, 201))
        counter.check("/points", "lidar", _cloud(300, 3))  # 1 %: counted, not over
        counter.check("/other", "lidar_2", _cloud(300, 0))
    warnings = [r.getMessage() for r in caplog.records]
    assert len(warnings) == 1
    assert "/points" in warnings[0]
    assert "201 of 300 points (67.0 %)" in warnings[0]
    assert counter.summary() == {
        "/points": {
            "clouds": 6,
            "points": 1800,
            "non_finite": 5 * 201 + 3,
            "clouds_with_non_finite": 6,
            "clouds_over": 5,
            "max_fraction": 0.67,
        }
    }
    assert set(counter.over()) == {"/points"}


def test_a_cloud_at_the_fraction_is_not_over() -> None:
    counter = NonFiniteCounter("log.mcap")
    counter.check("/points", "lidar", _cloud(1000, round(1000 * NON_FINITE_WARN_FRACTION)))
    assert counter.over() == {}
    assert counter.summary()["/points"]["non_finite"] == 100


def test_a_real_cloud_with_two_thirds_nan_is_reported_by_redrive_run(
    shared_data: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The three KITTI sweeps (real HDL-64E clouds, recorded with rosbag) with NaN / ±inf put in
    2 of every 3 points: one warning, the counts in the manifest, a line in the run's report."""
    bag = tmp_path / "kitti_nan.bag"
    injected = inject_non_finite(shared_data / KITTI_BAG, bag, topic=CLOUD_TOPIC, keep_every=3)
    points = sum(n for n, _ in injected)
    bad = sum(b for _, b in injected)
    assert 0.66 < bad / points < 0.67
    out = tmp_path / "run"
    with caplog.at_level(logging.WARNING, logger="redrive.assembly.non_finite"):
        status = main(
            [
                "run",
                str(bag),
                "--perception",
                "cluster-detector",
                "--out",
                str(out),
                "--no-progress",
            ]
        )
    assert status == 0
    warnings = [r.getMessage() for r in caplog.records if r.name == "redrive.assembly.non_finite"]
    assert len(warnings) == 1, warnings  # once per topic, not per frame
    assert CLOUD_TOPIC in warnings[0]
    assert "NaN or infinite" in warnings[0]
    summary = json.loads((out / "manifest.json").read_text())["summary"]
    counts = summary["non_finite_points"][CLOUD_TOPIC]
    assert counts["clouds"] == len(injected) == 3
    assert counts["points"] == points
    assert counts["non_finite"] == bad
    assert counts["clouds_over"] == 3
    assert counts["max_fraction"] == pytest.approx(max(b / n for n, b in injected), abs=1e-6)
    printed = " ".join(capsys.readouterr().out.split())
    assert f"{CLOUD_TOPIC}: 3 of 3 clouds had more than 10% NaN or infinite points" in printed


def test_the_points_reach_the_algorithms_unchanged(shared_data: Path, tmp_path: Path) -> None:
    from redrive.assembly import FrameAssembler
    from redrive.io import open_log

    bag = tmp_path / "kitti_nan.bag"
    injected = inject_non_finite(shared_data / KITTI_BAG, bag, topic=CLOUD_TOPIC, keep_every=3)
    with open_log(bag) as log:
        assembler = FrameAssembler(log)
        clouds = [
            s.data
            for f in assembler.frames()
            for s in f.sensors.values()
            if isinstance(s.data, PointCloud)
        ]
    assert [(len(c.xyz), non_finite_points(c)) for c in clouds] == injected
