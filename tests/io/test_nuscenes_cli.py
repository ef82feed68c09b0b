"""The real nuScenes keyframe through the CLI: `redrive info` knows it, the reference detector
runs on it and `redrive evaluate` scores it with the nuScenes detection metric."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from redrive.cli.main import main
from redrive.evaluation.detection.classes import NUSCENES_CLASS_RANGE_M, NUSCENES_CLASSES
from redrive.io import open_log

pytestmark = pytest.mark.shared_data


def test_info_says_what_the_keyframe_holds(
    nuscenes_demo: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["info", str(nuscenes_demo), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "nuscenes-mmdet3d"
    topics = {t["topic"]: t for t in info["topics"]}
    assert topics["/LIDAR_TOP"]["maps_to"] == "lidar_top (lidar, driver)"
    assert topics["/annotations"]["maps_to"] == "ground truth"
    assert topics["/ego_pose"]["maps_to"] == "vehicle state"
    assert sum(t.endswith("/image") for t in topics) == 6
    assert info["capabilities"]["has_ground_truth"]


def test_run_the_reference_detector_and_evaluate(
    nuscenes_demo: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    args = ["run", str(nuscenes_demo), "--perception", "cluster-detector", "-o", str(out)]
    assert main([*args, "--no-progress"]) == 0
    assert main(["evaluate", str(out), "--metric", "nuscenes_detection"]) == 0
    assert "nuscenes_detection" in capsys.readouterr().out
    (values_file,) = out.glob("metrics/nuscenes_detection*/values.parquet")
    values = dict(
        zip(*(pq.read_table(values_file).to_pydict()[k] for k in ("key", "value")), strict=True)
    )
    # the ground truth scored is the reader's: mapped classes, inside their range, with points
    with open_log(nuscenes_demo) as log:
        objects = log.samples[0].objects
    scored = [
        o
        for o in objects
        if (name := NUSCENES_CLASSES.get(o.object_class.value)) is not None
        and np.hypot(*o.box.center[:2]) < NUSCENES_CLASS_RANGE_M[name]
        and o.num_lidar_points
    ]
    assert values["gt_objects"] == len(scored) > 10
    assert values["frames"] == 1
    assert values["detections"] > 0
    assert 0.0 < values["mAP"] <= 1.0


def test_batch_takes_a_nuscenes_folder_for_one_log(nuscenes_demo: Path) -> None:
    from redrive.batch.spec import _logs_in_dir

    assert _logs_in_dir(nuscenes_demo) == [nuscenes_demo]
    assert nuscenes_demo in _logs_in_dir(nuscenes_demo.parent)
