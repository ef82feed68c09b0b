"""``redrive evaluate BATCH``: cells evaluated as runs, metrics pooled across logs the way their
definitions demand (detection AP over all frames of all logs: equal to the AP of one run that
holds every frame), stored as Parquet; CI gates exit 4 with the table of what failed."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pyarrow.dataset as ds
import pytest

from redrive.batch import read_batch_manifest
from redrive.batch.evaluate import read_cell_values, read_pooled
from redrive.cli._gates import EXIT_GATE_FAILED
from redrive.cli.main import main
from redrive.evaluation.base import EvalData
from redrive.evaluation.detection.nuscenes import NuScenesDetection
from redrive.evaluation.hota import Hota
from redrive.evaluation.tracking import ClearMot
from redrive.results import (
    AlgorithmEntry,
    FrameRecord,
    PipelineInfo,
    RunSetup,
    RunWriter,
    SourceLog,
    StepRecord,
    open_run,
)
from redrive.types import DetectedObject, Role

from .outputs import batch

PLUGINS = Path(__file__).with_name("plugins.py")
ALGO = "NoisyOracle"


@pytest.fixture(scope="module")
def truth_batch(truth_logs: list[Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("truth_batch") / "batch"
    detector = f"{PLUGINS}:NoisyOracle"
    assert batch(out, *map(str, truth_logs), "--perception", detector, "--workers", "2") == 0
    assert main(["evaluate", str(out)]) == 0
    return out


def _renumbered(objects: tuple[DetectedObject, ...], k: int) -> tuple[DetectedObject, ...]:
    import dataclasses

    return tuple(dataclasses.replace(o, object_id=o.object_id + 1000 * k) for o in objects)


def _concatenated_run(batch_dir: Path, out: Path) -> Path:
    """One run, written with the results writer, holding every frame of every cell one after
    the other (frame indices and object ids made unique per log)."""
    setup = RunSetup(
        log=SourceLog(path="concatenated", sha256="x", format="synthetic"),
        seed=0,
        pipeline=PipelineInfo(first_frame=0),
        algorithms=(AlgorithmEntry(name=ALGO, version="1", config_hash="a", role=Role.PERCEPTION),),
    )
    index = 0
    with RunWriter(out, setup=setup) as writer:
        for k, cell in enumerate(read_batch_manifest(batch_dir).cells):
            run = open_run(batch_dir / cell.run_dir)
            truth, dets = run.ground_truth(), run.detections(ALGO)
            stamps = run.table("frames").column("stamp_ns").to_pylist()
            for f in sorted(truth):
                step = StepRecord(
                    algorithm=ALGO,
                    stage="perception",
                    role="perception",
                    status="ok",
                    output=_renumbered(dets.get(f, ()), k),
                )
                writer.write_frame(
                    FrameRecord(
                        frame_index=index,
                        stamp_ns=stamps[f],
                        steps=(step,),
                        ground_truth=_renumbered(truth[f], k),
                    )
                )
                index += 1
    return out


def test_pooled_ap_is_the_ap_of_all_frames_as_one_run(truth_batch: Path, tmp_path: Path) -> None:
    pooled = read_pooled(truth_batch)
    cells = read_cell_values(truth_batch)

    def pooled_value(metric: str, key: str) -> float:
        rows = [
            r
            for r in pooled.to_pylist()
            if r["metric"] == metric and r["key"] == key and r["algorithm"] == ALGO
        ]
        assert len(rows) == 1, rows
        assert rows[0]["pipeline"] == "flags"
        assert rows[0]["logs"] == 3
        return float(rows[0]["value"])

    one = EvalData(open_run(_concatenated_run(truth_batch, tmp_path / "one")), ALGO)
    whole = NuScenesDetection().evaluate(one).values
    assert pooled_value("nuscenes_detection", "mAP") == pytest.approx(whole["mAP"], abs=1e-12)
    assert pooled_value("nuscenes_detection", "NDS_no_AAE") == pytest.approx(
        whole["NDS_no_AAE"], abs=1e-12
    )
    # tracking totals summed before the ratios, as one run of every frame gives them
    mot = ClearMot().evaluate(one).values
    for key in ("MOTA", "num_switches", "num_misses", "num_false_positives", "MOTP"):
        assert pooled_value("clear_mot", key) == pytest.approx(mot[key], abs=1e-12), key
    assert pooled_value("hota", "HOTA") == pytest.approx(Hota().evaluate(one).values["HOTA"])

    # … and not a mean of the per-log APs (the logs differ, so the two differ)
    per_log = [
        r for r in cells.to_pylist() if r["metric"] == "nuscenes_detection" and r["key"] == "mAP"
    ]
    assert sorted(r["log"] for r in per_log) == ["truth0", "truth1", "truth2"]
    mean = sum(r["value"] for r in per_log) / 3
    weighted = sum(r["value"] * r["frames"] for r in per_log) / sum(r["frames"] for r in per_log)
    assert not math.isclose(whole["mAP"], mean, abs_tol=1e-6)
    assert not math.isclose(whole["mAP"], weighted, abs_tol=1e-6)
    assert len({round(r["value"], 9) for r in per_log}) == 3


def test_the_rules_and_the_stored_tables(truth_batch: Path) -> None:
    pooled = read_pooled(truth_batch).to_pylist()
    rules = {r["metric"]: r["rule"] for r in pooled}
    for metric in ("nuscenes_detection", "kitti_detection", "clear_mot", "hota", "latency"):
        assert rules[metric] == "concatenate", metric
    assert rules["comfort"] == "frame_weighted_mean"
    # whose motion: the open-loop runs' ego is the logged one (issue 35 item 3)
    subjects = {r["metric"]: r["subject"] for r in pooled}
    assert (subjects["comfort"], subjects["nuscenes_detection"], subjects["latency"]) == (
        "log",
        ALGO,
        "run",
    )
    cell_subjects = {
        r["subject"] for r in read_cell_values(truth_batch).to_pylist() if r["metric"] == "comfort"
    }
    assert cell_subjects == {"log"}
    frames = {r["metric"]: r["frames"] for r in pooled}
    assert frames["latency"] == 20 + 14 + 26
    # latency percentiles over every frame of every log
    walls = []
    for cell in read_batch_manifest(truth_batch).cells:
        walls += open_run(truth_batch / cell.run_dir).table("frames").column("wall_ns").to_pylist()
    import numpy as np

    p95 = float(np.percentile(np.asarray(walls, dtype=np.float64) / 1e6, 95))
    (row,) = [r for r in pooled if r["metric"] == "latency" and r["key"] == "frame_p95_ms"]
    assert row["value"] == pytest.approx(p95)
    # the per-cell values: a Hive-partitioned dataset (pipeline, loop, log)
    data = ds.dataset(truth_batch / "evaluation" / "cells", format="parquet", partitioning="hive")
    table = data.to_table(filter=ds.field("log") == "truth1")
    assert set(table.column("pipeline").to_pylist()) == {"flags"}
    assert set(table.column("loop").to_pylist()) == {"open"}
    assert set(table.column("frames").to_pylist()) == {14}


def test_gates_on_the_pooled_value(truth_batch: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (mAP,) = [
        r["value"]
        for r in read_pooled(truth_batch).to_pylist()
        if r["metric"] == "nuscenes_detection" and r["key"] == "mAP"
    ]
    capsys.readouterr()
    ok = ["evaluate", str(truth_batch), "--metric", "nuscenes_detection", "--metric", "latency"]
    assert main([*ok, "--fail-under", f"nuscenes_detection.mAP={mAP - 0.01:.4f}"]) == 0
    assert "CI gates: all passed" in capsys.readouterr().out
    status = main(
        [
            *ok,
            "--fail-under",
            f"nuscenes_detection.mAP={mAP + 0.01:.4f}",
            "--fail-over",
            "latency.frame_p95_ms=100000",
        ]
    )
    assert status == EXIT_GATE_FAILED == 4
    out = capsys.readouterr().out
    assert "1 of 2 FAILED" in out
    failed = next(line for line in out.splitlines() if "FAILED" in line and "mAP" in line)
    assert "nuscenes_detection.mAP" in failed
    assert f"{mAP:.4g}" in failed
    assert f">= {mAP + 0.01:.4f}".rstrip("0") in failed
    # a gate on a value that does not exist fails: it checks nothing
    assert main([*ok, "--fail-under", "nuscenes_detection.no_such=0"]) == EXIT_GATE_FAILED
    assert "no such value" in capsys.readouterr().out


def test_gates_on_a_run_and_bad_gates(
    truth_batch: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cell = truth_batch / read_batch_manifest(truth_batch).cells[0].run_dir
    base = ["evaluate", str(cell), "--metric", "latency"]
    assert main([*base, "--fail-over", "latency.frame_p95_ms=100000"]) == 0
    capsys.readouterr()
    assert main([*base, "--fail-over", "latency.frame_p95_ms=0"]) == EXIT_GATE_FAILED
    out = capsys.readouterr().out
    assert "latency.frame_p95_ms" in out
    assert "<= 0" in out
    with pytest.raises(SystemExit) as exit_info:
        main([*base, "--fail-under", "mAP=0.4"])  # no metric named
    assert exit_info.value.code == 2
    assert "METRIC.VALUE" in capsys.readouterr().err


def test_failed_cells_are_left_out_with_their_reason(
    truth_logs: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    corrupt = tmp_path / "corrupt.mcap"
    corrupt.write_bytes(truth_logs[0].read_bytes()[:300])
    out = tmp_path / "b"
    detector = f"{PLUGINS}:NoisyOracle"
    assert batch(out, str(truth_logs[1]), str(corrupt), "--perception", detector) == 3
    capsys.readouterr()
    assert main(["evaluate", str(out), "--metric", "nuscenes_detection"]) == 0
    text = capsys.readouterr().out
    assert "not evaluated: cell flags/open/corrupt (failed)" in text
    assert [r["logs"] for r in read_pooled(out).to_pylist()] == [1] * read_pooled(out).num_rows


def _oracle_pipeline(folder: Path, name: str, *, worse: bool) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(
        f"""\
[[stage]]
name = "perception"
[[stage.algorithm]]
name = "det"
plugin = "{PLUGINS}:NoisyOracle"
config = {{ worse = {"true" if worse else "false"} }}
""",
        encoding="utf-8",
    )
    return path


def test_batch_gates_and_fleet_ab(
    truth_logs: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = _oracle_pipeline(tmp_path, "good", worse=False)
    bad = _oracle_pipeline(tmp_path, "bad", worse=True)
    out = tmp_path / "ab"
    logs = [str(p) for p in truth_logs]
    args = [*logs, "--pipeline", str(good), "--pipeline", str(bad), "--workers", "2"]
    # redrive batch evaluates after running when gated: a gate every pipeline passes …
    assert batch(out, *args, "--fail-under", "nuscenes_detection.mAP=0.01") == 0
    text = capsys.readouterr().out
    assert "pipeline good (open loop)" in text
    assert "CI gates: all passed" in text
    pooled = {
        r["pipeline"]: r["value"]
        for r in read_pooled(out).to_pylist()
        if r["metric"] == "nuscenes_detection" and r["key"] == "mAP"
    }
    assert pooled["bad"] < pooled["good"]
    # … and one the worse pipeline fails (the cells are complete: skipped, then evaluated)
    gate = f"nuscenes_detection.mAP={(pooled['bad'] + pooled['good']) / 2:.4f}"
    assert batch(out, *args, "--fail-under", gate) == EXIT_GATE_FAILED
    text = capsys.readouterr().out
    assert "1 of 2 FAILED" in text
    assert "bad/open det" in next(ln for ln in text.splitlines() if "FAILED" in ln and "bad" in ln)

    # two pipelines of one batch: per-log differences, a bootstrap over logs, the gate
    ab = ["compare", str(out), "--pipeline-a", "good", "--pipeline-b", "bad"]
    assert main([*ab, "--value", "nuscenes_detection.mAP"]) == 0
    text = capsys.readouterr().out
    assert "nuscenes_detection.mAP per log, B's worst first" in text
    assert "paired bootstrap over logs" in text
    for log in ("truth0", "truth1", "truth2"):
        assert log in text
    assert main([*ab, "--max-regression", "mAP=1"]) == 0
    capsys.readouterr()
    assert main([*ab, "--max-regression", "nuscenes_detection.mAP=0.001"]) == EXIT_GATE_FAILED
    text = capsys.readouterr().out
    assert "CI gates: 1 of 1 FAILED" in text
    failed = next(ln for ln in text.splitlines() if "FAILED" in ln and "mAP" in ln)
    assert "nuscenes_detection.mAP" in failed
    assert "worse by <= 0.001" in failed

    from redrive.batch.compare import compare_batches

    cmp = compare_batches(out, out, pipeline_a="good", pipeline_b="bad")
    # by default the headline of the first metric that scores an algorithm
    assert (cmp.metric, cmp.key) == ("clear_mot", "MOTA")
    assert [d.worse_by for d in cmp.logs] == sorted((d.worse_by for d in cmp.logs), reverse=True)
    assert cmp.bootstrap.n_frames == 3
    assert cmp.bootstrap.ci_low <= cmp.bootstrap.mean_delta <= cmp.bootstrap.ci_high
    mean = sum(d.delta for d in cmp.logs) / 3
    assert cmp.bootstrap.mean_delta == pytest.approx(mean)


def test_fleet_report(truth_batch: Path, tmp_path: Path) -> None:
    from openpyxl import load_workbook

    cells = read_batch_manifest(truth_batch).cells
    # (earlier tests evaluate the batch with other metrics: these are the ones looked at here)
    evaluate = ["evaluate", str(truth_batch)]
    for metric in ("nuscenes_detection", "comfort", "latency"):
        evaluate += ["--metric", metric]
    assert main(evaluate) == 0
    # one cell's own report, written as for any run: the fleet report links to it
    assert main(["report", str(truth_batch / cells[1].run_dir), "--worst", "0"]) == 0
    out = tmp_path / "fleet"
    assert main(["report", str(truth_batch), "-o", str(out), "--no-cell-reports"]) == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    for section in ("pooled", "distribution", "worst-logs", "worst-frames", "cells"):
        assert f'<section id="{section}">' in page
    hrefs = set(re.findall(r'href="([^"#][^"]*)"', page))
    report = truth_batch / cells[1].run_dir / "report" / "report.html"
    assert {(out / href).resolve() for href in hrefs} == {report.resolve()}
    (mAP,) = [
        r["value"]
        for r in read_pooled(truth_batch).to_pylist()
        if r["metric"] == "nuscenes_detection" and r["key"] == "mAP"
    ]
    assert f'<td class="num">{mAP:.4g}</td>' in page
    assert "data:image/png;base64," in page  # the per-log box plots
    # the logged ego's values apart, as the log's
    assert "score the logged ego of the open-loop runs" in page
    assert "comfort.comfortable (the log&#x27;s: logged ego)" in page or (
        "comfort.comfortable (the log's: logged ego)" in page
    )
    wb = load_workbook(out / "report.xlsx", read_only=True)
    assert wb.sheetnames == ["pooled", "cells", "worst_logs", "worst_frames", "cells_left_out"]
    rows = list(wb["cells"].iter_rows(values_only=True))
    assert {"pipeline", "loop", "log", "metric", "value"} <= set(rows[0])
    assert len(rows) - 1 == read_cell_values(truth_batch).num_rows
