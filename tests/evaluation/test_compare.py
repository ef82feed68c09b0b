"""A/B comparison: hand-made runs with hand-written metric tables (through the real store)."""

from __future__ import annotations

import argparse
import base64
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

from redrive.cli import compare as compare_cli
from redrive.errors import ConfigError
from redrive.evaluation import Bookmark, EvalData, Metric, MetricResult
from redrive.evaluation.compare import compare_runs, paired_bootstrap
from redrive.evaluation.compare_html import delta_bars
from redrive.evaluation.store import Scored, write_evaluation
from redrive.results import RunWriter, open_run
from redrive.types import Role
from tests.results._records import SETUP, T0_NS, frame

N = 40
FRAMES = np.arange(N, dtype=np.int64)


class Counts(Metric):
    """Hand-written results only (evaluate is never called)."""

    name = "counts"
    role = Role.PERCEPTION
    unit = "objects"
    defaults: ClassVar[Mapping[str, Any]] = {"range_m": 50.0}

    def evaluate(self, data: EvalData) -> MetricResult:
        raise AssertionError("results are written by hand")


class CountsV2(Counts):
    version = "2"


class Latency(Metric):
    """Run-level, lower is better."""

    name = "lag"
    role = None
    unit = "ms"
    higher_is_better = False

    def evaluate(self, data: EvalData) -> MetricResult:
        raise AssertionError("results are written by hand")


def make_run(
    path: Path,
    scored: Sequence[tuple[Metric, str, MetricResult]],
    *,
    sha: str = "abc",
    n: int = N,
    rename: Mapping[str, str] | None = None,
) -> Path:
    """``rename``: algorithms of the manifest under another name (a new version renamed)."""
    log = replace(SETUP.log, sha256=sha)
    algos = tuple(replace(x, name=(rename or {}).get(x.name, x.name)) for x in SETUP.algorithms)
    with RunWriter(path, setup=replace(SETUP, log=log, algorithms=algos)) as w:
        for i in range(n):
            w.write_frame(frame(i, planning=False))
    write_evaluation(
        open_run(path), [Scored(metric=m, algorithm=a, result=r) for m, a, r in scored]
    )
    return path


def counts(
    values: Mapping[str, float],
    *,
    missed: Any = None,
    fp: Any = None,
    frames: Any = FRAMES,
    bookmarks: Sequence[Bookmark] = (),
) -> MetricResult:
    per_frame = {"gt": (frames, np.full(len(frames), 3.0))}
    if missed is not None:
        per_frame["missed"] = (frames, np.asarray(missed, dtype=np.float64))
    if fp is not None:
        per_frame["fp"] = (frames, np.asarray(fp, dtype=np.float64))
    return MetricResult(
        values=values,
        units={"ate": "m"},
        higher_is_better={"ate": False, "num_missed": False},
        per_frame=per_frame,
        bookmarks=bookmarks,
    )


# A misses nothing; B misses one object on frames 0..19 (a clear shift of +0.5 per frame).
MISSED_A = np.zeros(N)
MISSED_B = np.where(FRAMES < 20, 1.0, 0.0)
# false positives: A on even frames, B on odd frames (noise: mean difference exactly 0).
FP_A = np.where(FRAMES % 2 == 0, 1.0, 0.0)
FP_B = 1.0 - FP_A


@pytest.fixture(scope="module")
def ab(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("ab")
    a = make_run(
        root / "a",
        [
            (Counts(), "det", counts(
                {"recall": 0.8, "ate": 0.5, "num_missed": 0.0, "zero": 0.0, "same": 2.0,
                 "undefined": float("nan")},
                missed=MISSED_A, fp=FP_A)),
            (Latency(), "", MetricResult(values={"p95": 12.0})),
        ],
    )  # fmt: skip
    b = make_run(
        root / "b",
        [
            (Counts(), "det", counts(
                {"recall": 0.6, "ate": 0.4, "num_missed": 20.0, "zero": 1.0, "same": 2.0,
                 "undefined": 1.0},
                missed=MISSED_B, fp=FP_B)),
            (Latency(), "", MetricResult(values={"p95": 15.0})),
        ],
    )  # fmt: skip
    return a, b


def test_value_deltas_and_directions(ab: tuple[Path, Path]) -> None:
    cmp = compare_runs(*ab)
    assert cmp.log_sha256 == "abc"
    assert cmp.pairs == (("", ""), ("det", "det"))
    assert cmp.skipped == ()
    v = {(x.metric, x.key): x for x in cmp.values}
    recall = v["counts", "recall"]  # higher is better (the metric's default)
    assert recall.delta == pytest.approx(-0.2)  # 0.6 − 0.8
    assert recall.relative_delta == pytest.approx(-0.25)  # −0.2 / 0.8
    assert recall.verdict == "worse"
    ate = v["counts", "ate"]  # lower is better (per value)
    assert (ate.unit, ate.higher_is_better) == ("m", False)
    assert ate.delta == pytest.approx(-0.1)  # 0.4 − 0.5
    assert ate.relative_delta == pytest.approx(-0.2)  # −0.1 / 0.5
    assert ate.verdict == "better"
    assert math.isnan(v["counts", "zero"].relative_delta)  # A = 0: no relative change
    assert v["counts", "zero"].verdict == "better"
    assert v["counts", "same"].verdict == "same"
    assert v["counts", "undefined"].verdict == "n/a"
    lag = v["lag", "p95"]  # run-level metric, lower is better: 15 − 12 = +3 ms is worse
    assert (lag.algorithm_a, lag.delta, lag.verdict) == ("", 3.0, "worse")
    assert lag.note == "no per-frame series: no significance test"


def test_bootstrap_clear_shift_and_noise(ab: tuple[Path, Path]) -> None:
    cmp = compare_runs(*ab, bootstrap=4000, seed=3)
    s = {x.series: x for x in cmp.series}
    missed, fp, gt = s["missed"], s["fp"], s["gt"]
    assert (missed.higher_is_better, fp.higher_is_better, gt.higher_is_better) == (
        False,
        False,
        None,
    )
    # shift: d = 1 on 20 of 40 frames → mean 0.5; sd (ddof 0) 0.5; normal approximation of the
    # percentile CI: 0.5 ± 1.96 · 0.5 / √40 = 0.5 ± 0.155 → [0.345, 0.655]
    bm = missed.bootstrap
    assert (bm.n_frames, bm.resamples) == (40, 4000)
    assert bm.mean_delta == pytest.approx(0.5)
    assert bm.ci_low == pytest.approx(0.345, abs=0.04)
    assert bm.ci_high == pytest.approx(0.655, abs=0.04)
    assert bm.excludes_zero
    # noise: d = ±1 alternating → mean 0; sd 1 → 0 ± 1.96 / √40 = ±0.31
    bf = fp.bootstrap
    assert bf.mean_delta == pytest.approx(0.0)
    assert bf.ci_low == pytest.approx(-0.31, abs=0.05)
    assert bf.ci_high == pytest.approx(0.31, abs=0.05)
    assert not bf.excludes_zero
    assert (gt.bootstrap.ci_low, gt.bootstrap.ci_high, gt.bootstrap.excludes_zero) == (
        0.0,
        0.0,
        False,
    )
    # a value named after a series carries the bootstrap of the statistic it is: num_missed is
    # the sum of the per-frame misses, so its CI is of the sum (40 × the mean's), around its Δ
    v = {x.key: x for x in cmp.values if x.metric == "counts"}
    assert v["num_missed"].series == "missed"
    nb = v["num_missed"].bootstrap
    assert nb is not None
    assert nb.statistic == "sum"
    assert nb.mean_delta == pytest.approx(v["num_missed"].delta) == pytest.approx(20.0)
    assert nb.ci_low == pytest.approx(40 * 0.345, abs=40 * 0.04)
    assert nb.ci_high == pytest.approx(40 * 0.655, abs=40 * 0.04)
    assert nb.ci_low <= v["num_missed"].delta <= nb.ci_high
    assert "excludes 0" in v["num_missed"].note
    assert v["num_missed"].significance.startswith("sum [")
    assert v["num_missed"].significance.endswith("≠ 0")
    assert v["recall"].bootstrap is None
    assert v["recall"].note.startswith("not a per-frame mean")
    assert "missed +0.5" in v["recall"].note
    assert "fp +0" in v["recall"].note
    assert "gt " not in v["recall"].note  # neutral series are not a significance note


def test_paired_bootstrap_seeded_and_against_scipy() -> None:
    d = np.random.default_rng(9).normal(0.0, 1.0, 40)
    one = paired_bootstrap(d, resamples=500, seed=1)
    assert one == paired_bootstrap(d, resamples=500, seed=1)  # seeded: reproducible
    assert one.ci_low != paired_bootstrap(d, resamples=500, seed=2).ci_low
    # n = 1: every resample is the one frame
    single = paired_bootstrap(np.array([3.0]), resamples=10)
    assert (single.ci_low, single.ci_high, single.n_frames) == (3.0, 3.0, 1)
    empty = paired_bootstrap(np.array([np.nan]))
    assert empty.n_frames == 0
    assert not empty.excludes_zero
    with pytest.raises(ConfigError, match="at least 1"):
        paired_bootstrap(d, resamples=0)
    # the same definition as scipy's percentile bootstrap (different draws: agree to ~0.02)
    from scipy.stats import bootstrap

    rng = np.random.default_rng(5)
    x = rng.normal(0.3, 1.0, 60)
    ours = paired_bootstrap(x, resamples=20000, seed=0)
    ref = bootstrap((x,), np.mean, n_resamples=20000, method="percentile", random_state=1)
    assert ours.ci_low == pytest.approx(ref.confidence_interval.low, abs=0.02)
    assert ours.ci_high == pytest.approx(ref.confidence_interval.high, abs=0.02)


def test_frames_missing_or_nan_are_not_paired(tmp_path: Path) -> None:
    missed_b = MISSED_B.copy()
    missed_b[5] = np.nan  # B undefined on frame 5
    a = make_run(tmp_path / "a", [(Counts(), "det", counts({"r": 1.0}, missed=MISSED_A))])
    b = make_run(
        tmp_path / "b",
        [(Counts(), "det", counts({"r": 1.0}, missed=missed_b[:30], frames=FRAMES[:30]))],
    )
    s = next(x for x in compare_runs(a, b).series if x.series == "missed")
    # frames both have: 0..29 without 5 → 29; A only: 5 and 30..39 → 11
    assert (s.bootstrap.n_frames, s.only_a, s.only_b) == (29, 11, 0)
    assert 5 not in s.frames.tolist()
    assert s.bootstrap.mean_delta == pytest.approx(19 / 29)  # frames 0..19 without 5


def test_different_logs_refused(tmp_path: Path) -> None:
    a = make_run(tmp_path / "a", [(Counts(), "det", counts({"r": 1.0}))], n=2)
    b = make_run(tmp_path / "b", [(Counts(), "det", counts({"r": 1.0}))], sha="def", n=2)
    with pytest.raises(ConfigError) as err:
        compare_runs(a, b)
    msg = str(err.value)
    assert "abc" in msg
    assert "def" in msg
    assert str(a / "manifest.json") in msg
    assert str(b / "manifest.json") in msg


def test_different_definitions_not_compared(tmp_path: Path) -> None:
    # A run stores one definition per metric name, so each difference gets its own pair of runs.
    a = make_run(
        tmp_path / "a",
        [
            (Counts(), "det", counts({"r": 1.0})),
            (Latency(), "", MetricResult(values={"p95": 1.0})),
        ],
        n=2,
    )
    b = make_run(tmp_path / "b", [(Counts(range_m=30.0), "det", counts({"r": 0.0}))], n=2)
    cmp = compare_runs(a, b)
    assert cmp.values == ()
    assert cmp.series == ()
    reasons = {(k.metric, k.algorithm_a): k.reason for k in cmp.skipped}
    assert reasons == {
        ("counts", "det"): "parameters differ (range_m: 50.0 → 30.0)",
        ("*", ""): "algorithm '' has no evaluation in B",
    }
    assert cmp.to_tables()["skipped"].num_rows == 2

    v2 = make_run(tmp_path / "v2", [(CountsV2(), "det", counts({"r": 1.0}))], n=2)
    v1 = make_run(tmp_path / "v1", [(Counts(), "det", counts({"r": 0.0}))], n=2)
    cmp = compare_runs(v2, v1)
    assert cmp.values == ()
    assert {(k.metric, k.algorithm_a): k.reason for k in cmp.skipped} == {
        ("counts", "det"): "version 2 in A, 1 in B"
    }


def test_explicit_pairing(tmp_path: Path) -> None:
    a = make_run(tmp_path / "a", [(Counts(), "det", counts({"r": 1.0}))], n=2)
    b = make_run(tmp_path / "b", [(Counts(), "det_v2", counts({"r": 0.5}))], n=2)
    by_name = compare_runs(a, b)
    assert by_name.values == ()
    assert {k.reason for k in by_name.skipped} == {
        "algorithm 'det' has no evaluation in B and no single algorithm of its role there to "
        "pair with: pair it with --algorithm-a/--algorithm-b",
        "algorithm 'det_v2' has no evaluation in A and no single algorithm of its role there to "
        "pair with: pair it with --algorithm-a/--algorithm-b",
    }
    cmp = compare_runs(a, b, algorithm_a="det", algorithm_b="det_v2")
    assert cmp.pairs == (("det", "det_v2"),)
    (v,) = cmp.values
    assert (v.algorithm_a, v.algorithm_b, v.delta, v.verdict) == ("det", "det_v2", -0.5, "worse")
    with pytest.raises(ConfigError, match=r"no evaluated algorithm 'nope' \(evaluated: det_v2\)"):
        compare_runs(a, b, algorithm_a="det", algorithm_b="nope")


def test_renamed_algorithms_pair_by_role(tmp_path: Path) -> None:
    """A's only evaluated detector 'det' and B's 'det_v2' (the manifest's perception algorithm
    renamed): paired by their role without flags (issue 17 item 7)."""
    a = make_run(tmp_path / "a", [(Counts(), "det", counts({"r": 1.0}))], n=2)
    b = make_run(
        tmp_path / "b", [(Counts(), "det_v2", counts({"r": 0.5}))], n=2, rename={"det": "det_v2"}
    )
    cmp = compare_runs(a, b)
    assert cmp.pairs == (("det", "det_v2"),)
    (v,) = cmp.values
    assert (v.algorithm_a, v.algorithm_b, v.verdict) == ("det", "det_v2", "worse")
    assert cmp.skipped == ()


def _worst_pair(tmp_path: Path) -> tuple[Path, Path]:
    f = FRAMES[:10]
    missed_a = np.zeros(10)
    missed_a[1] = 1.0  # A misses one on frame 1 (B does better there)
    missed_b = np.zeros(10)
    missed_b[3], missed_b[7] = 2.0, 1.0
    fp_a, fp_b = np.zeros(10), np.zeros(10)
    fp_b[7] = 4.0
    shared = Bookmark(frame_index=3, kind="missed_object", detail="car at 9.0 m not detected")
    a = make_run(
        tmp_path / "a",
        [(Counts(), "det", counts({"r": 1.0}, missed=missed_a, fp=fp_a, frames=f,
                                  bookmarks=[shared]))],
        n=10,
    )  # fmt: skip
    new = Bookmark(frame_index=3, kind="missed_object", detail="car at 12.0 m <not> detected")
    b = make_run(
        tmp_path / "b",
        [(Counts(), "det", counts({"r": 0.5, "x<script>alert(1)</script>": 1.0},
                                  missed=missed_b, fp=fp_b, frames=f, bookmarks=[shared, new]))],
        n=10,
    )  # fmt: skip
    return a, b


def test_worst_frames_ranking(tmp_path: Path) -> None:
    cmp = compare_runs(*_worst_pair(tmp_path))
    # missed (lower is better): worsening B − A = +2 on frame 3, +1 on frame 7, −1 on frame 1;
    #   largest |worsening| 2 → frame 3: 2/2 = 1.0, frame 7: 1/2 = 0.5 (frame 1 improves: 0)
    # fp: +4 on frame 7 → 4/4 = 1.0
    # scores: frame 7 = 0.5 + 1.0 = 1.5, frame 3 = 1.0; nothing else is worse
    worst = cmp.worst_frames()
    assert [w.frame_index for w in worst] == [7, 3]
    assert [w.score for w in worst] == pytest.approx([1.5, 1.0])
    assert worst[0].stamp_ns == T0_NS + 7 * 100_000_000
    assert worst[0].differences == (
        "counts[det]/fp 0 → 4 (+4, worse)",
        "counts[det]/missed 0 → 1 (+1, worse)",
    )
    assert worst[1].new_bookmarks == (
        "counts[det] missed_object: car at 12.0 m <not> detected",
    )  # the bookmark both runs have is not new
    assert cmp.worst_frames(1) == worst[:1]
    tables = cmp.to_tables()
    wt = tables["worst_frames"].to_pylist()
    assert [r["frame_index"] for r in wt] == [7, 3]
    pf = tables["per_frame"].to_pylist()
    row = next(r for r in pf if r["series"] == "missed" and r["frame_index"] == 1)
    assert (row["a"], row["b"], row["delta"], row["worsening"]) == (1.0, 0.0, -1.0, -1.0)
    assert tables["per_frame"].num_rows == 3 * 10  # gt, missed, fp × 10 frames
    assert set(tables) == {
        "values",
        "log_values",
        "series",
        "per_frame",
        "worst_frames",
        "skipped",
    }


def test_html_self_contained_and_escaped(tmp_path: Path) -> None:
    cmp = compare_runs(*_worst_pair(tmp_path))
    out = cmp.write_html(tmp_path / "out" / "ab.html")
    text = out.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>")
    assert "<style>" in text
    assert "<script>" not in text
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in text
    assert "car at 12.0 m &lt;not&gt; detected" in text
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", text)  # no network
    pngs = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    assert len(pngs) == 2  # delta bar chart, per-frame delta timeline
    assert all(base64.b64decode(p)[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)
    assert not list((tmp_path / "out").glob("*.tmp"))


def _cli(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="redrive")
    compare_cli.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    status: int = args.func(args)
    return status


def test_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a, b = _worst_pair(tmp_path)
    html_path = tmp_path / "ab.html"
    assert _cli(["compare", str(a), str(b), "--worst", "1", "--html", str(html_path)]) == 0
    out = capsys.readouterr().out
    assert "worse" in out
    assert "counts[det]/fp 0 → 4 (+4, worse)" in out
    assert f"HTML: {html_path}" in out
    assert html_path.is_file()
    assert _cli(["compare", str(a), str(b), "--json", "--worst", "1", "--bootstrap", "50"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [w["frame_index"] for w in data["worst_frames"]] == [7]
    assert data["bootstrap"] == {"resampled": "frames", "resamples": 50, "seed": 0}
    r = next(v for v in data["values"] if v["key"] == "r")
    assert (r["a"], r["b"], r["verdict"], r["relative_delta"]) == (1.0, 0.5, "worse", -0.5)
    unevaluated = tmp_path / "plain"
    with RunWriter(unevaluated, setup=SETUP) as w:
        w.write_frame(frame(0, planning=False))
    with pytest.raises(ConfigError, match="has not been evaluated"):
        _cli(["compare", str(a), str(unevaluated)])


_DETECTION_STAGE = """
[[stage]]
name = "detection"
[[stage.algorithm]]
name = "clusters"
plugin = "cluster-detector"
config = {config}
"""


def test_demo_runs_with_different_detector_parameters(tmp_path: Path, demo_log: Path) -> None:
    """Two runs of the demo log; B's detector needs 5× the points and sees half as far: the
    frames where B misses objects A finds are ranked first."""
    nuscenes = pytest.importorskip("redrive.evaluation.detection.nuscenes")
    from redrive.cli.main import main
    from redrive.evaluation.evaluator import evaluate_run

    runs = []
    for name, config in (("a", "{}"), ("b", "{ min_points = 60, range_m = 40.0 }")):
        toml = tmp_path / f"{name}.toml"
        toml.write_text(_DETECTION_STAGE.format(config=config), encoding="utf-8")
        out = tmp_path / name
        argv = ["run", str(demo_log), "--pipeline", str(toml), "--frames", "80:100"]
        assert main([*argv, "--out", str(out), "--no-progress"]) == 0
        evaluate_run(out, metrics=[nuscenes.NuScenesDetection()])
        runs.append(out)
    cmp = compare_runs(*runs)
    missed = next(s for s in cmp.series if s.series == "missed")
    assert missed.bootstrap.n_frames == 20
    more = set(missed.frames[missed.b > missed.a].tolist())  # B misses what A finds
    assert more, "B's detector should miss objects A's finds"
    ranked = [w.frame_index for w in cmp.worst_frames()]
    assert more <= set(ranked)
    top = cmp.worst_frames(1)[0]
    assert any("/missed" in d and d.endswith("worse)") for d in top.differences)
    assert missed.bootstrap.mean_delta > 0


def test_bar_chart_is_right_for_better_in_each_direction(ab: tuple[Path, Path]) -> None:
    """A latency that drops is a bar to the right (better); one that rises, to the left; the
    same for an error (ate) against a score (recall) (issue 17 item 2)."""
    a, b = ab
    bars = dict(delta_bars(compare_runs(a, b)))
    assert bars["lag p95"] == pytest.approx(-25.0)  # 12 → 15 ms: worse, left
    assert bars["counts[det] ate"] == pytest.approx(20.0)  # 0.5 → 0.4 m: better, right
    assert bars["counts[det] recall"] == pytest.approx(-25.0)  # 0.8 → 0.6: worse, left
    back = dict(delta_bars(compare_runs(b, a)))
    assert back["lag p95"] == pytest.approx(20.0)  # 15 → 12 ms: better, right


def test_cli_text_fits_a_screen_and_says_where_the_rest_is(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    many = {f"v{i:03d}": float(i) for i in range(200)}
    a = make_run(tmp_path / "a", [(Counts(), "det", counts(many))], n=2)
    b = make_run(
        tmp_path / "b", [(Counts(), "det", counts({k: v + 1 for k, v in many.items()}))], n=2
    )
    assert _cli(["compare", str(a), str(b), "--bootstrap", "50"]) == 0
    out = capsys.readouterr().out
    assert "v000" in out  # the headline
    assert "v150" not in out
    assert "199 more values" in out
    assert "--all lists every row" in out
    assert len(out.splitlines()) < 80
    assert _cli(["compare", str(a), str(b), "--bootstrap", "50", "--all"]) == 0
    assert "v150" in capsys.readouterr().out


def test_verdict_of_infinite_values() -> None:
    from redrive.evaluation.deltas import verdict

    inf = math.inf
    assert verdict(inf, inf, True) == "same"  # min TTC with nobody ahead on both sides
    assert verdict(inf, 3.0, True) == "worse"
    assert verdict(2.0, inf, True) == "better"
    assert verdict(-inf, inf, False) == "worse"
    assert verdict(math.nan, 1.0, True) == "n/a"
    assert verdict(1.0, 2.0, None) == "changed"


def test_cli_names_series_only_one_run_has_instead_of_rows_of_na(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A's latency has a stage B's pipeline lacks (h-tour: the per-frame table listed it as a
    row of 0 frames and n/a): it is named under the table as only in A; --all keeps the row."""
    t = np.linspace(10.0, 12.0, N)

    def lag(**series: Any) -> MetricResult:
        return MetricResult(
            values={"p95": 12.0}, per_frame={k: (FRAMES, v) for k, v in series.items()}
        )

    a = make_run(tmp_path / "a", [(Latency(), "", lag(frame_ms=t, **{"stage:detection": t / 2}))])
    b = make_run(tmp_path / "b", [(Latency(), "", lag(frame_ms=t + 1.0))])
    assert _cli(["compare", str(a), str(b), "--bootstrap", "50"]) == 0
    out = capsys.readouterr().out
    table = out.split("per-frame series", 1)[1].split("frames where B", 1)[0]
    assert "lag/frame_ms" in table
    assert "only in A, so not compared: lag/stage:detection" in table
    assert not any("stage:detection" in line and "n/a" in line for line in table.splitlines())
    assert _cli(["compare", str(a), str(b), "--bootstrap", "50", "--all"]) == 0
    everything = capsys.readouterr().out
    assert any("lag/stage:detection" in line and "n/a" in line for line in everything.splitlines())
