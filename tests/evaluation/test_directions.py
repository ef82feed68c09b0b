"""Every registered metric states the direction of each value it produces (issue 17 item 1):
errors are lower-is-better, counts of what the data held have no direction, scores are
higher-is-better — walked over every ``redrive.metrics`` entry point on real runs."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.config import pipeline_from_plugins
from redrive.evaluation import Metric
from redrive.evaluation.evaluator import evaluate_run
from redrive.evaluation.registry import installed_metrics
from redrive.results.evaluation import read_evaluation

#: value names whose direction the name patterns below would get wrong
HIGHER_EXACT = {
    "no_at_fault_collisions", "min_lon_accel_mps2", "making_progress", "num_matches",
    "mostly_tracked", "driven_frames", "min_ttc_s", "no_ego_at_fault_collisions",
    "time_to_collision_within_bound", "lon_accel_mps2_within_bound", "lat_accel_mps2_within_bound",
    "yaw_rate_rad_s_within_bound", "yaw_accel_rad_s2_within_bound", "lon_jerk_mps3_within_bound",
    "jerk_mps3_within_bound",
}  # fmt: skip
#: counts of what the data held and parameters echoed (the part before the first "/")
NEUTRAL_HEADS = {
    "frames", "num_frames", "num_objects", "num_predictions", "gt_objects", "detections",
    "matched", "deadline_ms", "expert_progress_m", "gt", "deviated_frames",
    "acceleration_from_states", "along_map_route", "lights_in_map", "frames_without_states",
}  # fmt: skip
LOWER = re.compile(
    r"rmse|mae|error|^m?a[tsova]e\b|^a[tsova]e/|^[af]de/|_ms\b|_ms/|miss|false_pos|switch|"
    r"fragment|collision|fallback|overspeed|outside|wrong_way|uncomfortable|off_road|speeding|"
    r"unmatched|low_ttc|mostly_lost|max|jerk|deviation|motp|stopped_|active_|without_output|"
    r"red_light"
)
HIGHER = re.compile(
    r"^m?ap|^recall|^precision|hota|deta|assa|loca|detre|detpr|assre|asspr|mota|idf1|^idp|^idr|"
    r"nds|pdm_score|scenario_score|^cls$|^multiplier$|^weighted_average$|compliance|progress|"
    r"ttc_within|comfortable|accuracy|f1|^(nc|dac|mp|ttc|ep|c|ddc)$"
)


def expected_direction(key: str) -> bool | str | None:
    """True/False/None by the value's name; "unknown" when no rule names it."""
    low = key.lower()
    if key in HIGHER_EXACT:
        return True
    if key.split("/", 1)[0] in NEUTRAL_HEADS:
        return None
    if LOWER.search(low):
        return False
    if HIGHER.search(low):
        return True
    return "unknown"


def test_the_rules_know_the_known_cases() -> None:
    assert expected_direction("mATE") is False
    assert expected_direction("ATE/car") is False
    assert expected_direction("mAP") is True
    assert expected_direction("NDS_no_AAE") is True
    assert expected_direction("position_rmse_m") is False
    assert expected_direction("gt_objects") is None
    assert expected_direction("no_at_fault_collisions") is True
    assert expected_direction("traffic_light_compliance") is True
    assert expected_direction("red_light_frames") is False
    assert expected_direction("lights_in_map") is None


def test_every_metric_class_states_its_direction() -> None:
    registry = installed_metrics()
    assert not registry.broken
    for name, cls in registry.items():
        declared = any("higher_is_better" in vars(k) for k in cls.__mro__ if k is not Metric)
        assert declared, f"metric {name} ({cls.__qualname__}) does not state higher_is_better"


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    tmp = tmp_path_factory.mktemp("directions")
    log = tmp / "cut_in.mcap"
    assert main(["synth", "cut_in", "--duration", "4", "-o", str(log)]) == 0
    open_loop = tmp / "open"
    assert main(["run", str(log), "--out", str(open_loop), "--no-progress"]) == 0
    closed = tmp / "closed"
    pipeline = pipeline_from_plugins(
        perception=["noisy-oracle"], planning=["idm-planner"], control=["pure-pursuit-pid"]
    )
    run_closed_loop(
        ClosedLoopRequest(scenario="cut_in", pipeline=pipeline, out=closed, duration_s=4.0)
    )
    for run in (open_loop, closed):
        summary = evaluate_run(run)
        assert not summary.failed, summary.failed
    return [open_loop, closed]


def test_every_value_of_every_metric_has_the_direction_its_name_says(
    evaluated: list[Path],
) -> None:
    seen: set[str] = set()
    wrong, unknown = [], []
    for run in evaluated:
        for row in read_evaluation(run).values.to_pylist():
            seen.add(row["metric"])
            want = expected_direction(row["key"])
            if want == "unknown":
                unknown.append(f"{row['metric']}.{row['key']}")
            elif row["higher_is_better"] is not want:
                wrong.append(f"{row['metric']}.{row['key']}: {row['higher_is_better']}, not {want}")
    assert not wrong, "\n".join(sorted(set(wrong)))
    assert not unknown, "add these to the rules of this test:\n" + "\n".join(sorted(set(unknown)))
    # every registered metric produced values on one of the two runs
    assert set(installed_metrics()) <= seen, set(installed_metrics()) - seen
