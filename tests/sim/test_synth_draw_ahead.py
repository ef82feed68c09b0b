"""SensorSimulation draws a camera image on a thread while the LiDAR sweep ending at the same
instant is cast: the images are the ones the camera draws of the world at their stamp."""

from __future__ import annotations

import numpy as np

from redrive.closedloop.sensors import FrameSensors
from redrive.sim import synth
from redrive.sim.camera import CameraModel
from redrive.sim.scenario import load_scenario
from redrive.sim.world import World
from redrive.types import Image


class _Images(FrameSensors):
    """Keeps every camera image by stamp."""

    def __init__(self, sim: synth.SensorSimulation) -> None:
        super().__init__(sim.rig)
        self.images: dict[int, Image] = {}

    def write(self, topic: str, log_time_ns: int, value: object, **kwargs: object) -> None:
        if isinstance(value, Image):
            self.images[log_time_ns] = value
        super().write(topic, log_time_ns, value, **kwargs)  # type: ignore[arg-type]


def test_images_drawn_ahead_are_the_scene_at_their_stamp() -> None:
    scenario = load_scenario("urban")
    sim = synth.SensorSimulation(scenario, duration_s=0.35)
    drawn_ahead: list[int] = []
    draw_ahead = synth._Recorder.draw_ahead

    def counting(recorder: synth._Recorder, names: list[str], stamp_ns: int) -> None:
        drawn_ahead.append(stamp_ns)
        draw_ahead(recorder, names, stamp_ns)

    sink = _Images(sim)
    synth._Recorder.draw_ahead = counting  # type: ignore[method-assign]
    try:
        sim.start(sink)
        for _ in sim.advance_to(sim.stop_ns):
            pass
    finally:
        synth._Recorder.draw_ahead = draw_ahead  # type: ignore[method-assign]
    period_ns = 100_000_000  # camera and LiDAR at 10 Hz: every image after the first
    assert drawn_ahead == [sim.start_ns + k * period_ns for k in (1, 2, 3)]
    assert sorted(sink.images) == [sim.start_ns + k * period_ns for k in range(4)]
    camera = CameraModel.from_spec(sim.rig["camera_front"])
    world = World(scenario)
    for stamp_ns, image in sorted(sink.images.items()):
        world.step_to(stamp_ns)
        assert np.array_equal(camera.render(world.scene()).image.pixels, image.pixels)
