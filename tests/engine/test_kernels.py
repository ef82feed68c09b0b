"""The install step's kernels (``python -m redrive.closedloop.kernels``): after it, another process's
synth and run of the reference pipeline — another log than the step's own — and the closed
loop's LQR tracker and ego substeps compile nothing,
and the detector's kernel is a cache hit there, not a fresh compile."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numba

import redrive
from redrive.engine.kernels import compiled_during

_SRC = str(Path(redrive.__file__).resolve().parents[1])

# a second process: another scenario's log (seed, length) through both modes, the numba
# compilations counted; then what the detector's main kernel's dispatcher says of its cache
_SECOND = """
import json, sys
from pathlib import Path
from redrive.config import reference_pipeline
from redrive.engine import RunRequest, run_log
from redrive.engine.kernels import compiled_during
from redrive.sim.scenario import load_scenario
from redrive.sim.synth import synthesize
from redrive.algorithms.reference import _kernels
from redrive.closedloop.tracker import LqrTracker
from redrive.sim.ego import ActuatedEgo, BicycleModel, EgoGeometry
from redrive.types import ControlCommands, PlannedPath, VehicleState
import numpy as np

out = Path(sys.argv[1])
with compiled_during() as compiled:
    synthesize(load_scenario("urban"), out / "other.mcap", duration_s=2.0, seed=11)
    for mode in ("sequential", "pipelined"):
        pipeline = reference_pipeline().with_options(mode=mode)
        report = run_log(RunRequest(log=out / "other.mcap", pipeline=pipeline, out=out / mode))
        assert report.status == "complete", report
    # the closed loop's LQR tracker on another path (another grid, frame and speed)
    t = np.arange(0.0, 6.0, 0.1)
    path = PlannedPath(stamp_ns=0, waypoints=np.c_[3 * t, t, 0 * t, t], frame_id="map")
    state = VehicleState(stamp_ns=0, velocity=np.array([3.0, 1.0, 0.0]))
    LqrTracker().commands(state, path, 0.1, stamp_ns=50_000_000)
    # the log backend's ego substeps (another geometry, command and step)
    ego = ActuatedEgo(BicycleModel(EgoGeometry(wheelbase_m=3.1), speed_mps=12.0))
    ego.apply_steps(ControlCommands(brake=0.4, steering_angle_rad=0.1), 0.005, 20)
stats = _kernels.crop_cell_minima.stats
print(json.dumps({"compiled": compiled, "hits": sum(stats.cache_hits.values()),
                  "misses": sum(stats.cache_misses.values())}))
"""


def _python(args: list[str], tmp: Path) -> str:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([_SRC, os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run(
        [sys.executable, *args],
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
        env=env,
        cwd=tmp,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_a_second_process_compiles_nothing_after_the_install_step(tmp_path: Path) -> None:
    step = _python(["-m", "redrive.closedloop.kernels"], tmp_path)
    assert "kernel" in step
    second = json.loads(_python(["-c", _SECOND, str(tmp_path)], tmp_path).splitlines()[-1])
    assert second["compiled"] == []
    assert second["hits"] >= 1  # loaded from numba's on-disk cache …
    assert second["misses"] == 0  # … not compiled because the cache lacked it


def test_compiled_during_counts_each_compilation_once() -> None:
    def twice(x: float) -> float:
        return 2.0 * x

    twice.__module__ = "redrive.tests_probe"  # counted: a redrive kernel
    kernel = numba.njit(twice)
    with compiled_during() as compiled:
        assert kernel(1.5) == 3.0
        assert kernel(2.5) == 5.0  # the same signature: compiled once
    assert compiled == [f"redrive.tests_probe.{twice.__qualname__}"]
    with compiled_during() as again:
        kernel(3.5)
    assert again == []
