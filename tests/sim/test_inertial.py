"""IMU integrates back to the true trajectory; GNSS round trip; odometry drift."""

from __future__ import annotations

import math

import numpy as np
import pytest

from redrive.geometry.quaternion import rotation_matrix_from_quaternion
from redrive.sim.inertial import (
    GRAVITY_MPS2,
    GnssModel,
    ImuModel,
    OdometryModel,
    enu_from_geodetic,
    geodetic_from_enu,
)
from redrive.types import VehicleState

RATE_HZ = 200.0


def _truth(t: float) -> tuple[VehicleState, float]:
    """Accelerate along a curve: speed 5 + t m/s, yaw rate 0.2 sin(0.5 t)."""
    speed, accel = 5.0 + t, 1.0
    yaw = -0.4 * math.cos(0.5 * t) + 0.4
    yaw_rate = 0.2 * math.sin(0.5 * t)
    yaw_acc = 0.1 * math.cos(0.5 * t)
    heading = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    left = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    state = VehicleState(
        stamp_ns=round(t * 1e9),
        velocity=speed * heading,
        acceleration=accel * heading + speed * yaw_rate * left,
        heading_rad=yaw,
        yaw_rate_rad_s=yaw_rate,
    )
    return state, yaw_acc


def _positions(duration_s: float) -> np.ndarray:
    ts = np.arange(0.0, duration_s + 1e-9, 1.0 / RATE_HZ)
    vel = np.array([_truth(t)[0].velocity for t in ts])
    pos = np.zeros_like(vel)
    pos[1:] = np.cumsum(0.5 * (vel[1:] + vel[:-1]) / RATE_HZ, axis=0)
    return pos


def test_imu_integrates_to_the_true_trajectory() -> None:
    duration = 10.0
    imu = ImuModel(
        accel_std_mps2=0.0, gyro_std_rad_s=0.0, accel_bias_walk_mps2=0.0, gyro_bias_walk_rad_s=0.0
    )
    rng = np.random.default_rng(0)
    ts = np.arange(0.0, duration + 1e-9, 1.0 / RATE_HZ)
    samples = [imu.sample(_truth(t)[0], rng, yaw_accel_rad_s2=_truth(t)[1]) for t in ts]
    true_pos = _positions(duration)
    # strapdown: attitude from the gyro, velocity and position from the specific force
    dt = 1.0 / RATE_HZ
    first = _truth(0.0)[0]
    rot = rotation_matrix_from_quaternion(samples[0].orientation)
    vel = first.velocity.copy()
    pos = np.zeros(3)
    g = np.array([0.0, 0.0, -GRAVITY_MPS2])
    for k in range(len(ts) - 1):
        a0 = rot @ samples[k].linear_acceleration + g
        w = 0.5 * (samples[k].angular_velocity + samples[k + 1].angular_velocity)
        angle = float(np.linalg.norm(w)) * dt
        axis = w / max(float(np.linalg.norm(w)), 1e-12)
        kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        rot = rot @ (np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx)
        a1 = rot @ samples[k + 1].linear_acceleration + g
        new_vel = vel + 0.5 * (a0 + a1) * dt
        pos = pos + 0.5 * (vel + new_vel) * dt
        vel = new_vel
    true_end = _truth(duration)[0]
    assert np.allclose(vel, true_end.velocity, atol=0.01)
    assert np.allclose(pos, true_pos[-1], atol=0.05)
    assert np.allclose(rot, rotation_matrix_from_quaternion(samples[-1].orientation), atol=1e-4)


def test_imu_at_rest_measures_gravity_and_noise() -> None:
    imu = ImuModel(accel_std_mps2=0.05, gyro_std_rad_s=0.01)
    rng = np.random.default_rng(1)
    at_rest = [imu.sample(VehicleState(stamp_ns=i * 10_000_000), rng) for i in range(2000)]
    acc = np.array([s.linear_acceleration for s in at_rest])
    gyr = np.array([s.angular_velocity for s in at_rest])
    assert np.allclose(acc.mean(axis=0), [0.0, 0.0, GRAVITY_MPS2], atol=0.02)
    assert acc[:, 0].std() == pytest.approx(0.05, rel=0.1)
    assert gyr[:, 2].std() == pytest.approx(0.01, rel=0.1)


def test_imu_lever_arm_sees_centripetal_acceleration() -> None:
    mount = np.eye(4)
    mount[0, 3] = 2.0  # 2 m ahead of the rear axle
    imu = ImuModel(
        base_from_imu=mount,
        accel_std_mps2=0.0,
        gyro_std_rad_s=0.0,
        accel_bias_walk_mps2=0.0,
        gyro_bias_walk_rad_s=0.0,
    )
    state = VehicleState(stamp_ns=0, yaw_rate_rad_s=0.5)
    sample = imu.sample(state, np.random.default_rng(0))
    assert sample.linear_acceleration[0] == pytest.approx(-(0.5**2) * 2.0)
    assert sample.angular_velocity[2] == pytest.approx(0.5)


def test_gnss_round_trip() -> None:
    ref = (48.137, 11.575, 520.0)
    for enu in ([0.0, 0.0, 0.0], [1234.5, -678.9, 12.0], [-20_000.0, 35_000.0, -3.0]):
        lat, lon, alt = geodetic_from_enu(enu, reference=ref)
        assert np.allclose(enu_from_geodetic(lat, lon, alt, reference=ref), enu, atol=1e-6)
    # 1 km north is about 0.009° of latitude at 48°
    lat, lon, _ = geodetic_from_enu([0.0, 1000.0, 0.0], reference=ref)
    assert lat - ref[0] == pytest.approx(0.008993, abs=2e-5)
    assert lon == pytest.approx(ref[1], abs=1e-9)
    gnss = GnssModel(reference=ref, horizontal_std_m=0.0, vertical_std_m=0.0)
    state = VehicleState(stamp_ns=0, position=[250.0, -80.0, 0.0], heading_rad=1.0)
    fix = gnss.fix(state, np.random.default_rng(0))
    assert np.allclose(gnss.map_position(fix), [250.0, -80.0, 0.0], atol=1e-6)
    noisy = GnssModel(reference=ref, horizontal_std_m=0.5, vertical_std_m=1.0)
    errs = np.array(
        [noisy.map_position(noisy.fix(state, np.random.default_rng(i))) for i in range(300)]
    ) - [250.0, -80.0, 0.0]
    assert errs[:, 0].std() == pytest.approx(0.5, rel=0.15)
    assert errs[:, 2].std() == pytest.approx(1.0, rel=0.15)
    assert noisy.fix(state, np.random.default_rng(0)).position_covariance_m2[0, 0] == 0.25


def test_odometry_dead_reckons_the_truth_without_noise() -> None:
    odo = OdometryModel(speed_std_mps=0.0, yaw_rate_std_rad_s=0.0)
    rng = np.random.default_rng(0)
    ts = np.arange(0.0, 5.0 + 1e-9, 1.0 / 50.0)
    out = [odo.measure(_truth(t)[0], rng) for t in ts]
    end = out[-1]
    assert end.frame_id == "odom"
    assert end.heading_rad == pytest.approx(_truth(5.0)[0].heading_rad, abs=2e-3)
    true_pos = _positions(5.0)[-1]
    assert np.allclose(end.position[:2], true_pos[:2], atol=0.1)
    noisy = OdometryModel(speed_std_mps=0.1)
    speeds = [noisy.measure(_truth(1.0)[0], np.random.default_rng(i)).speed_mps for i in range(200)]
    assert np.std(speeds) == pytest.approx(0.1, rel=0.2)
