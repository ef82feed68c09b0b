"""The signals' states as ground truth: the world's TrafficData, the synthetic log's
/ground_truth/traffic_lights topic, read back into Frame.traffic."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest

from redrive.assembly.frames import iter_frames
from redrive.errors import UnsupportedMessageError
from redrive.io import open_log
from redrive.io.mcap.writer import McapWriter
from redrive.sim.lights import light_id_text
from redrive.sim.scenario import load_scenario
from redrive.sim.synth import TRAFFIC_LIGHTS_TOPIC, synthesize
from redrive.sim.world import World
from redrive.types import Box3D, DetectedObject, Frame, LightState, TrafficData, TrafficLight
from tests.sim.test_synth import SMALL_RIG

R, Y, G = LightState.RED, LightState.YELLOW, LightState.GREEN


def _west(frame_or_data: Frame | TrafficData) -> LightState:
    data = frame_or_data.traffic if isinstance(frame_or_data, Frame) else frame_or_data
    return {light.id: light.state for light in data.traffic_lights}["0"]


def test_world_traffic_data_follows_the_cycle() -> None:
    # red_light: west/east (group 0) green until 5 s, yellow 5–8 s, red 8–24 s; the other group
    # is red while group 0 is green (a half cycle apart)
    world = World(load_scenario("red_light"))
    seen = {}
    for t_s in (0.0, 4.9, 5.1, 7.9, 8.1, 14.0):
        world.step_to(world.scenario.start_stamp_ns + round(t_s * 1e9))
        data = world.traffic_data()
        assert [light.id for light in data.traffic_lights] == ["0", "1", "2", "3"]
        states = {light.id: light.state for light in data.traffic_lights}
        assert states["0"] == states["2"]  # west and east share a phase
        seen[t_s] = (states["0"], states["1"])
    assert seen == {
        0.0: (G, R),
        4.9: (G, R),
        5.1: (Y, R),
        7.9: (Y, R),
        8.1: (R, R),  # all-red
        14.0: (R, G),
    }
    assert light_id_text(3) == "3"


def test_highway_has_no_lights() -> None:
    assert World(load_scenario("highway")).traffic_data().traffic_lights == ()


def test_synthetic_log_carries_the_states_into_frames(tmp_path: Path) -> None:
    scenario = dataclasses.replace(load_scenario("red_light"), rig=SMALL_RIG)
    summary = synthesize(scenario, tmp_path / "r.mcap", duration_s=9.0)
    assert summary.topics[TRAFFIC_LIGHTS_TOPIC] == "redrive_msgs/msg/TrafficLightStateArray"
    with open_log(tmp_path / "r.mcap") as log:
        assert log.topics[TRAFFIC_LIGHTS_TOPIC].count == 90  # with each objects message
        frames = list(iter_frames(log))
    assert len(frames) == 90
    world = World(scenario)
    for frame in frames:
        assert "traffic_lights" not in frame.missing
        world.step_to(frame.stamp_ns)
        assert frame.traffic == world.traffic_data()  # the state at the sweep's start
    states = [_west(f) for f in frames]
    assert states[0] is G
    assert states[-1] is R
    assert states.index(Y) == 50  # 5 s at 10 Hz
    assert states.index(R) == 80  # 8 s


def test_frame_traffic_round_trips_through_write_frame(tmp_path: Path) -> None:
    lights = (TrafficLight(id="a", state=R), TrafficLight(id="b", state=LightState.UNKNOWN))
    frames = [
        Frame(
            stamp_ns=1_000_000_000 + k * 100_000_000,
            index=k,
            traffic=TrafficData(traffic_lights=lights),
        )
        for k in range(3)
    ]
    with McapWriter(tmp_path / "f.mcap") as writer:
        for frame in frames:
            writer.write(
                "/lidar", frame.stamp_ns, _cloud(), frame_id="lidar", stamp_ns=frame.stamp_ns
            )
            writer.write_frame(frame)
    with open_log(tmp_path / "f.mcap") as log:
        back = list(iter_frames(log))
    assert [f.traffic.traffic_lights for f in back] == [lights] * 3


def _cloud() -> Any:
    import numpy as np

    from redrive.types import PointCloud

    return PointCloud(xyz=np.zeros((1, 3), dtype=np.float32))


@pytest.mark.parametrize(
    ("value", "words"),
    [
        (
            TrafficData(
                traffic_lights=(TrafficLight(id="a", state=R),),
                nearby_vehicles=(
                    DetectedObject(
                        object_id=1, box=Box3D(center=(0.0, 0.0, 0.0), size=(1.0, 1.0, 1.0))
                    ),
                ),
            ),
            "nearby vehicle",
        ),
        (
            TrafficData(
                traffic_lights=(TrafficLight(id="a", state=R), TrafficLight(id="a", state=G))
            ),
            "appear twice",
        ),
    ],
)
def test_what_the_message_cannot_carry_is_refused(
    tmp_path: Path, value: TrafficData, words: str
) -> None:
    with (
        McapWriter(tmp_path / "x.mcap") as writer,
        pytest.raises(UnsupportedMessageError, match=words),
    ):
        writer.write("/lights", 1, value)


def test_traffic_data_states_are_state_of_each_signal() -> None:
    # traffic_data computes the timing's terms once: every state is still state()'s, at phase
    # boundaries, negative times and offsets too, and after the timing is replaced
    from redrive.sim.lights import LightTiming, TrafficLights
    from redrive.sim.roads import build_network

    signals = build_network(load_scenario("urban").road).signals
    assert len(signals) >= 2
    lights = TrafficLights(signals, LightTiming(green_s=7.3, yellow_s=2.9, offset_s=-1.7))
    for timing in (lights.timing, LightTiming(green_s=4.0, yellow_s=0.0, all_red_s=0.7)):
        lights.timing = timing
        cycle = timing.cycle_s
        times = [k * 0.05 for k in range(-200, 900)]
        times += [b + e for b in (timing.green_s, cycle / 2, cycle) for e in (-1e-12, 0.0, 1e-12)]
        for t_s in times:
            got = [light.state for light in lights.traffic_data(t_s).traffic_lights]
            assert got == [lights.state(sig.light_id, t_s) for sig in signals], t_s
