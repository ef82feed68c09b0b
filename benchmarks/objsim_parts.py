"""Where the object-level closed loop's simulation CPU goes, part by part (thread CPU seconds).

Two tables for the 20-s ``urban`` scenario (200 frames of 0.1 s), passes after a warm-up one:

- the two worlds of a replayed-agents closed loop stepped alone: the *expert* one (the scripted
  ego among the agents) and the *driven* one (agents dropped, the ego on held pedals) — a frame's
  ``step_to`` (and of it the compiled frame kernel ``stepper._frame``), ``ground_truth_columns``
  and ``ego_state``;
- the simulator alone (``SyntheticSimulator.observe`` / ``logged_state`` / ``step`` with a fixed
  command, no algorithms), replayed and reactive agents.

Run it in two trees alternately (``PYTHONPATH=<tree>/src python benchmarks/objsim_parts.py``);
``time.thread_time`` costs ≈ 4 µs a call on the benchmark VM, so the wrapped kernel's figure
includes ≈ 8 µs a frame of that.
"""

from __future__ import annotations

import sys
import time
from typing import Any

from redrive.algorithms import StageOutputs
from redrive.closedloop.synthetic import SyntheticSimulator
from redrive.sim import stepper
from redrive.sim.ego import PedalModel
from redrive.sim.scenario import load_scenario
from redrive.sim.world import World
from redrive.types import ControlCommands, Role

FRAME_NS = 100_000_000
FRAMES = 200


class _NoTracker:
    def reset(self) -> None:
        pass

    def describe(self) -> dict[str, Any]:
        return {}


def worlds(passes: int) -> None:
    scenario = load_scenario("urban")
    kernel_s = [0.0]
    frame = stepper._frame

    def timed(*args: Any) -> Any:
        c = time.thread_time()
        out = frame(*args)
        kernel_s[0] += time.thread_time() - c
        return out

    stepper._frame = timed
    try:
        for p in range(passes + 1):
            for kind in ("expert", "driven"):
                w = World(scenario)
                if kind == "driven":
                    w.drop_agents()
                    w.drive_ego_pedals(ControlCommands(throttle=0.3), PedalModel())
                kernel_s[0] = step_s = truth_s = ego_s = 0.0
                for _ in range(FRAMES):
                    c0 = time.thread_time()
                    w.step_to(w.time_ns + FRAME_NS)
                    c1 = time.thread_time()
                    w.ground_truth_columns()
                    c2 = time.thread_time()
                    w.ego_state()
                    c3 = time.thread_time()
                    step_s, truth_s, ego_s = step_s + c1 - c0, truth_s + c2 - c1, ego_s + c3 - c2
                if p:
                    print(
                        f"world {kind}: step_to {step_s:.4f} (kernel {kernel_s[0]:.4f}) "
                        f"ground_truth_columns {truth_s:.4f} ego_state {ego_s:.4f}"
                    )
    finally:
        stepper._frame = frame


def simulator(passes: int) -> None:
    out = StageOutputs(roles={"c": Role.CONTROL}, outputs={"c": ControlCommands(throttle=0.3)})
    for p in range(passes + 1):
        for agents in ("replay", "reactive"):
            sim = SyntheticSimulator(load_scenario("urban"), tracker=_NoTracker(), agents=agents)
            o = lg = s = 0.0
            while not sim.done:
                c0 = time.thread_time()
                sim.observe()
                c1 = time.thread_time()
                _ = sim.logged_state
                c2 = time.thread_time()
                sim.step(out, sim.dt_s)
                c3 = time.thread_time()
                o, lg, s = o + c1 - c0, lg + c2 - c1, s + c3 - c2
            if p:
                print(f"simulator {agents}: observe {o:.4f} logged_state {lg:.4f} step {s:.4f}")


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    worlds(n)
    simulator(n)
