"""docs/evaluation.md runs as written, and its commands do what the page says."""

from __future__ import annotations

from pathlib import Path

from redrive.results.evaluation import read_evaluation
from tests.docs._tutorial import DOCS, run_tutorial, steps

DOC = DOCS / "evaluation.md"


def test_the_tutorial_runs(tmp_path: Path) -> None:
    assert [k for k, _ in steps(DOC)].count("file") >= 3
    done = run_tutorial(DOC, tmp_path)
    run_a = tmp_path / "runs" / "a"
    report = run_a / "report" / "report.html"
    assert report.is_file()
    assert "<img" in report.read_text(encoding="utf-8")
    assert (run_a / "report" / "report.xlsx").is_file()
    # the user's metric ran from its file
    outputs = "\n".join(p.stdout for p in done)
    assert "near_misses" in outputs
    assert "missed_per_frame" in outputs
    # the A/B step: B (stricter detector) is compared on nuScenes values and ranked frames
    values = read_evaluation(tmp_path / "runs" / "b").values.to_pylist()
    assert {v["metric"] for v in values} == {"nuscenes_detection"}
    html = (tmp_path / "ab.html").read_text(encoding="utf-8")
    assert "nuscenes_detection" in html
    assert "WorseFrame(frame_index=" in done[-1].stdout
