"""Fixtures of the batch tests: short demo bags (ROS 1, LiDAR + odometry + IMU + GNSS, written
with the real writer) of slightly different lengths, and two cheap pipeline files."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.testing.demo_log import write_demo_bag

from .outputs import batch

#: seconds of the four logs: about 2 s each, different so that their cells differ.
DURATIONS_S = (2.0, 2.1, 2.2, 2.3)

PIPELINE_A = """\
[[stage]]
name = "planning"
[[stage.algorithm]]
plugin = "idm-planner"

[[stage]]
name = "control"
[[stage.algorithm]]
plugin = "pure-pursuit-pid"
"""

PIPELINE_B = """\
[[stage]]
name = "detection"
[[stage.algorithm]]
plugin = "cluster-detector"

[[stage]]
name = "planning"
[[stage.algorithm]]
plugin = "idm-planner"
"""


@pytest.fixture(scope="package")
def logs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("batch_logs")
    return [
        write_demo_bag(folder / f"drive{i}.bag", duration_s=d) for i, d in enumerate(DURATIONS_S)
    ]


@pytest.fixture(scope="package")
def pipelines(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("batch_pipelines")
    out = []
    for name, text in (("a", PIPELINE_A), ("b", PIPELINE_B)):
        path = folder / f"{name}.toml"
        path.write_text(text, encoding="utf-8")
        out.append(path)
    return out


@pytest.fixture(scope="package")
def two_workers(
    logs: list[Path], pipelines: list[Path], tmp_path_factory: pytest.TempPathFactory
) -> Path:
    out = tmp_path_factory.mktemp("two_workers") / "batch"
    args = [str(p) for p in logs]
    for p in pipelines:
        args += ["--pipeline", str(p)]
    assert batch(out, *args, "--workers", "2") == 0
    return out
