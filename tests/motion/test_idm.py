"""The one IDM kernel gives what the plain-Python IDM gives, bit for bit: the world's agents'
(gap floored at 5 cm, desired speed at 1 mm/s) and the reference planner's (gap at 1 mm)."""

from __future__ import annotations

import math

import numpy as np

from redrive.motion import IdmParams, idm_acceleration, idm_kernel


def _reference(  # noqa: PLR0917 - the kernel's parameters
    v: float,
    gap: float,
    v_lead: float,
    v0: float,
    delta: float,
    headway: float,
    s0: float,
    a_max: float,
    b: float,
    max_decel: float,
    v0_min: float,
    gap_min: float,
) -> float:
    """The IDM in plain Python, as the world's agents computed it before the kernel."""
    free = 1.0 - (max(v, 0.0) / max(v0, v0_min)) ** delta
    interaction = 0.0
    if math.isfinite(gap):
        dv = v - v_lead
        s_star = s0 + max(0.0, v * headway + v * dv / (2.0 * math.sqrt(a_max * b)))
        interaction = (s_star / max(gap, gap_min)) ** 2
    accel = float(a_max * (free - interaction))
    return min(max(accel, -max_decel), a_max)


def test_kernel_equals_the_python_idm() -> None:
    rng = np.random.default_rng(32)
    n = 20_000
    v = rng.uniform(-1.0, 30.0, n)
    v[:50] = 0.0
    gap = rng.choice([0.0, 0.02, 1.0, 10.0, 80.0], n) * rng.uniform(0.0, 2.0, n)
    gap[rng.random(n) < 0.2] = math.inf
    v_lead = rng.uniform(0.0, 30.0, n)
    v0 = rng.choice([0.0, 1e-4, 5.0, 13.9, 30.0], n)
    headway = rng.uniform(0.5, 2.5, n)
    s0 = rng.uniform(0.5, 4.0, n)
    a_max = rng.uniform(0.5, 3.0, n)
    b = rng.uniform(1.0, 4.0, n)
    for row in zip(*(a.tolist() for a in (v, gap, v_lead, v0, headway, s0, a_max, b)), strict=True):
        vk, gk, lk, v0k, tk, s0k, ak, bk = row
        for v0_min, gap_min in ((1e-3, 0.05), (-math.inf, 1e-3)):
            if v0_min < 0 and v0k == 0.0:
                continue  # the planner's v0 is positive (0 would divide by zero, as before)
            args = (vk, gk, lk, v0k, 4.0, tk, s0k, ak, bk, 9.0, v0_min, gap_min)
            assert idm_kernel(*args, 2.0) == _reference(*args), args


def test_idm_acceleration_is_the_kernel_with_the_worlds_floors() -> None:
    p = IdmParams(desired_speed_mps=20.0)
    assert idm_acceleration(p, 0.0) == p.max_accel_mps2
    assert idm_acceleration(p, 20.0) == 0.0
    assert idm_acceleration(p, 10.0, gap_m=1.0, leader_speed_mps=0.0) == -p.max_decel_mps2
    got = idm_acceleration(p, 8.0, gap_m=0.01, leader_speed_mps=3.0)
    assert got == _reference(8.0, 0.01, 3.0, 20.0, 4.0, 1.5, 2.0, 1.5, 2.0, 9.0, 1e-3, 0.05)
