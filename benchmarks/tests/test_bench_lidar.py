"""``python -m benchmarks lidar``: runs end to end on a tiny configuration (no timings asserted)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks.cli import build_parser
from benchmarks.lidar import bench_lidar, bench_scene


def _run(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    status: int = args.func(args)
    return status


def test_bench_scene_keeps_the_ego_clear() -> None:
    scene = bench_scene(np.random.default_rng(0), num_boxes=60, num_buildings=4)
    assert len(scene.objects) == 64
    ego_xy = scene.map_from_base[:2, 3]
    dist = np.linalg.norm(scene.objects.center_m[:, :2] - ego_xy, axis=1)
    assert dist.min() > 5.0


def test_bench_lidar_small() -> None:
    result = bench_lidar(scans=2, camera_frames=1, preset="VLP-16", num_boxes=5, open3d=False)
    assert result.scans_per_s > 0
    assert result.camera_fps > 0
    assert result.rays_per_scan == 16 * 1800
    assert result.ratio is None
    assert result.points_per_scan > 1000


def test_cli_json_and_text(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["lidar", "--scans", "2", "--frames", "1", "--boxes", "5", "--no-open3d"]
    assert _run([*argv, "--preset", "VLP-16", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["preset"] == "VLP-16"
    assert data["scans_per_s"] > 0
    assert _run(argv) == 0
    out = capsys.readouterr().out
    assert "sweeps/s" in out
    assert "frames/s" in out
    with pytest.raises(SystemExit):
        _run(["lidar", "--help"])
    assert "python -m benchmarks lidar" in capsys.readouterr().out
