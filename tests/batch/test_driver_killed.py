"""A SIGKILLed ``redrive batch`` driver takes its local workers with it (issue 37: after a
killed batch its workers kept running and overlapped the rerun's workers on the same cells)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

PLUGINS = Path(__file__).with_name("plugins.py")
_SRC = Path(__file__).resolve().parents[2] / "src"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_the_workers_of_a_killed_driver_die_with_it(logs: list[Path], tmp_path: Path) -> None:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(_SRC), os.environ.get("PYTHONPATH", "")]),
    }
    driver = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "redrive",
            "batch",
            str(logs[0]),
            str(logs[1]),
            "--planning",
            f"{PLUGINS}:Sleepy",
            "--workers",
            "2",
            "--out",
            str(tmp_path / "batch"),
            "--no-progress",
        ],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 120
        workers: list[psutil.Process] = []
        while time.monotonic() < deadline and driver.poll() is None:
            workers = [
                p
                for p in psutil.Process(driver.pid).children(recursive=True)
                if "redrive-batch" in " ".join(_cmdline(p)) or _started_a_cell(tmp_path)
            ]
            if _started_a_cell(tmp_path) and workers:
                break
            time.sleep(0.2)
        assert driver.poll() is None, "the batch ended before a cell started"
        # the cells: the forkserver's children (the server and the resource tracker are the
        # driver's children, idle, and end by themselves)
        workers = [c for s in psutil.Process(driver.pid).children() for c in s.children()]
        assert workers
        driver.send_signal(signal.SIGKILL)
        driver.wait(10)
        _gone, alive = psutil.wait_procs(workers, timeout=10)
        assert not alive, f"still running after the driver was killed: {alive}"
    finally:
        if driver.poll() is None:
            driver.kill()


def _cmdline(proc: psutil.Process) -> list[str]:
    try:
        return proc.cmdline()
    except psutil.Error:
        return []


def _started_a_cell(tmp_path: Path) -> bool:
    return any((tmp_path / "batch").rglob("manifest.json"))
