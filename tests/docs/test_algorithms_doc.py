"""docs/algorithms.md runs as written: its files are written, its commands run, in order."""

from __future__ import annotations

from pathlib import Path

from tests.docs._tutorial import DOCS, run_tutorial, steps

DOC = DOCS / "algorithms.md"


def test_the_doc_has_files_and_commands() -> None:
    kinds = [k for k, _ in steps(DOC)]
    assert kinds.count("file") >= 3
    assert kinds.count("command") >= 5


def test_the_tutorial_runs(tmp_path: Path) -> None:
    run_tutorial(DOC, tmp_path)
    assert (tmp_path / "runs" / "tall" / "manifest.json").is_file()
    assert (tmp_path / "mine" / "lane_keeper.py").is_file()
    assert list((tmp_path / "runs" / "pipeline").rglob("*.xlsx"))
