"""docs/ci.md's commands are real: each parses with redrive's own parser, and its gates are the
gates the commands check."""

from __future__ import annotations

import re
import shlex

import pytest

from redrive.cli.main import build_parser
from tests.docs._tutorial import DOCS

DOC = DOCS / "ci.md"


def _commands() -> list[list[str]]:
    text = DOC.read_text(encoding="utf-8").replace("\\\n", " ")
    found = []
    for raw in text.splitlines():
        line = re.sub(r"^(- )?run: ", "", raw.strip())
        if line.startswith("redrive "):
            found.append(shlex.split(line.split("#")[0])[1:])
    return found


def test_every_redrive_command_of_the_page_parses() -> None:
    commands = _commands()
    assert {c[0] for c in commands} == {"batch", "compare", "report"}
    parser = build_parser()
    for argv in commands:
        try:
            args = parser.parse_args(argv)
        except SystemExit:
            pytest.fail(f"docs/ci.md: `redrive {' '.join(argv)}` does not parse")
        if argv[0] == "batch":
            assert args.fail_under
            assert args.out is not None
        if argv[0] == "compare":
            assert args.max_regression


def test_the_pipelines_of_the_batch_are_the_ones_compared() -> None:
    text = DOC.read_text(encoding="utf-8")
    stems = set(re.findall(r"--pipeline (\w+)\.toml", text))
    assert stems == {"baseline", "candidate"}
    assert set(re.findall(r"--pipeline-[ab] (\w+)", text)) == stems
