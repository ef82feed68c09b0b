"""KalmanTracker: ids, velocities, life cycle, ego motion, determinism, a synthetic log."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from redrive.algorithms.base import Role, StageOutputs, StepStatus
from redrive.algorithms.reference.oracle import NoisyOracle
from redrive.algorithms.reference.tracker import KalmanTracker
from redrive.assembly.frames import iter_frames
from redrive.errors import AlgorithmError, ConfigError
from redrive.io import open_log
from redrive.sim.scenario import load_scenario
from redrive.sim.synth import synthesize
from redrive.types import Box3D, DetectedObject, Frame, ObjectClass, VehicleState

T0_NS = 1_700_000_000_000_000_000
DT_NS = 100_000_000  # 10 Hz


def det(
    x: float,
    y: float,
    *,
    cls: ObjectClass = ObjectClass.VEHICLE,
    yaw_rad: float = 0.0,
    confidence: float = 0.9,
) -> DetectedObject:
    return DetectedObject(
        object_class=cls,
        confidence=confidence,
        box=Box3D(center=np.array([x, y, 0.75]), size=np.array([4.5, 1.9, 1.5]), yaw_rad=yaw_rad),
    )


def frame(index: int, ego: VehicleState | None = None) -> Frame:
    return Frame(stamp_ns=T0_NS + index * DT_NS, index=index, vehicle_state=ego)


def upstream(objects: Sequence[DetectedObject], name: str = "det") -> StageOutputs:
    return StageOutputs({name: tuple(objects)}, {name: Role.PERCEPTION})


def tracker(**config: object) -> KalmanTracker:
    algo = KalmanTracker()
    algo.configure(config)
    return algo


def nearest(tracks: Sequence[DetectedObject], xy: npt.ArrayLike) -> DetectedObject:
    return min(tracks, key=lambda t: float(np.hypot(*(t.box.center[:2] - np.asarray(xy)))))


def test_crossing_objects_keep_their_ids() -> None:
    algo = tracker(min_hits=2)
    rng = np.random.default_rng(0)
    ids_a, ids_b = [], []
    for i in range(50):
        t = i * 0.1
        a = (5.0 + 4.0 * t, -10.0 + 4.0 * t)  # the two paths cross at (15, 0) at t = 2.5 s
        b = (5.0 + 4.0 * t, 10.0 - 4.0 * t)
        dets = [det(*(np.add(p, rng.normal(0, 0.05, 2)))) for p in (a, b)]
        if rng.random() < 0.5:
            dets.reverse()
        out = algo.step(frame(i), upstream(dets))
        if i >= 2:
            assert len(out) == 2
            if i != 25:  # at the crossing itself "nearest" cannot tell them apart
                ids_a.append(nearest(out, a).object_id)
                ids_b.append(nearest(out, b).object_id)
            by_id = {o.object_id: o for o in out}
            assert by_id[1].velocity[1] > 3.5  # A heads left, B right, before and after
            assert by_id[2].velocity[1] < -3.5
    assert len(set(ids_a)) == 1
    assert len(set(ids_b)) == 1
    assert ids_a[0] != ids_b[0]


def test_constant_velocity_converges_to_the_truth() -> None:
    algo = tracker()
    rng = np.random.default_rng(1)
    v_true = np.array([3.0, -1.0])
    out: list[DetectedObject] = []
    for i in range(60):
        p = np.array([10.0, 0.0]) + v_true * i * 0.1 + rng.normal(0.0, 0.1, 2)
        out = algo.step(frame(i), upstream([det(*p)]))
    assert len(out) == 1
    assert np.linalg.norm(out[0].velocity[:2] - v_true) < 0.3
    assert out[0].velocity[2] == 0.0


def _ego_on_arc(i: int) -> VehicleState:
    """An ego driving a left-hand circle: 10 m/s, 0.2 rad/s, in map."""
    t = i * 0.1
    speed, rate = 10.0, 0.2
    heading = 0.3 + rate * t
    radius = speed / rate
    x = 100.0 + radius * (math.sin(heading) - math.sin(0.3))
    y = -50.0 - radius * (math.cos(heading) - math.cos(0.3))
    return VehicleState(
        stamp_ns=T0_NS + i * DT_NS,
        frame_id="map",
        position=np.array([x, y, 2.0]),
        velocity=np.array([speed * math.cos(heading), speed * math.sin(heading), 0.0]),
        heading_rad=heading,
        yaw_rate_rad_s=rate,
    )


def _in_base(ego: VehicleState, xy_map: np.ndarray, yaw_map: float) -> DetectedObject:
    c, s = math.cos(ego.heading_rad), math.sin(ego.heading_rad)
    d = xy_map - ego.position[:2]
    return det(c * d[0] + s * d[1], -s * d[0] + c * d[1], yaw_rad=yaw_map - ego.heading_rad)


def test_moving_turning_ego_parked_object_reads_zero_over_ground() -> None:
    algo = tracker()
    parked = np.array([140.0, -20.0])
    mover_v = np.array([5.0, 1.0])
    out: list[DetectedObject] = []
    ego = _ego_on_arc(0)
    for i in range(40):
        ego = _ego_on_arc(i)
        mover = np.array([110.0, -45.0]) + mover_v * i * 0.1
        dets = [_in_base(ego, parked, 0.7), _in_base(ego, mover, 0.2)]
        out = algo.step(frame(i, ego), upstream(dets))
    assert len(out) == 2
    expected = [_in_base(ego, parked, 0.7), _in_base(ego, mover, 0.2)]
    got_parked = nearest(out, expected[0].box.center[:2])
    got_mover = nearest(out, expected[1].box.center[:2])
    # positions and yaws come back in base_link of the current frame
    np.testing.assert_allclose(got_parked.box.center, expected[0].box.center, atol=0.05)
    assert got_parked.box.yaw_rad == pytest.approx(expected[0].box.yaw_rad, abs=1e-6)
    # velocity: over ground, in base_link axes
    assert np.linalg.norm(got_parked.velocity) < 0.1
    c, s = math.cos(ego.heading_rad), math.sin(ego.heading_rad)
    v_base = np.array([c * mover_v[0] + s * mover_v[1], -s * mover_v[0] + c * mover_v[1]])
    np.testing.assert_allclose(got_mover.velocity[:2], v_base, atol=0.15)


def test_without_ego_state_velocity_is_relative_to_the_ego() -> None:
    algo = tracker()
    out: list[DetectedObject] = []
    for i in range(40):  # ego at 10 m/s straight ahead, object parked: it approaches at 10 m/s
        out = algo.step(frame(i), upstream([det(60.0 - 10.0 * i * 0.1, 3.0)]))
    np.testing.assert_allclose(out[0].velocity[:2], [-10.0, 0.0], atol=0.1)


def test_confirmation_after_min_hits_and_tentative_tracks_die_on_a_miss() -> None:
    algo = tracker(min_hits=3)
    assert algo.step(frame(0), upstream([det(10, 0)])) == []
    assert algo.step(frame(1), upstream([det(10, 0)])) == []
    out = algo.step(frame(2), upstream([det(10, 0)]))
    assert [o.object_id for o in out] == [1]
    # a second object seen twice, missed once, then seen again: a new tentative track
    algo.step(frame(3), upstream([det(10, 0), det(30, 5)]))
    algo.step(frame(4), upstream([det(10, 0), det(30, 5)]))
    algo.step(frame(5), upstream([det(10, 0)]))
    for i in (6, 7):
        assert [o.object_id for o in algo.step(frame(i), upstream([det(10, 0), det(30, 5)]))] == [1]
    out = algo.step(frame(8), upstream([det(10, 0), det(30, 5)]))
    assert [o.object_id for o in out] == [1, 3]


def test_min_hits_one_confirms_at_birth() -> None:
    out = tracker(min_hits=1).step(frame(0), upstream([det(10, 0), det(20, 0)]))
    assert [o.object_id for o in out] == [1, 2]


@pytest.mark.parametrize("coasting", [True, False])
def test_short_miss_keeps_the_id_long_miss_does_not(coasting: bool) -> None:
    algo = tracker(min_hits=2, max_misses=3, output_coasting=coasting)

    def at(i: int) -> DetectedObject:
        return det(10.0 + 0.5 * i, 2.0)

    for i in range(10):
        out = algo.step(frame(i), upstream([at(i)]))
    assert [o.object_id for o in out] == [1]
    for i in (10, 11, 12):  # three missed frames: coasting
        out = algo.step(frame(i), upstream([]))
        if coasting:
            assert [o.object_id for o in out] == [1]
            assert out[0].box.center[0] == pytest.approx(at(i).box.center[0], abs=0.1)
        else:
            assert out == []
    assert [o.object_id for o in algo.step(frame(13), upstream([at(13)]))] == [1]
    for i in range(14, 18):  # four misses: deleted
        algo.step(frame(i), upstream([]))
    algo.step(frame(18), upstream([at(18)]))
    assert [o.object_id for o in algo.step(frame(19), upstream([at(19)]))] == [2]


def test_class_by_vote_and_outputs_carry_the_box() -> None:
    algo = tracker(min_hits=1, box_smoothing=1.0)
    classes = [ObjectClass.VEHICLE, ObjectClass.TRUCK, ObjectClass.VEHICLE, ObjectClass.TRUCK]
    classes += [ObjectClass.VEHICLE]
    out: list[DetectedObject] = []
    for i, cls in enumerate(classes):
        out = algo.step(frame(i), upstream([det(10, 0, cls=cls, yaw_rad=0.4, confidence=0.6)]))
    assert out[0].object_class is ObjectClass.VEHICLE
    out = algo.step(frame(5), upstream([det(10, 0, cls=ObjectClass.TRUCK)]))
    assert out[0].object_class is ObjectClass.TRUCK  # 3 votes each: the most recent wins
    out = algo.step(frame(6), upstream([det(10, 0, cls=ObjectClass.VEHICLE, yaw_rad=0.4)]))
    assert out[0].object_class is ObjectClass.VEHICLE  # 4 vehicle votes against 3
    np.testing.assert_allclose(out[0].box.size, [4.5, 1.9, 1.5])
    assert out[0].box.yaw_rad == pytest.approx(0.4)
    assert out[0].orientation[0] == pytest.approx(0.4)
    assert out[0].confidence == pytest.approx(0.9)


def _run(
    algo: KalmanTracker, n: int, make: Callable[[int], list[DetectedObject]]
) -> list[tuple[object, ...]]:
    rows: list[tuple[object, ...]] = []
    for i in range(n):
        for o in algo.step(frame(i, _ego_on_arc(i)), upstream(make(i))):
            rows.append((i, o.object_id, o.object_class, *o.box.center, *o.velocity))
    return rows


def test_deterministic_and_reset_clears_everything() -> None:
    rng = np.random.default_rng(5)
    scenes = [
        [det(*rng.uniform(-30, 30, 2)) for _ in range(int(rng.integers(3, 8)))] for _ in range(30)
    ]
    a, b = tracker(min_hits=1), tracker(min_hits=1)
    first = _run(a, 30, lambda i: scenes[i])
    assert first == _run(b, 30, lambda i: scenes[i])
    a.reset()
    assert _run(a, 30, lambda i: scenes[i]) == first
    assert first
    assert min(int(str(r[1])) for r in first) == 1


def test_missing_upstream_output_is_an_algorithm_error() -> None:
    algo = tracker()
    with pytest.raises(AlgorithmError, match=r"frame 0 .* no output"):
        algo.step(frame(0), StageOutputs())
    result = algo.run_step(frame(0), StageOutputs())
    assert result.status is StepStatus.ERROR
    assert result.error is not None
    assert result.error.type == "AlgorithmError"


def test_source_selects_the_upstream_algorithm() -> None:
    both = StageOutputs(
        {"a": (det(10, 0),), "b": (det(10, 0), det(20, 5))},
        {"a": Role.PERCEPTION, "b": Role.PERCEPTION},
    )
    assert len(tracker(min_hits=1, source="a").step(frame(0), both)) == 1
    assert len(tracker(min_hits=1).step(frame(0), both)) == 2  # default: the last one
    with pytest.raises(AlgorithmError, match="'c'"):
        tracker(source="c").step(frame(0), both)


def test_time_must_not_run_backwards() -> None:
    algo = tracker()
    algo.step(frame(5), upstream([]))
    with pytest.raises(AlgorithmError, match="earlier than"):
        algo.step(frame(4), upstream([]))


def test_tracking_frame_change_drops_tracks() -> None:
    algo = tracker(min_hits=1)
    algo.step(frame(0), upstream([det(10, 0)]))
    out = algo.step(frame(1, _ego_on_arc(1)), upstream([det(10, 0)]))
    assert [o.object_id for o in out] == [2]


@pytest.mark.parametrize(
    "config",
    [{"min_hits": 0}, {"max_misses": -1}, {"gate_chi2": 0}, {"box_smoothing": 1.5}, {"bogus": 1}],
)
def test_bad_config_is_refused(config: dict[str, object]) -> None:
    with pytest.raises(ConfigError):
        KalmanTracker().configure(config)


LIDAR_ONLY = {
    "lidar_top": {"kind": "lidar", "preset": "VLP-16", "xyz": [1.2, 0.0, 1.9], "rate_hz": 10}
}


def test_oracle_into_tracker_on_a_synthetic_log(tmp_path: Path) -> None:
    scenario = dataclasses.replace(load_scenario("urban"), rig=LIDAR_ONLY)
    synthesize(scenario, tmp_path / "urban.mcap", duration_s=3.0)
    oracle = NoisyOracle()
    oracle.configure({"keep_ids": False, "seed": 3, "false_positive_rate": 0.2})
    algo = tracker()
    errors, parked, switches, matched = [], [], 0, 0
    last_track: dict[int, int] = {}
    frames = list(iter_frames(open_log(tmp_path / "urban.mcap")))
    assert len(frames) >= 25
    for f in frames:
        assert f.vehicle_state is not None
        assert f.ground_truth is not None
        detections = oracle.run_step(f, StageOutputs())
        assert detections.status is StepStatus.OK
        assert isinstance(detections.output, tuple)
        tracks = algo.run_step(
            f, StageOutputs({"oracle": detections.output}, {"oracle": Role.PERCEPTION})
        )
        assert tracks.status is StepStatus.OK
        assert isinstance(tracks.output, tuple)
        if not tracks.output:
            continue
        for gt in f.ground_truth:
            if not gt.num_lidar_points:
                continue
            best = nearest(tracks.output, gt.box.center[:2])
            if np.hypot(*(best.box.center[:2] - gt.box.center[:2])) > 1.5:
                continue
            matched += 1
            if gt.object_id in last_track and last_track[gt.object_id] != best.object_id:
                switches += 1
            last_track[gt.object_id] = best.object_id
            if f.index >= 10:  # after the filters settled
                err = float(np.linalg.norm(best.velocity[:2] - gt.velocity[:2]))
                errors.append(err)
                if np.linalg.norm(gt.velocity) < 0.01:
                    parked.append(float(np.linalg.norm(best.velocity[:2])))
    assert matched > 50
    assert len(errors) > 40
    assert parked
    assert float(np.mean(errors)) < 0.6
    assert float(np.mean(parked)) < 0.5  # ~0 over ground although the ego drives ~10 m/s
    assert switches <= 2
