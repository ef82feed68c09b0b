"""Treiber's Intelligent Driver Model (Treiber, Hennecke & Helbing 2000), one compiled kernel::

    a = a_max · [1 − (v / v0)^δ − (s* / s)²],   s* = s0 + max(0, v·T + v·Δv / (2·√(a_max·b)))

clipped to ``[−max_decel, a_max]``, with the bumper-to-bumper gap ``s`` to the leader (inf: a
free road) floored at ``gap_min_m`` and the desired speed floored at ``v0_min_mps``.

:func:`idm_kernel` is the one implementation: the world's lane followers and scripted ego
(:mod:`redrive.sim.fleet`, :mod:`redrive.sim.stepper`), the reference planner's speed profile
(:mod:`redrive.algorithms.reference._plan_kernels`) call it from their kernels, and Python calls
it through :func:`idm_acceleration` (the closed loop's reactive log agents, the world's agent
objects).  It does the float64 operations of Python's arithmetic in order (numba compiles without
``fastmath``): ``max``/``min`` written out as Python's builtins choose (the first argument unless
the other compares greater / smaller), and the square through ``pow`` with an exponent passed in
at run time (``two``, always 2.0: a literal would let LLVM turn ``pow(x, 2.0)`` into ``x * x``,
which need not equal libm's ``pow``, Python's ``**``).

numba keys a kernel's cache by its own file: the kernels that call this one keep a stale copy
when it changes — run ``make clean-kernels`` after editing it.
"""

# max/min written out, the constant first, as Python's builtins compare (see above)
# ruff: noqa: PLR1730, SIM300

from __future__ import annotations

import math
from dataclasses import dataclass

import numba

__all__ = ["GAP_MIN_M", "V0_MIN_MPS", "IdmParams", "idm_acceleration", "idm_kernel"]

#: the floors of the world's agents: the gap (metres) and the desired speed (m/s)
GAP_MIN_M = 0.05
V0_MIN_MPS = 1e-3


@dataclass(frozen=True, slots=True, kw_only=True)
class IdmParams:
    """IDM parameters: desired speed v0 (m/s), time headway T (s), minimum gap s0 (m),
    maximum acceleration a (m/s²), comfortable deceleration b (m/s²), exponent δ, and the
    physical braking limit (m/s², positive) the command is clipped to."""

    desired_speed_mps: float = 13.9
    time_headway_s: float = 1.5
    min_gap_m: float = 2.0
    max_accel_mps2: float = 1.5
    comfort_decel_mps2: float = 2.0
    delta: float = 4.0
    max_decel_mps2: float = 9.0


@numba.njit(cache=True, nogil=True)
def idm_kernel(  # noqa: PLR0917 (numba has no keyword-only parameters)
    speed_mps: float,
    gap_m: float,
    leader_speed_mps: float,
    v0_mps: float,
    delta: float,
    headway_s: float,
    s0_m: float,
    a_max_mps2: float,
    b_mps2: float,
    max_decel_mps2: float,
    v0_min_mps: float,
    gap_min_m: float,
    two: float,
) -> float:  # pragma: no cover - compiled
    """The IDM acceleration (m/s²) at ``speed_mps`` behind a leader ``gap_m`` ahead (inf: none)
    at ``leader_speed_mps`` (see the module text; ``two`` must be 2.0)."""
    v = speed_mps
    vv = v
    if 0.0 > vv:
        vv = 0.0
    v0 = v0_mps
    if v0_min_mps > v0:
        v0 = v0_min_mps
    free = 1.0 - (vv / v0) ** delta
    interaction = 0.0
    if math.isfinite(gap_m):
        dyn = v * headway_s + v * (v - leader_speed_mps) / (2.0 * math.sqrt(a_max_mps2 * b_mps2))
        s_star = s0_m + (dyn if dyn > 0.0 else 0.0)
        g = gap_m
        if gap_min_m > g:
            g = gap_min_m
        interaction = (s_star / g) ** two
    accel = a_max_mps2 * (free - interaction)
    if -max_decel_mps2 > accel:
        accel = -max_decel_mps2
    if a_max_mps2 < accel:
        accel = a_max_mps2
    return float(accel)


def idm_acceleration(
    params: IdmParams,
    speed_mps: float,
    *,
    gap_m: float = math.inf,
    leader_speed_mps: float = 0.0,
) -> float:
    """IDM acceleration (m/s²) for a bumper-to-bumper ``gap_m`` to a leader (inf: free road),
    with the world's floors (a gap of at least 5 cm, a desired speed of at least 1 mm/s)."""
    p = params
    return float(
        idm_kernel(
            float(speed_mps),
            float(gap_m),
            float(leader_speed_mps),
            p.desired_speed_mps,
            p.delta,
            p.time_headway_s,
            p.min_gap_m,
            p.max_accel_mps2,
            p.comfort_decel_mps2,
            p.max_decel_mps2,
            V0_MIN_MPS,
            GAP_MIN_M,
            2.0,
        )
    )
