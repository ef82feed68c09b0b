"""A named pipe or a device given as a log is refused at once with what it is (issue 37: `mkfifo
x.mcap; redrive info x.mcap` blocked forever, as did run, convert and repair)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.io.readers import recognised_format


@pytest.fixture
def fifo(tmp_path: Path) -> Path:
    path = tmp_path / "x.mcap"
    os.mkfifo(path)
    return path


@pytest.mark.parametrize(
    "argv",
    [
        ["info", "{log}"],
        ["info", "--json", "{log}"],
        ["run", "{log}", "--out", "{tmp}/run"],
        ["convert", "{log}", "{tmp}/y.mcap"],
        ["repair", "{log}", "-o", "{tmp}/y.mcap"],
    ],
)
def test_a_named_pipe_is_refused_at_once(
    argv: list[str], fifo: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = [a.format(log=fifo, tmp=tmp_path) for a in argv]
    assert main(args) == 1
    assert f"{fifo}: a named pipe (FIFO), not a log" in capsys.readouterr().err


def test_a_device_is_refused_and_a_pipe_in_a_folder_is_no_log(fifo: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "redrive", "info", "/dev/zero"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 1
    assert "/dev/zero: a character device, not a log" in done.stderr
    assert recognised_format(fifo) is None  # `redrive batch DIR` passes it over
