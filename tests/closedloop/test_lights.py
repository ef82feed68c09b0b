"""Traffic lights in a closed loop: the frames carry the world's light states, and the other
road users — replayed or reactive — stop at the red stop line and go at green."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.config import pipeline_from_plugins
from redrive.results import RunStatus, open_run
from redrive.sim.scenario import load_scenario
from redrive.sim.world import World
from redrive.types import LightState

PLUGINS = "tests.closedloop.plugins"
STOP_LINE_X = -9.5  # urban: the west approach's stop line, near edge (map frame)


@pytest.mark.parametrize("agents", ["replay", "reactive"])
def test_the_lead_car_stops_at_red_and_goes_at_green(tmp_path: Path, agents: str) -> None:
    # urban: west/east yellow at 2 s, red 5–22 s; the lead car (id 1) drives west → east ahead
    # of an ego that stands still
    out = tmp_path / agents
    request = ClosedLoopRequest(
        scenario="urban",
        pipeline=pipeline_from_plugins(planning=[f"{PLUGINS}:StandStill"]),
        out=out,
        duration_s=26.0,
        agents=agents,
    )
    assert run_closed_loop(request).status is RunStatus.COMPLETE
    run = open_run(out)
    ego, truth, lights = run.ego(), run.ground_truth(), run.traffic_lights()
    world = World(load_scenario("urban"))
    lead: dict[int, tuple[float, float]] = {}  # frame → (front bumper x, speed)
    for frame, state in ego.items():
        world.step_to(state.stamp_ns)
        assert lights[frame] == world.traffic_data().traffic_lights  # the world's states
        (car,) = [o for o in truth[frame] if o.object_id == 1]
        h = state.heading_rad
        x = state.position[0] + math.cos(h) * car.box.center[0] - math.sin(h) * car.box.center[1]
        lead[frame] = (x + car.box.size[0] / 2.0, math.hypot(car.velocity[0], car.velocity[1]))
    west = {f: {t.id: t.state for t in lights[f]}["0"] for f in lead}
    red = [f for f in lead if west[f] is LightState.RED]
    assert max(lead[f][0] for f in red) < STOP_LINE_X  # never past the line while red
    assert sum(1 for f in red if lead[f][1] < 0.05) > 100  # it waited there
    last = max(lead)
    assert west[last] is LightState.GREEN
    assert lead[last][1] > 1.0  # and drives off at green
