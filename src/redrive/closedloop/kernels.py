"""The install step: every numba kernel of ``make demo``'s path and of the closed loop compiled
into numba's on-disk cache once, ahead of the first run (``make venv`` / ``make demo`` run
``python -m redrive.closedloop.kernels`` after ``pip install``).

It is :func:`redrive.engine.kernels.compile_kernels` (a short synthetic log through the reference
pipeline: synth's, the detector's, the tracker's, the planner's and the controller's kernels),
then the closed loop's own: the LQR tracker's compiled body (``closedloop._tracker_kernels``,
≈ 10 s to compile), called once on a straight path with the argument types every closed-loop run
gives it, and the log backend's ego substeps (``sim.stepper.pedal_steps``).  It sits here, not
in ``redrive.engine``, because the closed loop is the layer above.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from redrive.closedloop.tracker import LqrTracker
from redrive.engine.kernels import KernelReport, compile_kernels, compiled_during, print_report
from redrive.sim.ego import ActuatedEgo, BicycleModel, EgoGeometry
from redrive.types import ControlCommands, PlannedPath, VehicleState

__all__ = ["compile_all_kernels", "main", "warm_tracker"]


def warm_tracker() -> None:
    """One LqrTracker command on a straight map-frame path and ten ego substeps of the log
    backend (their kernels loaded or compiled)."""
    t = np.arange(0.0, 8.0, 0.1)
    path = PlannedPath(stamp_ns=0, waypoints=np.c_[5.0 * t, 0.0 * t, 0.0 * t, t], frame_id="map")
    state = VehicleState(stamp_ns=0, frame_id="map", velocity=np.array([5.0, 0.0, 0.0]))
    LqrTracker().commands(state, path, 0.1, stamp_ns=0)
    # the closed loop on a log moves its ego in substeps, in one compiled call a frame
    ActuatedEgo(BicycleModel(EgoGeometry(), speed_mps=5.0)).apply_steps(
        ControlCommands(throttle=0.2), 0.01, 10
    )


def compile_all_kernels() -> KernelReport:
    """:func:`~redrive.engine.kernels.compile_kernels`, then :func:`warm_tracker`."""
    t0 = time.perf_counter()
    engine = compile_kernels()
    with compiled_during() as compiled:
        warm_tracker()
    return KernelReport(compiled=(*engine.compiled, *compiled), wall_s=time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m redrive.closedloop.kernels",
        description=(
            "Compile the numba kernels of `redrive synth`, of the reference pipeline and of the "
            "closed loop's LQR tracker into numba's on-disk cache, so that the first `redrive "
            "run` loads them instead of compiling them (make venv / make demo run this after "
            "installing)."
        ),
    )
    parser.parse_args(argv)
    print_report(compile_all_kernels())
    return 0


if __name__ == "__main__":
    sys.exit(main())
