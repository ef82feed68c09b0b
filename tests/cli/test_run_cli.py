"""``redrive run`` as a new user runs it: a plugin file outside the package, a real process,
Ctrl-C and --resume."""

from __future__ import annotations

import io
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.cli.run import parse_frames
from redrive.cli.run_report import ProgressLines
from redrive.errors import ConfigError
from redrive.results import RunStatus, open_run
from redrive.testing.demo_log import write_demo_bag

REDRIVE = [sys.executable, "-m", "redrive"]

USER_PLUGIN = textwrap.dedent(
    '''
    """A researcher's own detector, in a file of its own."""
    import os
    import pathlib
    import time

    import numpy as np

    from redrive.algorithms import Algorithm, Role
    from redrive.types import Box3D, DetectedObject, ObjectClass, SensorType


    class TallThings(Algorithm):
        """Boxes around LiDAR returns more than 1 m above the lowest one."""

        role = Role.PERCEPTION
        inputs = (SensorType.LIDAR,)
        defaults = {"height_m": 1.0, "sleep_s": 0.0}

        def step(self, frame, upstream):
            time.sleep(self.config["sleep_s"])
            # Test hook (outside the config, so that --resume sees the same config): at frame 10,
            # say so through a file and wait there until the test interrupts the run.
            handshake = os.environ.get("TALL_HANDSHAKE_DIR")
            if handshake and frame.index == 10:
                pathlib.Path(handshake, "reached").touch()
                while True:
                    time.sleep(0.05)
            xyz = self.sensor(frame, SensorType.LIDAR).data.xyz
            tall = xyz[xyz[:, 2] > xyz[:, 2].min() + self.config["height_m"]]
            if len(tall) == 0:
                return []
            lo, hi = tall.min(axis=0), tall.max(axis=0)
            box = Box3D(center=(lo + hi) / 2, size=hi - lo)
            return [DetectedObject(object_class=ObjectClass.VEHICLE, confidence=0.5, box=box)]
    '''
)


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_demo_bag(tmp_path_factory.mktemp("run_cli") / "drive.bag")


@pytest.fixture
def user_dir(tmp_path: Path) -> Path:
    (tmp_path / "tall.py").write_text(USER_PLUGIN)
    return tmp_path


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # the plugin is found by its path, not by sys.path
    return env


def test_a_user_file_runs_without_touching_redrive(bag: Path, user_dir: Path) -> None:
    proc = subprocess.run(
        [
            *REDRIVE,
            "run",
            str(bag),
            "--perception",
            "tall.py:TallThings",
            "-o",
            "out",
        ],
        cwd=user_dir,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "50 frames" in proc.stdout
    # stderr is a pipe here: progress comes as plain lines, one per tenth of the frames
    lines = [line for line in proc.stderr.splitlines() if " frames, " in line]
    assert [line.split(":")[1].split()[0] for line in lines] == [
        f"{n}/50" for n in range(5, 51, 5)
    ], proc.stderr
    assert "ETA" in lines[0]
    run = open_run(user_dir / "out")
    assert run.manifest.status is RunStatus.COMPLETE
    assert run.manifest.algorithms[0].source == str(user_dir / "tall.py")
    det = run.table("detections")
    assert det.num_rows > 0
    assert set(det.column("algorithm").to_pylist()) == {"TallThings"}


def test_ctrl_c_leaves_a_run_that_resume_completes(
    bag: Path, user_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cmd = [*REDRIVE, "run", str(bag), "--perception", "tall.py:TallThings", "-o", "out",
           "--no-progress"]  # fmt: skip
    # The plugin waits at frame 10 until interrupted: Ctrl-C lands mid-run however slow the
    # machine is (no sleep-and-hope race with the run's end).
    handshake = user_dir / "handshake"
    handshake.mkdir()
    proc = subprocess.Popen(
        cmd,
        cwd=user_dir,
        env={**_env(), "TALL_HANDSHAKE_DIR": str(handshake)},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    manifest = user_dir / "out" / "manifest.json"
    try:
        deadline = time.monotonic() + 120
        while not (handshake / "reached").exists() and proc.poll() is None:
            assert time.monotonic() < deadline, "the run never reached frame 10"
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:  # a run that did not stop is not left waiting at frame 10 forever
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=10)
    assert proc.returncode == 130, stderr
    # the hint is the exact command to paste: the same flags (--perception too) and --resume
    hint = re.search(r"continue with `(.+)`", stdout)
    assert hint, stdout
    pasted = shlex.split(hint.group(1))
    assert pasted == ["redrive", *cmd[len(REDRIVE) :], "--resume"]
    first = json.loads(manifest.read_text())
    assert first["status"] == "interrupted"
    done = open_run(user_dir / "out").table("frames").column("frame_index").to_pylist()
    assert 0 < len(done) < 50
    assert set(done) <= set(range(11))
    # evaluated now, the numbers say they cover part of the log
    capsys.readouterr()
    assert main(["evaluate", str(user_dir / "out"), "--metric", "latency"]) == 0
    said = capsys.readouterr().out
    assert f"the run was interrupted: it covers the {len(done)} frames it stored" in said
    assert "these numbers cover part of the log" in said

    resumed = subprocess.run(
        [*REDRIVE, *pasted[1:]],
        cwd=user_dir,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert resumed.returncode == 0, resumed.stderr
    run = open_run(user_dir / "out")
    assert run.manifest.status is RunStatus.COMPLETE
    frames = run.table("frames").column("frame_index").to_pylist()
    assert frames == list(range(50))  # each frame exactly once
    assert len(run.manifest.resumes) == 1


def test_frames_argument() -> None:
    assert parse_frames("100:200") == (100, 200)
    assert parse_frames("5:") == (5, None)
    assert parse_frames(":7") == (None, 7)
    assert parse_frames("3") == (3, 4)
    with pytest.raises(ConfigError, match="START:STOP"):
        parse_frames("a-b")
    with pytest.raises(ConfigError, match="greater"):
        parse_frames("9:3")


def test_bad_plugin_is_a_clear_error(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    status = main(
        [
            "run",
            str(bag),
            "--perception",
            str(tmp_path / "nope.py:X"),
            "-o",
            str(tmp_path / "out"),
            "--no-progress",
        ]
    )
    assert status == 1
    err = capsys.readouterr().err
    assert "nope.py" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "case",
    [("--perception", "idm-planner", "planning"), ("--control", "cluster-detector", "perception")],
)
def test_an_algorithm_given_under_another_role_is_refused(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], case: tuple[str, str, str]
) -> None:
    flag, plugin, role = case
    out = tmp_path / "out"
    status = main(["run", str(bag), flag, plugin, "-o", str(out), "--no-progress"])
    assert status == 1
    err = capsys.readouterr().err
    assert f"is a {role} algorithm (role = Role.{role.upper()}), given as {flag}" in err
    assert f"pass it with --{role} {plugin}" in err
    assert not out.exists()


FAILING_PLUGIN = textwrap.dedent(
    '''
    from redrive.algorithms import Algorithm, Role


    class Broken(Algorithm):
        """Fails on every frame, or from frame ``from_frame`` on."""

        role = Role.PERCEPTION
        defaults = {"from_frame": 0}

        def step(self, frame, upstream):
            if frame.index >= self.config["from_frame"]:
                raise RuntimeError(f"broken on frame {frame.index}")
            return []
    '''
)


def test_a_run_where_nothing_succeeded_exits_3_and_partial_failures_are_counted(
    bag: Path, user_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (user_dir / "broken.py").write_text(FAILING_PLUGIN)
    out = user_dir / "all"
    argv = ["run", str(bag), "--perception", f"{user_dir / 'broken.py'}:Broken", "--no-progress"]
    assert main([*argv, "-o", str(out)]) == 3
    captured = capsys.readouterr()
    assert "50 of 50 frames had a failed step" in captured.out
    assert "no algorithm step succeeded in any of the 50 frames" in captured.err
    assert open_run(out).manifest.status is RunStatus.COMPLETE  # the failures are stored

    pipeline = user_dir / "late.toml"
    pipeline.write_text(
        '[[stage]]\nname = "p"\n[[stage.algorithm]]\nname = "late"\n'
        f'plugin = "{user_dir / "broken.py"}:Broken"\nconfig = {{ from_frame = 40 }}\n'
    )
    some = user_dir / "some"
    assert (
        main(["run", str(bag), "--pipeline", str(pipeline), "--no-progress", "-o", str(some)]) == 0
    )
    captured = capsys.readouterr()
    assert "10 of 50 frames had a failed step" in captured.out
    assert "no algorithm step succeeded" not in captured.err


def test_stale_inputs_are_reported_per_frame_and_counted(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The Luminar bag's odometry is stamped months from its clouds: no frame has an ego state
    within the tolerance. Each frame says so and the run's summary counts it (it was silent)."""
    bag = shared_data / "rosbag1_real" / "embag_luminar_test.bag"
    out = tmp_path / "lum"
    status = main(["run", str(bag), "--perception", "cluster-detector", "-o", str(out),
                   "--no-progress"])  # fmt: skip
    assert status == 0
    said = capsys.readouterr().out
    assert "5 of 5 frames had no vehicle_state within the tolerance" in said
    run = open_run(out)
    assert run.table("frames").column("missing_inputs").to_pylist() == ["vehicle_state"] * 5
    assert run.manifest.summary is not None
    assert run.manifest.summary.missing_inputs == {"vehicle_state": 5}
    # a log whose inputs are all there has none
    full = tmp_path / "full"
    assert main(["run", str(shared_data / "rosbag1_recorded_here" / "kitti_3frames_rosbag_record_lz4.bag"),
                 "--perception", "cluster-detector", "-o", str(full), "--no-progress"]) == 0  # fmt: skip
    assert "within the tolerance" not in capsys.readouterr().out
    assert set(open_run(full).table("frames").column("missing_inputs").to_pylist()) == {""}


def test_progress_lines_without_a_total_come_every_100_frames() -> None:
    out = io.StringIO()
    lines = ProgressLines("x.bag", out)
    lines.start(None)
    for done in range(1, 251):
        lines.update(done, done / 50.0)
    assert out.getvalue().splitlines() == [
        "x.bag: 100 frames, 50.0 frames/s",
        "x.bag: 200 frames, 50.0 frames/s",
    ]


def test_a_run_that_processed_no_frame_exits_3(
    demo_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A frame range past the log's end: no frame processed is a failure, not success (issue 37)."""
    assert main(["run", str(demo_log), "--frames", "5000:5100", "--out", str(tmp_path / "r")]) == 3
    assert "no frame was processed" in capsys.readouterr().err
