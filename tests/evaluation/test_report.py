"""redrive report: self-contained HTML (plots inline, no network, escaped), XLSX, CSV, CLI.

The run is hand-made (4 frames, a perception algorithm with a hostile name, a planner) and its
evaluation is written through the real store (``write_evaluation``) from two metrics whose
results are fixed here, so every number the report must show is known.
"""

from __future__ import annotations

import argparse
import csv
import re
from collections.abc import Mapping
from html.parser import HTMLParser
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pyarrow as pa
import pytest
from openpyxl import load_workbook

from redrive.cli import report as cli_report
from redrive.errors import ConfigError
from redrive.evaluation import Bookmark, EvalData, Metric, MetricResult, Series
from redrive.evaluation.detection.nuscenes import NuScenesDetection
from redrive.evaluation.evaluator import evaluate_run
from redrive.evaluation.plots import frame_scores, worst_frames
from redrive.evaluation.report import DEFAULT_WORST, render_html, write_report
from redrive.evaluation.store import Evaluation, Scored, read_evaluation, write_evaluation
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
from redrive.types import Box3D, DetectedObject, ObjectClass, PlannedPath, Role

EVIL = '<script>alert("x")</script>'
FORMULA = '=HYPERLINK("http://x")'
T0_NS = 1_700_000_000_000_000_000
IMG = '<img src="data:image/png;base64,'

SETUP = RunSetup(
    log=SourceLog(path="/data/<b>drive</b>.mcap", sha256="ab12" * 16, format="mcap"),
    seed=0,
    pipeline=PipelineInfo(first_frame=0),
    algorithms=(
        AlgorithmEntry(name=EVIL, version="3", config_hash="c0ffee" * 10, role=Role.PERCEPTION),
        AlgorithmEntry(name="planner", version="1", config_hash="beef" * 16, role=Role.PLANNING),
    ),
)


def _obj(x: float, y: float, cls: ObjectClass = ObjectClass.VEHICLE, conf: float = 1.0) -> Any:
    return DetectedObject(
        object_id=-1,
        object_class=cls,
        confidence=conf,
        box=Box3D(center=np.array([x, y, 0.8]), size=np.array([4.0, 1.8, 1.5])),
    )


#: frame → (ground truth, detections of EVIL); n_gt 2, 1, 2, 0 and detections 1, 0, 2, 1.
SCENE = {
    0: ((_obj(10, 0), _obj(5, 3, ObjectClass.PEDESTRIAN)), (_obj(10.2, 0, conf=0.9),)),
    1: ((_obj(12, 0),), ()),
    2: ((_obj(8, -2), _obj(20, 5, ObjectClass.BICYCLE)), (_obj(8, -2), _obj(30, -10, conf=0.3))),
    3: ((), (_obj(15, 1, conf=0.5),)),
}
#: step latencies, ms: EVIL 1, 2, 3, 4; planner 5 each.
EVIL_LATENCY_MS = (1, 2, 3, 4)


def build_run(path: Path) -> Path:
    """Write the 4-frame run (real RunWriter) into ``path``."""
    with RunWriter(path, setup=SETUP) as writer:
        for i, (gt, dets) in SCENE.items():
            stamp = T0_NS + i * 100_000_000
            wp = np.column_stack([np.linspace(0, 20, 5), np.zeros(5), np.zeros(5), np.arange(5.0)])
            steps = (
                StepRecord(algorithm=EVIL, stage="detection", role="perception", status="ok",
                           latency_ns=EVIL_LATENCY_MS[i] * 1_000_000, output=dets),
                StepRecord(algorithm="planner", stage="planning", role="planning", status="ok",
                           latency_ns=5_000_000,
                           output=PlannedPath(stamp_ns=stamp, waypoints=wp, frame_id="base_link")),
            )  # fmt: skip
            writer.write_frame(
                FrameRecord(frame_index=i, stamp_ns=stamp, steps=steps, ground_truth=gt)
            )
    return path


def _series(frames: list[int], values: list[float]) -> Series:
    return np.array(frames, dtype=np.int64), np.array(values, dtype=np.float64)


def _curve(x: list[float], y: list[float]) -> tuple[Any, Any]:
    return np.array(x, dtype=np.float64), np.array(y, dtype=np.float64)


class _Fixed(Metric):
    """A metric whose result is given (the report is under test, not the metric)."""

    result: ClassVar[MetricResult]

    def evaluate(self, data: EvalData) -> MetricResult:
        return self.result


class DetMetric(_Fixed):
    name = "det_metric"
    role = Role.PERCEPTION
    version = "2"
    defaults: ClassVar[Mapping[str, Any]] = {"threshold_m": 2.0}
    result = MetricResult(
        values={"mAP": 0.625, "recall": 0.6},
        units={"recall": "ratio"},
        per_frame={"tp": _series([0, 1, 2, 3], [1, 0, 1, 0]), "missed": _series([0, 1, 2], [1, 1, 1])},
        curves={
            "PR/car/2.0": _curve([0.0, 0.5, 1.0], [1.0, 1.0, 0.5]),
            "PR/car/4.0": _curve([0.0, 1.0], [1.0, 0.5]),
            "cumulative": _curve([0.0, 1.0], [1.0, 1.0]),
        },
        bookmarks=[
            Bookmark(frame_index=1, kind="missed_object", detail="car at 12.0 m", severity=1 / 12),
            Bookmark(frame_index=2, kind="false_positive",
                     detail=FORMULA + " <img src=http://evil.example/x.png>", severity=0.5),
            Bookmark(frame_index=2, kind="missed_object", detail="bicycle 20.6 m", severity=0.05),
        ],
    )  # fmt: skip


class LatencyMetric(_Fixed):
    name = "lat"
    role = None
    unit = "ms"
    higher_is_better = False
    result = MetricResult(
        values={"p95_ms": 4.85},
        per_frame={"latency_ms": _series([0, 1, 2, 3], [6.0, 7.0, 8.0, 9.0])},
    )


def evaluate(run_dir: Path) -> None:
    run = open_run(run_dir)
    write_evaluation(
        run,
        [
            Scored(metric=DetMetric(), algorithm=EVIL, result=DetMetric.result),
            Scored(metric=LatencyMetric(), algorithm="", result=LatencyMetric.result),
        ],
    )


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Any]:
    run_dir = build_run(tmp_path_factory.mktemp("report") / "run")
    evaluate(run_dir)
    return run_dir, write_report(run_dir)


def test_files_written(report: tuple[Path, Any]) -> None:
    run_dir, files = report
    assert files.html == run_dir / "report" / "report.html"
    assert [p.name for p in files.paths()] == [
        "report.html", "report.xlsx", "values.csv", "per_frame.csv", "curves.csv", "bookmarks.csv"
    ]  # fmt: skip
    assert all(p.is_file() and p.stat().st_size > 0 for p in files.paths())
    assert not list((run_dir / "report").glob("*.tmp"))


def test_html_has_the_plots(report: tuple[Path, Any]) -> None:
    text = report[1].html.read_text(encoding="utf-8")
    # 1 PR figure (det_metric on EVIL: PR/car/2.0, PR/car/4.0; "cumulative" is not PR)
    # + 2 timelines (det_metric/EVIL: tp, missed; lat/run: latency_ms) + 1 latency figure
    # + 2 bird's-eye snapshots (bookmarked frames 2 and 1) = 6
    assert text.count(IMG) == 6
    for png in re.findall(r'data:image/png;base64,([A-Za-z0-9+/=]+)"', text):
        assert png.startswith("iVBORw0KGgo")  # b"\x89PNG\r\n\x1a\n" in base64
    assert "frame 2</b>" in text
    assert "frame 1</b>" in text
    assert "frame 0</b>" not in text


class _Links(HTMLParser):
    """Tags and their src/href/srcset/action attributes, as a browser's parser sees them."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[str] = []
        self.links: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        for name, value in attrs:
            if name in ("src", "href", "srcset", "action", "data", "poster"):
                self.links.append(value or "")


def test_html_needs_no_network(report: tuple[Path, Any]) -> None:
    text = report[1].html.read_text(encoding="utf-8")
    parser = _Links()
    parser.feed(text)
    # every reference is an inline image or an anchor in the page
    assert parser.links
    assert all(link.startswith(("data:image/png;base64,", "#")) for link in parser.links)
    assert sum(link.startswith("data:") for link in parser.links) == 6
    assert not {"script", "link", "iframe", "object", "embed"} & set(parser.tags)
    assert not re.search(r"@import|url\(", text)
    assert "<style>" in text


def test_html_escapes_strings_of_the_run(report: tuple[Path, Any]) -> None:
    text = report[1].html.read_text(encoding="utf-8")
    assert EVIL not in text
    assert "&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt;" in text
    assert "/data/&lt;b&gt;drive&lt;/b&gt;.mcap" in text
    assert "&lt;img src=http://evil.example/x.png&gt;" in text
    assert "<img src=http" not in text


def test_html_facts_and_headlines(report: tuple[Path, Any]) -> None:
    text = report[1].html.read_text(encoding="utf-8")
    assert "ab12" * 16 in text  # log sha256
    assert "c0ffeec0ffee" in text  # config hash, first 12 characters shown
    assert "<td>frames</td><td>4</td>" in text
    # det_metric headline row: mAP 0.625, better higher; lat headline p95_ms 4.85 ms lower
    assert '<td>det_metric</td><td>mAP</td><td class="num">0.625</td><td></td><td>higher ↑' in text
    assert '<td>lat</td><td>p95_ms</td><td class="num">4.85</td><td>ms</td><td>lower ↓' in text
    assert '<td>recall</td><td class="num">0.6</td><td>ratio</td>' in text
    # latency p50 of EVIL over 1, 2, 3, 4 ms = 2.5 ms (summary table)
    assert '<td class="num">2.5</td>' in text
    assert "Bookmarks (3)" in text


def test_worst_frames_by_severity(tmp_path: Path) -> None:
    run_dir = build_run(tmp_path / "run")
    evaluate(run_dir)
    run = open_run(run_dir)
    ev = read_evaluation(run)
    ranked = worst_frames(run, ev, count=DEFAULT_WORST)
    # severities: frame 2: 0.5 and 0.05, frame 1: 1/12 = 0.0833 → frame 2 first, both its lines
    assert [f for f, _ in ranked] == [2, 1]
    assert ranked[0][1][0].startswith("false_positive (det_metric/" + EVIL + ", severity 0.5)")
    assert ranked[0][1][1] == f"missed_object (det_metric/{EVIL}, severity 0.05): bicycle 20.6 m"
    assert ranked[1][1] == [f"missed_object (det_metric/{EVIL}, severity 0.0833): car at 12.0 m"]
    assert [f for f, _ in worst_frames(run, ev, count=1)] == [2]
    assert worst_frames(run, ev, count=0) == []
    assert render_html(run, ev, worst=1).count(IMG) == 5  # one snapshot fewer


def test_worst_frames_without_bookmarks_are_the_most_missed(tmp_path: Path) -> None:
    run_dir = build_run(tmp_path / "run")
    run = open_run(run_dir)
    write_evaluation(
        run, [Scored(metric=LatencyMetric(), algorithm="", result=LatencyMetric.result)]
    )
    ev = read_evaluation(run)
    # n_gt − detections of EVIL: frame 0: 2 − 1 = 1, frame 1: 1 − 0 = 1, frame 2: 2 − 2 = 0,
    # frame 3: 0 − 1 < 0 → frames 0 and 1 (tie broken by frame index)
    assert worst_frames(run, ev, count=5) == [
        (0, [f"2 ground-truth objects, 1 found by {EVIL}"]),
        (1, [f"1 ground-truth objects, 0 found by {EVIL}"]),
    ]


def test_xlsx(report: tuple[Path, Any]) -> None:
    wb = load_workbook(report[1].xlsx, read_only=True)
    assert wb.sheetnames == [
        "summary", "run", "algorithms", "per_frame", "curves", "bookmarks", "metrics",
    ]  # fmt: skip
    # the summary is one tidy table: a header, then a row per value (issue 17 item 12)
    summary = [list(r) for r in wb["summary"].iter_rows(values_only=True)]
    assert summary[0] == [
        "metric", "algorithm", "value", "number", "unit", "better", "headline", "definition",
        "scores",
    ]  # fmt: skip
    rows = [r[:7] for r in summary[1:]]
    assert rows == [  # an empty string reads back as an empty cell (None)
        ["det_metric", EVIL, "mAP", 0.625, None, "higher", True],
        ["det_metric", EVIL, "recall", 0.6, "ratio", "higher", False],
        ["lat", "(run)", "p95_ms", 4.85, "ms", "lower", True],
    ]
    assert all(r[7].startswith(("v2 params ", "v1 params ")) for r in summary[1:])
    assert [r[8] for r in summary[1:]] == [EVIL, EVIL, "run"]  # whose output each value scores
    # header frozen and filterable on every sheet with rows
    full = load_workbook(report[1].xlsx)
    for name in ("summary", "run", "algorithms", "bookmarks", "metrics"):
        assert full[name].freeze_panes == "A2", name
        assert full[name].auto_filter.ref is not None, name
    facts = [list(r) for r in wb["run"].iter_rows(values_only=True)]
    assert ["log sha256", "ab12" * 16] in facts
    algos = [list(r) for r in wb["algorithms"].iter_rows(values_only=True)]
    assert [EVIL, "perception", "3", "c0ffee" * 10] in algos
    wide = [list(r) for r in wb["per_frame"].iter_rows(values_only=True)]
    assert wide == [
        ["frame_index", f"{EVIL} / det_metric / tp", f"{EVIL} / det_metric / missed",
         "(run) / lat / latency_ms"],
        [0, 1, 1, 6], [1, 0, 1, 7], [2, 1, 1, 8], [3, 0, None, 9],
    ]  # fmt: skip
    marks = [list(r) for r in wb["bookmarks"].iter_rows(values_only=True)]
    assert marks[0][:3] == ["frame_index", "stamp_ns", "kind"]
    assert [m[0] for m in marks[1:]] == [2, 1, 2]  # by severity
    assert marks[1][5] == "'" + FORMULA + " <img src=http://evil.example/x.png>"
    assert marks[1][1] == T0_NS + 200_000_000
    curves = [list(r) for r in wb["curves"].iter_rows(values_only=True)]
    assert len(curves) == 1 + 3 + 2 + 2
    metrics = [list(r) for r in wb["metrics"].iter_rows(values_only=True)]
    assert metrics[1][:2] == ["det_metric", "2"]
    assert metrics[1][5] == '{"threshold_m": 2.0}'


def test_csv(report: tuple[Path, Any]) -> None:
    run_dir = report[0]
    with (run_dir / "report" / "bookmarks.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["frame_index"] for r in rows] == ["2", "1", "2"]
    assert rows[0]["detail"].startswith("'=HYPERLINK")
    assert rows[0]["algorithm"] == EVIL
    with (run_dir / "report" / "values.csv").open(newline="") as f:
        values = list(csv.DictReader(f))
    assert [(v["key"], float(v["value"])) for v in values] == [
        ("mAP", 0.625), ("recall", 0.6), ("p95_ms", 4.85)
    ]  # fmt: skip
    with (run_dir / "report" / "per_frame.csv").open(newline="") as f:
        assert sum(1 for _ in csv.DictReader(f)) == 4 + 3 + 4


def test_not_evaluated_says_what_to_do(tmp_path: Path) -> None:
    run_dir = build_run(tmp_path / "run")
    with pytest.raises(ConfigError, match=r"run `redrive evaluate .*` first"):
        write_report(run_dir)
    assert not (run_dir / "report").exists()


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="redrive")
    cli_report.register(parser.add_subparsers(dest="command"))
    return parser


def test_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run_dir = build_run(tmp_path / "run")
    evaluate(run_dir)
    out = tmp_path / "out"
    args = _parser().parse_args(["report", str(run_dir), "-o", str(out), "--worst", "1"])
    assert args.func(args) == 0
    printed = capsys.readouterr().out.split()
    assert printed == [str(out / n) for n in (
        "report.html", "report.xlsx", "values.csv", "per_frame.csv", "curves.csv", "bookmarks.csv"
    )]  # fmt: skip
    assert (out / "report.html").read_text(encoding="utf-8").count(IMG) == 5  # --worst 1
    assert cli_report.DEFAULT_WORST == DEFAULT_WORST
    assert _parser().parse_args(["report", str(run_dir)]).worst == DEFAULT_WORST
    with pytest.raises(SystemExit):
        _parser().parse_args(["report", str(run_dir), "--worst", "-1"])


def test_cli_not_evaluated(tmp_path: Path) -> None:
    run_dir = build_run(tmp_path / "run")
    args = _parser().parse_args(["report", str(run_dir)])
    with pytest.raises(ConfigError, match="has not been evaluated"):
        args.func(args)


def test_real_detection_metric(tmp_path: Path) -> None:
    """The nuScenes detection metric on the hand-made run: its PR curves and per-frame series
    reach the report (1 PR figure + 1 timeline + latency + snapshots of its bookmarks)."""
    run_dir = build_run(tmp_path / "run")
    summary = evaluate_run(run_dir, metrics=[NuScenesDetection()])
    assert [s.algorithm for s in summary.scored] == [EVIL]
    ev = read_evaluation(open_run(run_dir))
    assert any(c.startswith("PR/") for c in ev.curves.column("curve").to_pylist())
    frames = {f for f, _ in worst_frames(open_run(run_dir), ev, count=DEFAULT_WORST)}
    files = write_report(run_dir)
    text = files.html.read_text(encoding="utf-8")
    assert text.count(IMG) == 1 + 1 + 1 + len(frames)
    assert "nuscenes_detection" in text


def _evaluation(per_frame: list[tuple[str, str, str, int, float]], marks: list[dict]) -> Evaluation:
    from redrive.results.evaluation import BOOKMARKS, CURVES, PER_FRAME, VALUES

    rows = [dict(zip(PER_FRAME.names, (*r, r[1] or "run"), strict=True)) for r in per_frame]
    return Evaluation(
        values=VALUES.empty_table(),
        per_frame=pa.Table.from_pylist(rows, schema=PER_FRAME),
        curves=CURVES.empty_table(),
        bookmarks=pa.Table.from_pylist(marks, schema=BOOKMARKS),
        metrics=(),
        evaluated="",
    )


def test_worst_frames_rank_by_a_score_of_errors_not_by_switch_bookmarks(
    report: tuple[Path, Any],
) -> None:
    """Frame 4 has one identity switch (bookmark severity 1.0), frame 7 three missed objects
    and a false positive (missed-object bookmarks of severity ~0.05): by the documented score
    (missed + fp + switches) frame 7 is worse; --rank-by clear_mot.switches puts frame 4 first."""
    run = open_run(report[0])
    pf = [("nuscenes_detection", "det", "missed", f, float(m)) for f, m in ((4, 0), (7, 3))]
    pf += [("nuscenes_detection", "det", "fp", f, float(m)) for f, m in ((4, 0), (7, 1))]
    pf += [("clear_mot", "det", "switches", f, float(m)) for f, m in ((4, 1), (7, 0))]
    mark = {"stamp_ns": 0, "metric": "clear_mot", "algorithm": "det", "detail": ""}
    marks = [
        {**mark, "frame_index": 4, "kind": "id_switch", "severity": 1.0},
        {**mark, "frame_index": 7, "kind": "missed_object", "severity": 0.05},
    ]
    ev = _evaluation(pf, marks)
    assert frame_scores(ev) == {4: 1.0, 7: 4.0}
    ranked = worst_frames(run, ev, count=2)
    assert [f for f, _ in ranked] == [7, 4]
    assert ranked[0][1][0] == "score (missed + false positives + switches) 4"
    by_switches = worst_frames(run, ev, count=2, rank_by="clear_mot.switches")
    assert [f for f, _ in by_switches] == [4, 7]
    with pytest.raises(ConfigError, match=r"--rank-by latency\.frame_ms: no such per-frame"):
        worst_frames(run, ev, count=2, rank_by="latency.frame_ms")


def test_the_per_frame_plots_tick_whole_frame_indices(monkeypatch: pytest.MonkeyPatch) -> None:
    # issue 35 item 10: a 3-frame run's per-frame plots ticked 0.25, 0.5 … on the frame axis
    from matplotlib.figure import Figure

    from redrive.evaluation import plots

    drawn: list[Figure] = []
    monkeypatch.setattr(plots.h, "png", lambda fig, dpi: drawn.append(fig) or b"")
    frames = np.array([0, 1, 2], dtype=np.int64)
    plots.timelines_png([("tp", frames, np.array([1.0, 2.0, 1.0]))], title="t")
    (fig,) = drawn
    fig.canvas.draw()
    ticks = [t for t in fig.axes[-1].get_xticks() if -0.5 <= t <= 2.5]
    assert ticks
    assert all(float(t).is_integer() for t in ticks), ticks


def test_timelines_drawn_again_are_the_pixels_of_a_new_figure() -> None:
    # the report draws its timelines into the figures of earlier ones (same row count): every
    # pixel must be the one a new figure gives, whatever the earlier figure held (all-NaN
    # series keep the default limits, marks off the data, markers, a 1e6 offset, an empty one)
    import io

    from PIL import Image

    from redrive.evaluation import plots

    rng = np.random.default_rng(7)
    f3, f90 = np.arange(3, dtype=np.int64), np.arange(90, dtype=np.int64)
    cases = [
        ([("a", f90, rng.normal(size=90)), ("b", f90, 1e6 + rng.normal(size=90))], [5, 300]),
        ([("nan", f3, np.full(3, np.nan)), ("c $x$", f3 + 1000, np.ones(3))], []),
        ([("only", f3, np.array([1.0, np.inf, 2.0]))], [-4, 1]),
        ([("nan", f3, np.full(3, np.nan))], []),
        ([], [2]),
        ([("a", f90, -rng.random(90) * 1e-4), ("b", f90, np.zeros(90))], list(range(0, 90, 3))),
    ]
    again: dict[int, Any] = {}
    for series, marks in cases:
        new = plots.timelines_png(series, title="t", marks=marks)
        reused = plots.timelines_png(series, title="t", marks=marks, again=again)
        a, b = (np.asarray(Image.open(io.BytesIO(png))) for png in (new, reused))
        assert a.shape == b.shape
        assert np.array_equal(a, b), [name for name, _, _ in series]
    assert sorted(again) == [1, 2]


def test_the_worst_frames_views_draw_the_log_s_lidar_points(demo_run: Path) -> None:
    # issue 35 item 10: the report's bird's-eye views of the worst frames drew no LiDAR points
    from redrive.assembly.frames import iter_frames
    from redrive.evaluation.frame_points import lidar_points_of_frames
    from redrive.io import open_log
    from redrive.results import open_run

    run = open_run(demo_run)
    got = lidar_points_of_frames(run, [3, 7], max_points=10**9)
    assert set(got) == {3, 7}
    with open_log(run.manifest.log.path) as log:
        frames = {f.index: f for f in iter_frames(log) if f.index in (3, 7)}
    for index, xy in got.items():
        cloud = frames[index].sensors["lidar_top"]
        expect = cloud.data.xyz[:, :2].astype(np.float64) + cloud.sensor_location[:2]
        np.testing.assert_allclose(xy, expect[np.all(np.isfinite(expect), axis=1)])
    assert len(lidar_points_of_frames(run, [3], max_points=1000)[3]) <= 1100  # subsampled
    # no frame asked for: the log is not read
    assert lidar_points_of_frames(run, []) == {}
