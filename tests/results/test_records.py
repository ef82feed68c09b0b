"""The engine's unchecked record constructors make the same records as the checked ones."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from redrive.results import FrameRecord, StepRecord
from redrive.results.records import frame_record_unchecked, step_record_unchecked
from redrive.types import ControlCommands, PlannedPath, VehicleState


def test_unchecked_step_record_equals_checked() -> None:
    path = PlannedPath(stamp_ns=5, waypoints=np.zeros((2, 4)))
    checked = StepRecord(
        algorithm="p", stage="plan", role="planning", status="ok", latency_ns=7, cpu_ns=3,
        output=path,
    )  # fmt: skip
    assert step_record_unchecked("p", "plan", "planning", "ok", 7, 3, path) == checked
    failed = StepRecord(
        algorithm="c", stage="ctl", role="control", status="error", latency_ns=1, cpu_ns=1,
        error_type="ValueError", error_message="bad", traceback="tb",
    )  # fmt: skip
    made = step_record_unchecked(
        "c", "ctl", "control", "error", 1, 1, None, "ValueError", "bad", "tb"
    )
    assert made == failed
    assert repr(made) == repr(failed)
    # a real, frozen StepRecord (built as another class and given StepRecord's class)
    assert type(made) is StepRecord
    with pytest.raises(dataclasses.FrozenInstanceError):
        made.status = "ok"  # type: ignore[misc]
    assert pickle.loads(pickle.dumps(made)) == failed
    assert dataclasses.replace(made, status="timeout").status == "timeout"


def test_unchecked_frame_record_equals_checked() -> None:
    steps = (
        StepRecord(
            algorithm="c", stage="ctl", role="control", status="ok", output=ControlCommands()
        ),
    )
    ego = VehicleState(stamp_ns=9, position=(1.0, 2.0, 0.0))
    checked = FrameRecord(
        frame_index=4, stamp_ns=9, steps=steps, vehicle_state=ego, ground_truth=(), wall_ns=11,
        late=True, missing=("cam",),
    )  # fmt: skip
    made = frame_record_unchecked(4, 9, steps, ego, (), 11, True, ("cam",))
    assert made == checked
    assert made.closed_loop is None
    assert made.logged_vehicle_state is None
    assert type(made) is FrameRecord
    with pytest.raises(dataclasses.FrozenInstanceError):
        made.late = False  # type: ignore[misc]
    restored = pickle.loads(pickle.dumps(made))  # the ego's arrays are copied: not ==
    assert type(restored) is FrameRecord
    assert (restored.steps, restored.wall_ns, restored.missing) == (steps, 11, ("cam",))
