"""Whose motion a value scores (issue 35 item 3), pairing renamed algorithms by role (item 4)
and confidence intervals of the value they stand beside (item 5) — on the real WOMD scenario
and the real KITTI frames."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.cli.main import main
from redrive.evaluation.bootstrap import paired_bootstrap, paired_statistic_bootstrap
from redrive.evaluation.compare import compare_runs
from redrive.evaluation.compare_html import CHART_CLIP_PCT, chart_panels
from redrive.evaluation.store import read_evaluation
from redrive.results import open_run

WOMD = "womd/motion_data_one_scenario.tfrecord"
KITTI = "kitti_object/training"
#: metrics of the ego's motion: in an open-loop run, of the logged ego.
EGO_METRICS = ("comfort", "ego_progress", "at_fault_collisions", "drivable_area")
METRICS = ("planning", "control", "latency", *EGO_METRICS)

SLOW_PLANNER = '''
from __future__ import annotations

from types import MappingProxyType

from redrive.algorithms.reference.planner import IdmPlanner


class SlowIdm(IdmPlanner):
    """The reference planner wanting 5 m/s instead of 13.9 m/s."""

    defaults = MappingProxyType({**IdmPlanner.defaults, "v0_mps": 5.0})
'''


def _run(log: Path, out: Path, *stages: str, metrics: tuple[str, ...]) -> Path:
    assert main(["run", str(log), *stages, "-o", str(out), "--no-progress"]) == 0
    argv = ["evaluate", str(out)]
    for m in metrics:
        argv += ["--metric", m]
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def two_planners(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The WOMD scenario (real ego track, agents and map) replayed open loop twice: the
    reference planner (A) and a planner written outside the repository (B), the same
    controller after each."""
    tmp = tmp_path_factory.mktemp("planners")
    plugin = tmp / "slow_planner.py"
    plugin.write_text(textwrap.dedent(SLOW_PLANNER), encoding="utf-8")
    log = shared_data / WOMD
    a = _run(
        log, tmp / "a", "--planning", "idm-planner", "--control", "pure-pursuit-pid",
        metrics=METRICS,
    )  # fmt: skip
    b = _run(
        log, tmp / "b", "--planning", f"{plugin}:SlowIdm", "--control", "pure-pursuit-pid",
        metrics=METRICS,
    )  # fmt: skip
    return a, b


def _values(run: Path) -> dict[tuple[str, str, str], dict[str, Any]]:
    rows = read_evaluation(open_run(run)).values.to_pylist()
    return {(r["metric"], r["algorithm"], r["key"]): r for r in rows}


def test_stored_subjects_say_whose_motion(two_planners: tuple[Path, Path]) -> None:
    a, _ = two_planners
    v = _values(a)
    assert {r["subject"] for (m, _, _), r in v.items() if m == "planning"} == {"idm-planner"}
    for metric in EGO_METRICS:
        assert {r["subject"] for (m, _, _), r in v.items() if m == metric} == {"log"}, metric
    assert {r["subject"] for (m, _, _), r in v.items() if m == "latency"} == {"run"}
    # the controller: its tracking error is the logged ego's, its command rates its own
    assert v["control", "pure-pursuit-pid", "lateral_rmse_m"]["subject"] == "log"
    assert v["control", "pure-pursuit-pid", "steering_rate_rmse_rad_s"]["subject"] == (
        "pure-pursuit-pid"
    )
    per_frame = read_evaluation(open_run(a)).per_frame.to_pylist()
    subjects = {(r["metric"], r["series"]): r["subject"] for r in per_frame}
    assert subjects["control", "lateral_error_m"] == "log"
    assert subjects["control", "steering_rate_rad_s"] == "pure-pursuit-pid"
    # a value says which per-frame statistic it is
    row = v["planning", "idm-planner", "max_lon_accel_mps2"]
    assert (row["series"], row["statistic"]) == ("max_lon_accel_mps2", "max")


def test_two_planners_differ_and_the_log_scores_do_not(two_planners: tuple[Path, Path]) -> None:
    a, b = two_planners
    va, vb = _values(a), _values(b)
    # the planners' own scores differ …
    plan_a = {k[2]: r["value"] for k, r in va.items() if k[:2] == ("planning", "idm-planner")}
    plan_b = {k[2]: r["value"] for k, r in vb.items() if k[:2] == ("planning", "SlowIdm")}
    differ = [k for k in plan_a if plan_a[k] != plan_b[k] and not math.isnan(plan_a[k])]
    assert {"ADE/3s", "FDE/3s", "max_abs_jerk_mps3"} <= set(differ)
    # … the logged ego's are identical, whichever planner ran
    log_a = {k: r["value"] for k, r in va.items() if r["subject"] == "log" and k[0] != "control"}
    log_b = {k: r["value"] for k, r in vb.items() if r["subject"] == "log" and k[0] != "control"}
    assert len(log_a) >= 4 * 2
    assert log_a.keys() == log_b.keys()
    assert all(
        log_a[k] == log_b[k] or (math.isnan(log_a[k]) and math.isnan(log_b[k])) for k in log_a
    )

    cmp = compare_runs(a, b, bootstrap=500)
    assert cmp.role_pairs == (("idm-planner", "SlowIdm", "planning"),)
    compared = {v.metric for v in cmp.values}
    assert "planning" in compared
    assert not compared & set(EGO_METRICS)
    assert not any(v.subject == "log" for v in cmp.values)
    assert not any(s.subject == "log" for s in cmp.series)
    kept_apart = {v.metric for v in cmp.log_values}
    assert set(EGO_METRICS) <= kept_apart
    assert all(v.verdict in ("same", "n/a") for v in cmp.log_values if v.metric != "control")
    assert all(v.bootstrap is None and "log's value" in v.note for v in cmp.log_values)
    planning = {v.key: v for v in cmp.values if v.metric == "planning"}
    assert planning["ADE/3s"].verdict in ("better", "worse")
    # nothing of the log among the frames where B is worse
    assert not any(
        any(m in d for m in EGO_METRICS) for w in cmp.worst_frames() for d in w.differences
    )


def test_cli_report_and_fleet_say_the_log(
    two_planners: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a, b = two_planners
    assert main(["compare", str(a), str(b), "--html", str(tmp_path / "ab.html")]) == 0
    out = " ".join(capsys.readouterr().out.split())  # rich wraps long lines
    assert "idm-planner ↔ SlowIdm (paired by role" in out
    assert "the log's values" in out
    assert main(["report", str(a)]) == 0
    html = next(a.glob("report*/report.html"), None) or next(a.rglob("report.html"))
    text = html.read_text(encoding="utf-8")
    assert "the log (logged ego of this open-loop run)" in text
    page = (tmp_path / "ab.html").read_text(encoding="utf-8")
    assert "The log&#x27;s values (not compared)" in page or "The log's values" in page


def test_ci_of_a_max_is_of_the_max(two_planners: tuple[Path, Path]) -> None:
    """The CI beside a max over frames is the bootstrap of that max: the value's Δ lies in it
    (the per-frame series' mean CI, of another number, is not put beside it)."""
    cmp = compare_runs(*two_planners, bootstrap=1000)
    planning = {v.key: v for v in cmp.values if v.metric == "planning"}
    checked = 0
    for key in ("max_lon_accel_mps2", "max_abs_jerk_mps3", "max_abs_lon_jerk_mps3"):
        v = planning[key]
        assert v.bootstrap is not None, key
        assert v.bootstrap.statistic == "max", key
        assert v.significance.startswith("max [")
        if v.series and not any(s.only_a or s.only_b for s in cmp.series if s.series == v.series):
            assert v.bootstrap.ci_low <= v.delta <= v.bootstrap.ci_high, key
            assert v.bootstrap.mean_delta == pytest.approx(v.delta, rel=1e-12, abs=1e-15)
            checked += 1
    assert checked
    # latency's percentiles: the CI of the percentile; the renamed planner's
    # own latency pairs under both names
    latency = {v.key: v for v in cmp.values if v.metric == "latency"}
    expected = {"frame_p95_ms": "p95", "frame_p50_ms": "p50", "p95_ms/idm-planner→SlowIdm": "p95"}
    for key, stat in expected.items():
        v = latency[key]
        assert v.bootstrap is not None, key
        assert v.bootstrap.statistic == stat, key
        # (its Δ is of measured times: not asserted inside the CI, which a timing may not be)
        assert v.bootstrap.mean_delta == pytest.approx(v.delta), key
    assert "p95_ms/idm-planner" not in latency


def test_ci_of_a_max_contains_its_delta_where_the_mean_ci_does_not() -> None:
    """The issue's case: the worst frame gets worse (max +0.9) while most frames improve (the
    per-frame mean CI lies below 0)."""
    rng = np.random.default_rng(5)
    a = 1.0 + 0.01 * rng.standard_normal(60)
    b = a - 0.05
    b[17] = a.max() + 0.9
    d_max = float(b.max() - a.max())
    mean = paired_bootstrap(b - a, resamples=2000, seed=0)
    assert mean.ci_high < 0 < d_max  # that CI contradicts the max's Δ
    boot = paired_statistic_bootstrap(a, b, statistic="max", resamples=2000, seed=0)
    assert boot.statistic == "max"
    assert boot.mean_delta == pytest.approx(d_max)
    assert boot.ci_low <= d_max <= boot.ci_high
    # the mean statistic is exactly the per-frame-difference bootstrap
    assert paired_statistic_bootstrap(a, b, statistic="mean", resamples=2000, seed=0) == mean


def test_chart_keeps_latency_apart(two_planners: tuple[Path, Path]) -> None:
    cmp = compare_runs(*two_planners, bootstrap=200)
    panels = chart_panels(cmp)
    titles = [t for t, _ in panels]
    assert titles[0].startswith("values of the algorithms")
    for title, bars in panels:
        is_timing = title.startswith("timing")
        assert all(label.startswith("latency") == is_timing for label, _ in bars), title
    assert CHART_CLIP_PCT == 100.0


def test_plugin_pairs_with_installed_detector_by_role(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A detector written outside the repository (named after its class) against the
    installed one, each before the same tracker; then both renamed at once (paired by stage)."""
    plugin = tmp_path / "ransac.py"
    plugin.write_text(
        textwrap.dedent(
            '''
            from __future__ import annotations

            from redrive.algorithms.reference.detector import ClusterDetector
            from redrive.algorithms.reference.tracker import KalmanTracker


            class RansacCluster(ClusterDetector):
                """The reference clusters under a plugin's own name."""


            class MyTracker(KalmanTracker):
                """The reference tracker under a plugin's own name."""
            '''
        ),
        encoding="utf-8",
    )
    log = shared_data / KITTI
    metrics = ("kitti_detection",)
    a = _run(log, tmp_path / "a", "--perception", "cluster-detector", "--perception",
             "kalman-tracker", metrics=metrics)  # fmt: skip
    b = _run(log, tmp_path / "b", "--perception", f"{plugin}:RansacCluster", "--perception",
             "kalman-tracker", metrics=metrics)  # fmt: skip
    c = _run(log, tmp_path / "c", "--perception", f"{plugin}:RansacCluster", "--perception",
             f"{plugin}:MyTracker", metrics=metrics)  # fmt: skip
    cmp = compare_runs(a, b, bootstrap=100)
    assert ("cluster-detector", "RansacCluster") in cmp.pairs
    assert cmp.role_pairs == (("cluster-detector", "RansacCluster", "perception"),)
    detection = [v for v in cmp.values if v.metric == "kitti_detection"]
    assert {v.algorithm_b for v in detection} == {"RansacCluster", "kalman-tracker"}
    assert not [k for k in cmp.skipped if k.metric == "kitti_detection"]
    # the same clusters: every detection value the same
    assert all(v.verdict in ("same", "n/a") for v in detection)
    capsys.readouterr()
    assert main(["compare", str(a), str(b)]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "cluster-detector ↔ RansacCluster (paired by role" in out
    assert "not compared: kitti_detection" not in out
    both = compare_runs(a, c, bootstrap=100)
    assert set(both.role_pairs) == {
        ("cluster-detector", "RansacCluster", "perception, stage perception_1"),
        ("kalman-tracker", "MyTracker", "perception, stage perception_2"),
    }
    assert not [k for k in both.skipped if k.metric in ("kitti_detection", "*")]


def test_an_evaluation_stored_before_subjects_reads(
    two_planners: tuple[Path, Path], tmp_path: Path
) -> None:
    """Tables written before the subject/series/statistic columns read with subject = the
    algorithm (``run`` for a whole-run metric), as those values were then taken to be."""
    import shutil

    import pyarrow.parquet as pq

    run = tmp_path / "old"
    shutil.copytree(two_planners[0], run)
    for path in (run / "metrics").glob("*/*.parquet"):
        table = pq.read_table(path)
        keep = [n for n in table.column_names if n not in ("subject", "series", "statistic")]
        pq.write_table(table.select(keep), path)
    ev = read_evaluation(open_run(run))
    rows = ev.values.to_pylist()
    assert {r["subject"] for r in rows if r["metric"] == "comfort"} == {"run"}
    assert {r["subject"] for r in rows if r["metric"] == "planning"} == {"idm-planner"}
    assert {r["statistic"] for r in rows} == {""}
    assert set(ev.per_frame.column("subject").to_pylist()) >= {"run", "idm-planner"}
