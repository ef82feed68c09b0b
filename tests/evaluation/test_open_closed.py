"""Open loop beside closed loop (issue 15, item 5): ``compare`` and ``report --beside`` pair an
open-loop run of a synthetic log with a closed-loop run of the same scenario, seed and pipeline.

Hand-made runs with hand-written metric tables (through the real store), and one end-to-end pair
made by ``redrive synth`` + ``redrive run`` on a 5-s scenario.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from openpyxl import load_workbook

from redrive.errors import ConfigError
from redrive.evaluation import MetricResult
from redrive.evaluation.compare import compare_runs
from redrive.evaluation.report import write_report
from redrive.evaluation.store import Scored, write_evaluation
from redrive.results import RunWriter, SourceLog, open_run
from tests.evaluation.test_compare import FRAMES, Counts, Latency, N, _cli, counts
from tests.results._records import SETUP, frame

SCENARIO = {"name": "urban", "seed": 7, "duration_s": 5.0}


def _write(path: Path, setup: Any, scored: list[tuple[Any, str, MetricResult]]) -> Path:
    with RunWriter(path, setup=setup) as w:
        for i in range(N):
            w.write_frame(frame(i, planning=False))
    write_evaluation(
        open_run(path), [Scored(metric=m, algorithm=a, result=r) for m, a, r in scored]
    )
    return path


def open_loop_run(
    path: Path, *, scenario: Mapping[str, Any] | None = None, recall: float = 0.8
) -> Path:
    """An open-loop replay of a synthetic log of ``scenario`` (default urban, seed 7, 5 s)."""
    log = replace(SETUP.log, sha256="log-sha", scenario=dict(scenario or SCENARIO))
    scored = [(Counts(), "det", counts({"recall": recall}, missed=np.zeros(N), fp=FRAMES % 2))]
    return _write(path, replace(SETUP, log=log), scored)


def closed_loop_run(
    path: Path,
    *,
    seed: int = 7,
    duration_s: float = 5.0,
    scenario: str = "urban",
    algorithms: Any = None,
    agents: str = "replay",
) -> Path:
    """A closed-loop run of the scenario with the same pipeline; it has a run-level metric
    (``lag``) the open-loop run was not evaluated with."""
    setup = replace(
        SETUP,
        log=SourceLog(path=f"scenario:{scenario}", format="scenario", sha256=None, source=scenario),
        pipeline=replace(SETUP.pipeline, mode_manager="closed_loop"),
        closed_loop={
            "backend": "synthetic",
            "scenario": scenario,
            "seed": seed,
            "duration_s": duration_s,
            "agents": agents,
        },
        algorithms=SETUP.algorithms if algorithms is None else algorithms,
    )
    scored = [
        (Counts(), "det", counts({"recall": 0.6}, missed=np.ones(N), fp=FRAMES % 2)),
        (Latency(), "", MetricResult(values={"p95": 15.0})),
    ]
    return _write(path, setup, scored)


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("open_closed")
    return open_loop_run(root / "open"), closed_loop_run(root / "closed")


def test_pairing_recognised_in_either_order(pair: tuple[Path, Path]) -> None:
    open_, closed = pair
    cmp = compare_runs(open_, closed, bootstrap=50)
    p = cmp.pairing
    assert (p.open_closed, p.loop_a, p.loop_b) == (True, "open loop", "closed loop")
    assert p.source == cmp.log_sha256 == "scenario urban seed 7 duration 5.0 s"
    assert p.pipeline_differences == ()
    assert "the same pipeline" in p.describe()
    assert p.notes == ("closed loop agents: replay (as scripted, as in the log)",)
    back = compare_runs(closed, open_, bootstrap=50).pairing
    assert (back.loop_a, back.loop_b, back.label_a) == (
        "closed loop",
        "open loop",
        "A (closed loop)",
    )


def test_both_values_and_one_sided_metrics_shown(pair: tuple[Path, Path]) -> None:
    cmp = compare_runs(*pair, bootstrap=50)
    v = {(x.metric, x.key): x for x in cmp.values}
    recall = v["counts", "recall"]
    assert (recall.a, recall.b, recall.verdict) == (0.8, 0.6, "worse")
    lag = v["lag", "p95"]  # only the closed-loop run was evaluated with it: listed, not dropped
    assert (lag.in_a, lag.in_b, lag.b, lag.verdict) == (False, True, 15.0, "only B")
    assert np.isnan(lag.a)
    assert lag.higher_is_better is False
    assert not [k for k in cmp.skipped if k.metric == "lag"]


def test_a_plain_ab_still_skips_what_one_run_lacks(tmp_path: Path) -> None:
    """Two open-loop runs of one log: a metric only one has stays 'not compared' (unchanged)."""
    a = open_loop_run(tmp_path / "a")
    log = replace(SETUP.log, sha256="log-sha")
    scored = [
        (Counts(), "det", counts({"recall": 0.5}, missed=np.zeros(N), fp=FRAMES % 2)),
        (Latency(), "", MetricResult(values={"p95": 1.0})),
    ]
    b = _write(tmp_path / "b", replace(SETUP, log=log), scored)
    cmp = compare_runs(a, b, bootstrap=50)
    assert not cmp.pairing.open_closed
    assert [k.reason for k in cmp.skipped if k.metric == "*"] == [
        "algorithm '' has no evaluation in A"
    ]


@pytest.mark.parametrize(
    ("closed", "message"),
    [
        ({"seed": 8}, r"seed differ.*--seed 7"),
        ({"duration_s": 10.0}, r"duration_s differ.*--duration 5\.0"),
        ({"scenario": "highway"}, r"scenario differ.*run the closed loop on scenario urban"),
    ],
)
def test_mismatched_scenario_refused(tmp_path: Path, closed: dict[str, Any], message: str) -> None:
    open_ = open_loop_run(tmp_path / "open")
    other = closed_loop_run(tmp_path / "closed", **closed)
    with pytest.raises(ConfigError, match=message):
        compare_runs(open_, other)
    with pytest.raises(ConfigError, match="not the same situation"):
        compare_runs(other, open_)


def test_log_without_scenario_refused(tmp_path: Path) -> None:
    """A replay of a log that records no scenario (a recorded log, an old synth log)."""
    log = replace(SETUP.log, sha256="log-sha")
    plain = _write(
        tmp_path / "open",
        replace(SETUP, log=log),
        [(Latency(), "", MetricResult(values={"p95": 1.0}))],
    )
    closed = closed_loop_run(tmp_path / "closed")
    with pytest.raises(ConfigError, match="records no scenario"):
        compare_runs(plain, closed)


def test_different_pipelines_flagged(tmp_path: Path) -> None:
    open_ = open_loop_run(tmp_path / "open")
    algos = tuple(
        replace(a, config_hash="other", config={"v0_mps": 20.0}) if a.name == "planner" else a
        for a in SETUP.algorithms
    )
    closed = closed_loop_run(tmp_path / "closed", algorithms=algos, agents="reactive")
    p = compare_runs(open_, closed, bootstrap=50).pairing
    assert p.pipeline_differences == ("planner: configuration differs (v0_mps '—' → 20.0)",)
    assert "DIFFERENT pipelines (planner: configuration differs" in p.describe()
    assert "they react to the driven ego" in p.notes[0]


def test_cli_text_json_html(
    pair: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    open_, closed = pair
    html = tmp_path / "oc.html"
    assert _cli(["compare", str(open_), str(closed), "--bootstrap", "50", "--html", str(html)]) == 0
    out = capsys.readouterr().out
    assert (
        "open loop beside closed loop: A is open loop, B is closed loop, the same pipeline" in out
    )
    assert "A (open loop)" in out
    assert "B (closed loop)" in out
    assert "Δ = B − A = closed loop − open loop" in out
    lag_row = next(line for line in out.splitlines() if "lag" in line and "p95" in line)
    assert "—" in lag_row
    assert "15" in lag_row
    assert "only B" in lag_row
    page = html.read_text(encoding="utf-8")
    assert "Open loop beside closed loop" in page
    assert '<th class="num">A (open loop)</th>' in page
    assert '<td class="num">—</td>' in page
    assert _cli(["compare", str(closed), str(open_), "--json", "--bootstrap", "50"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["pairing"] == {
        "kind": "open/closed",
        "a": "closed loop",
        "b": "open loop",
        "source": "scenario urban seed 7 duration 5.0 s",
        "same_pipeline": True,
        "pipeline_differences": [],
        "notes": ["closed loop agents: replay (as scripted, as in the log)"],
    }
    lag = next(v for v in data["values"] if v["metric"] == "lag")
    assert (lag["a"], lag["b"], lag["in_a"], lag["in_b"]) == (15.0, None, True, False)


def test_report_beside(pair: tuple[Path, Path], tmp_path: Path) -> None:
    open_, closed = pair
    files = write_report(closed, out=tmp_path / "rep", worst=0, beside=open_)
    assert files.csvs[-1].name == "beside.csv"
    page = files.html.read_text(encoding="utf-8")
    section = page[page.index('<section id="beside">') :]
    section = section[: section.index("</section>")]
    assert "Open loop beside closed loop" in section
    assert "closed (closed loop)" in section
    assert "open (open loop)" in section
    assert "A is closed loop, B is open loop, the same pipeline" in section
    lag = section[section.index("<td>lag</td>") :]
    lag = lag[: lag.index("</tr>")]
    assert '<td class="num">15</td><td class="num">—</td>' in lag
    assert "only in closed (closed loop)" in lag
    recall = section[section.index("<td>recall</td>") :]
    recall = recall[: recall.index("</tr>")]
    assert '<td class="num">0.6</td><td class="num">0.8</td>' in recall
    assert "open (open loop)" in recall  # the better value is the open loop's
    wb = load_workbook(files.xlsx, read_only=True)
    rows = [list(r) for r in wb["beside"].iter_rows(values_only=True)]
    head = rows.index(["metric", "algorithm", "value", "unit", "higher_is_better",
                       "closed (closed loop)", "open (open loop)", "delta", "better in"])  # fmt: skip
    table = {(r[0], r[2]): r for r in rows[head + 1 :]}
    assert table["lag", "p95"][5:8] == [15.0, None, None]
    assert table["counts", "recall"][5:7] == [0.6, 0.8]
    assert "beside" not in load_workbook(write_report(closed, out=tmp_path / "plain", worst=0).xlsx,
                                         read_only=True).sheetnames  # fmt: skip


def test_report_beside_refuses_another_situation(tmp_path: Path) -> None:
    open_ = open_loop_run(tmp_path / "open", scenario={**SCENARIO, "seed": 3})
    closed = closed_loop_run(tmp_path / "closed")
    with pytest.raises(ConfigError, match=r"seed differ.*--seed 3"):
        write_report(closed, out=tmp_path / "rep", beside=open_)


def test_synth_log_and_closed_loop_pair_end_to_end(tmp_path: Path) -> None:
    """`redrive synth` records the scenario, the replay stores it, and the replay of the log
    and the closed loop of the scenario (same pipeline) pair for compare."""
    from redrive.cli.main import main
    from redrive.evaluation.closedloop.motion import EgoProgress
    from redrive.evaluation.evaluator import evaluate_run

    log = tmp_path / "u.mcap"
    assert main(["synth", "urban", "--duration", "5", "-o", str(log)]) == 0
    pipeline = ["--perception", "noisy-oracle", "--planning", "idm-planner", "--no-progress"]
    assert main(["run", str(log), "--out", str(tmp_path / "open"), *pipeline]) == 0
    closed_argv = ["run", "urban", "--closed-loop", "--duration", "5", "--out"]
    assert main([*closed_argv, str(tmp_path / "closed"), *pipeline]) == 0
    assert open_run(tmp_path / "open").manifest.log.scenario == SCENARIO
    for name in ("open", "closed"):
        evaluate_run(tmp_path / name, metrics=[EgoProgress()])
    cmp = compare_runs(tmp_path / "closed", tmp_path / "open", bootstrap=50)
    assert cmp.pairing.open_closed
    assert cmp.pairing.pipeline_differences == ()
    assert cmp.log_sha256 == "scenario urban seed 7 duration 5.0 s"
    progress = next(v for v in cmp.values if v.key == "ego_progress_m")
    assert progress.in_a
    assert progress.in_b
    assert progress.a > 10.0
    assert progress.b > 10.0
