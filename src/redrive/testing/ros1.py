"""A ROS 1 master of our own for the tests and ``python -m benchmarks record``/``record-ros2``.

Debian's ROS 1 (``make system-test-deps``) on a free port of 127.0.0.1, with its environment
(``ROS_MASTER_URI``, ``ROS_HOME`` …) in a folder of the caller's. The master is ``rosmaster
--core``, not ``roscore``: measured here it answers after ~0.14 s and stops in ~5 ms, against
~0.5 s (0.6 s with /rosout up) and ~0.7 s for ``roscore``, which also starts roslaunch and the
rosout node (``full=True`` starts ``roscore`` all the same).
"""

from __future__ import annotations

import http.client
import os
import signal
import socket
import subprocess
import time
import xmlrpc.client
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from redrive.testing.processes import stop_group

__all__ = [
    "HOST",
    "ROSCORE",
    "ROSMASTER",
    "MasterError",
    "RunningMaster",
    "free_port",
    "master_answers",
    "ros_env",
    "start_master",
]

HOST = "127.0.0.1"
ROSCORE = Path("/usr/bin/roscore")
ROSMASTER = Path("/usr/bin/rosmaster")


class MasterError(RuntimeError):
    """The ROS master did not come up; the message holds what it printed."""


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on (free when asked; may be taken later)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((HOST, 0))
        port: int = sock.getsockname()[1]
        return port


def ros_env(port: int, home: Path) -> dict[str, str]:
    """The environment of a ROS process talking to the master on ``port``, logging under ``home``."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env.update(
        ROS_MASTER_URI=f"http://{HOST}:{port}",
        ROS_IP=HOST,
        ROS_HOSTNAME=HOST,
        ROS_HOME=str(home),
        ROS_LOG_DIR=str(home / "log"),
        # ROS scripts started by name must find Debian's python3 first, not a pyenv shim.
        PATH=f"/usr/bin:/bin:{os.environ.get('PATH', '')}",
        PYTHONUNBUFFERED="1",
    )
    return env


def master_answers(port: int, timeout_s: float = 1.0) -> bool:
    """True when the master on ``port`` answers ``getSystemState``."""
    body = xmlrpc.client.dumps(("/redrive",), "getSystemState")
    conn = http.client.HTTPConnection(HOST, port, timeout=timeout_s)
    try:
        conn.request("POST", "/RPC2", body, {"Content-Type": "text/xml"})
        reply: Any = xmlrpc.client.loads(conn.getresponse().read())[0]
        code = reply[0][0]
    except (OSError, http.client.HTTPException, xmlrpc.client.Error, IndexError, TypeError):
        return False
    finally:
        conn.close()
    return bool(code == 1)


@dataclass(frozen=True, slots=True)
class RunningMaster:
    """A master started by :func:`start_master`: its port, the environment of its clients
    (``env["ROS_MASTER_URI"]`` is its URI) and its process, leader of a session of its own."""

    port: int
    env: dict[str, str]
    proc: subprocess.Popen[str]

    @property
    def uri(self) -> str:
        return self.env["ROS_MASTER_URI"]

    def stop(self, wait_s: float = 10.0) -> None:
        """SIGTERM to its process group (a master started from a script ignores SIGINT), SIGKILL
        after ``wait_s``; returns once every process of the group is gone."""
        stop_group(self.proc, signal.SIGTERM, wait_s=wait_s)


def start_master(
    home: Path, *, full: bool = False, timeout_s: float = 20.0, attempts: int = 3
) -> RunningMaster:
    """Start ``rosmaster --core`` (``roscore`` when ``full``) on a free port; return once it
    answers.

    Tries another port when the master dies at start (the free port was taken in between);
    raises :class:`MasterError` with what each attempt printed when none came up.
    """
    (home / "log").mkdir(parents=True, exist_ok=True)
    problems: list[str] = []
    for _attempt in range(attempts):
        port = free_port()
        env = ros_env(port, home)
        cmd = (
            [str(ROSCORE), "-p", str(port)] if full else [str(ROSMASTER), "--core", "-p", str(port)]
        )
        log_path = home / f"master-{port}.out"
        with log_path.open("w") as log:
            proc: subprocess.Popen[str] = subprocess.Popen(
                cmd,
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
                text=True,
                start_new_session=True,
            )
        master = RunningMaster(port=port, env=env, proc=proc)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and proc.poll() is None:
            if master_answers(port):
                return master
            time.sleep(0.02)
        master.stop(wait_s=5)
        problems.append(f"{' '.join(cmd)}: {log_path.read_text().strip()[-2000:] or 'no output'}")
    raise MasterError("the ROS master did not come up:\n" + "\n".join(problems))
