"""Live-mode fixtures: a real ROS 1 master on a free port, and rospy code under /usr/bin/python3.

rospy imports only under Debian's ``/usr/bin/python3`` (not the venv's Python, see NOTES.md "ROS
1"), so ROS nodes run as subprocesses of that interpreter with :attr:`RosCore.env`.  Tests that need
ROS skip, saying why, when ``/usr/bin/roscore`` is missing or rospy does not import
(``make system-test-deps`` installs both).

The master is ``rosmaster --core``, not ``roscore``: measured here it answers after ~0.14 s and
stops in ~5 ms, against ~0.5 s (0.6 s with /rosout up) and ~0.7 s for ``roscore``, which also
starts roslaunch and the rosout node — nothing the tests need.
"""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import subprocess
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from redrive.testing import ros1
from redrive.testing.processes import stop_group

ROS_PYTHON = Path("/usr/bin/python3")
ROSCORE = ros1.ROSCORE
ROSMASTER = ros1.ROSMASTER
_INSTALL_HINT = "run `make system-test-deps` (as root) to install Debian's ROS 1"


@functools.cache
def ros1_missing() -> str | None:
    """Why the ROS 1 tests cannot run here, or None when they can."""
    if not ROSCORE.is_file() or not ROSMASTER.is_file():
        return f"ROS 1 is not installed ({ROSCORE} is missing); {_INSTALL_HINT}"
    if not ROS_PYTHON.is_file():
        return f"{ROS_PYTHON} is missing; rospy runs only under Debian's python3; {_INSTALL_HINT}"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    probe = subprocess.run(
        [str(ROS_PYTHON), "-c", "import rospy"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
        check=False,
    )
    if probe.returncode != 0:
        last = (probe.stderr.strip().splitlines() or ["no output"])[-1]
        return f"rospy does not import under {ROS_PYTHON} ({last}); {_INSTALL_HINT}"
    return None


def _python_argv(code: str | Path, args: tuple[str, ...]) -> list[str]:
    if isinstance(code, Path):
        return [str(ROS_PYTHON), str(code), *args]
    return [str(ROS_PYTHON), "-c", code, *args]


def _stop_group(proc: subprocess.Popen[str] | subprocess.Popen[bytes], *, wait_s: float) -> None:
    """SIGTERM to the process group of ``proc`` (its own session), SIGKILL after ``wait_s``."""
    stop_group(proc, signal.SIGTERM, wait_s=wait_s)


@dataclass(slots=True)
class RosProcess:
    """A running ``/usr/bin/python3`` process; :attr:`output` collects its stdout and stderr."""

    proc: subprocess.Popen[str]
    lines: list[str] = field(default_factory=list)
    ready: threading.Event = field(default_factory=threading.Event)

    @property
    def output(self) -> str:
        return "".join(self.lines)


@dataclass(frozen=True, slots=True)
class RosCore:
    """A running ROS 1 master.

    Attributes:
        uri: ``http://127.0.0.1:PORT``.
        port: its TCP port.
        env: the environment for ROS subprocesses (``ROS_MASTER_URI``, ``ROS_IP``,
            ``ROS_HOSTNAME``, ``ROS_HOME``, ``ROS_LOG_DIR`` set; /usr/bin first on PATH).
        home: ``ROS_HOME`` (logs under ``home/log``).
        pid: the master's process id (and process group id).
    """

    uri: str
    port: int
    env: dict[str, str]
    home: Path
    pid: int

    def run_python(
        self, code: str | Path, *args: str, timeout_s: float = 30.0, check: bool = True
    ) -> subprocess.CompletedProcess[str]:
        """Run a snippet (str) or a script (Path) under /usr/bin/python3 against this master."""
        done = subprocess.run(
            _python_argv(code, args),
            env=self.env,
            capture_output=True,
            text=True,
            timeout=timeout_s,
            check=False,
        )
        if check and done.returncode != 0:
            pytest.fail(
                f"/usr/bin/python3 exited with {done.returncode}:\n{done.stdout}\n{done.stderr}"
            )
        return done

    @contextlib.contextmanager
    def python_process(
        self,
        code: str | Path,
        *args: str,
        ready: str | None = "READY",
        timeout_s: float = 20.0,
        stop_wait_s: float = 10.0,
    ) -> Iterator[RosProcess]:
        """A /usr/bin/python3 process (e.g. a rospy publisher) for the ``with`` block.

        Waits until it prints the line ``ready`` (unless None); stops it at exit with SIGTERM to
        its process group — rospy then unregisters from the master — and SIGKILL after
        ``stop_wait_s``.
        """
        proc = subprocess.Popen(
            _python_argv(code, args),
            env=self.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )
        running = RosProcess(proc)

        def drain() -> None:
            assert proc.stdout is not None
            for line in proc.stdout:
                running.lines.append(line)
                if ready is not None and line.strip() == ready:
                    running.ready.set()
            running.ready.set()  # end of output: stop waiting, the poll below tells why

        reader = threading.Thread(target=drain, name="ros-python-output", daemon=True)
        reader.start()
        try:
            if ready is not None:
                if not running.ready.wait(timeout_s):
                    pytest.fail(
                        f"/usr/bin/python3 did not print {ready!r} within {timeout_s} s:\n"
                        f"{running.output}"
                    )
                if proc.poll() is not None and ready not in running.output:
                    pytest.fail(
                        f"/usr/bin/python3 exited with {proc.returncode} before {ready!r}:\n"
                        f"{running.output}"
                    )
            yield running
        finally:
            _stop_group(proc, wait_s=stop_wait_s)
            reader.join(timeout=5)


def start_master(
    home: Path, *, full: bool = False, timeout_s: float = 20.0
) -> tuple[RosCore, subprocess.Popen[str]]:
    """Start ``rosmaster --core`` (``roscore`` when ``full``) on a free port; wait until it answers
    (:func:`redrive.testing.ros1.start_master`); the test fails with what it printed otherwise."""
    try:
        master = ros1.start_master(home, full=full, timeout_s=timeout_s)
    except ros1.MasterError as exc:
        pytest.fail(str(exc))
    core = RosCore(uri=master.uri, port=master.port, env=master.env, home=home, pid=master.proc.pid)
    return core, master.proc


@pytest.fixture(scope="session")
def roscore(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RosCore]:
    """A ROS 1 master for the whole session (skips when ROS 1 is missing); stopped by its PID."""
    reason = ros1_missing()
    if reason is not None:
        pytest.skip(reason)
    core, proc = start_master(tmp_path_factory.mktemp("ros"))
    try:
        yield core
    finally:
        # SIGINT is ignored by a master started from a script: SIGTERM to its process group.
        _stop_group(proc, wait_s=10)


@pytest.fixture
def dead_master_uri() -> str:
    """``http://127.0.0.1:PORT`` with nothing listening on PORT."""
    return f"http://{ros1.HOST}:{ros1.free_port()}"
