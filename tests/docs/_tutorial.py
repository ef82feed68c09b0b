"""Run a tutorial in docs/ as written: its files are written, its commands run, in order."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[2] / "docs"
FENCE = re.compile(r"^```(\w+)([^\n]*)\n(.*?)^```", re.MULTILINE | re.DOTALL)


def steps(doc: Path) -> list[tuple[str, str]]:
    """("file", name + text) and ("command", line) in document order."""
    found: list[tuple[str, str]] = []
    for lang, info, body in FENCE.findall(doc.read_text(encoding="utf-8")):
        name = re.search(r"file=(\S+)", info)
        if name:
            found.append(("file", f"{name[1]}\n{body}"))
        elif lang == "console":
            found += [("command", line[2:]) for line in body.splitlines() if line.startswith("$ ")]
    return found


def run_tutorial(doc: Path, cwd: Path) -> list[subprocess.CompletedProcess[str]]:
    """Write the files and run the commands of ``doc`` in ``cwd``; fail on the first error."""
    done = []
    for kind, text in steps(doc):
        if kind == "file":
            name, body = text.split("\n", 1)
            (cwd / name).write_text(body, encoding="utf-8")
            continue
        argv = shlex.split(text)
        if argv[0] == "redrive":
            argv = [sys.executable, "-m", "redrive", *argv[1:]]
            if argv[3] == "run":
                argv.append("--no-progress")
        elif argv[0] == "python":
            argv = [sys.executable, *argv[1:]]
        else:
            pytest.fail(f"unknown command in {doc.name}: {text}")
        proc = subprocess.run(
            argv, cwd=cwd, capture_output=True, text=True, timeout=300, check=False
        )
        assert proc.returncode == 0, f"$ {text}\n{proc.stdout}\n{proc.stderr}"
        done.append(proc)
    return done
