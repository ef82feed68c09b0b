"""docs/algorithms.md runs as written: its files are written, its commands run, in order."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "algorithms.md"
FENCE = re.compile(r"^```(\w+)([^\n]*)\n(.*?)^```", re.MULTILINE | re.DOTALL)


def _steps() -> list[tuple[str, str]]:
    """("file", name + text) and ("command", line) in document order."""
    steps: list[tuple[str, str]] = []
    for lang, info, body in FENCE.findall(DOC.read_text(encoding="utf-8")):
        name = re.search(r"file=(\S+)", info)
        if name:
            steps.append(("file", f"{name[1]}\n{body}"))
        elif lang == "console":
            steps += [("command", line[2:]) for line in body.splitlines() if line.startswith("$ ")]
    return steps


def test_the_doc_has_files_and_commands() -> None:
    kinds = [k for k, _ in _steps()]
    assert kinds.count("file") >= 3
    assert kinds.count("command") >= 5


def test_the_tutorial_runs(tmp_path: Path) -> None:
    for kind, text in _steps():
        if kind == "file":
            name, body = text.split("\n", 1)
            (tmp_path / name).write_text(body, encoding="utf-8")
            continue
        argv = shlex.split(text)
        if argv[0] == "redrive":
            argv = [sys.executable, "-m", "redrive", *argv[1:]]
            if argv[3] == "run":
                argv.append("--no-progress")
        elif argv[0] == "python":
            argv = [sys.executable, *argv[1:]]
        else:
            pytest.fail(f"unknown command in docs/algorithms.md: {text}")
        proc = subprocess.run(
            argv, cwd=tmp_path, capture_output=True, text=True, timeout=300, check=False
        )
        assert proc.returncode == 0, f"$ {text}\n{proc.stdout}\n{proc.stderr}"
    assert (tmp_path / "runs" / "tall" / "manifest.json").is_file()
    assert (tmp_path / "mine" / "lane_keeper.py").is_file()
    assert list((tmp_path / "runs" / "pipeline").rglob("*.xlsx"))
