"""nuPlan's LQR tracking math, once, batched: the reference profiles of a path and the two
one-step LQR laws.

Two official trackers are built on the same functions of nuplan-devkit's
``nuplan/planning/simulation/controller/tracker/tracker_utils.py`` and ``lqr.py``:

- nuPlan's own ``LQRTracker`` (one path; :class:`redrive.closedloop.tracker.LqrTracker`, the
  closed loop's built-in tracker), and
- NAVSIM's ``BatchLQRTracker`` (``navsim/planning/simulation/planner/pdm_planner/simulation/
  batch_lqr.py`` and ``batch_lqr_utils.py``: the same functions over a batch of proposals;
  :mod:`redrive.evaluation.closedloop.navsim_sim`).

Where the two differ (how the reference is read — interpolated in time for nuPlan, by index for
NAVSIM — and the motion model) the callers keep their own code; what is the same lives here:

- :func:`fit_speed_profiles`: ``_fit_initial_velocity_and_acceleration_profile`` — the initial
  speed ``v_0`` and accelerations ``a_0 … a_{M−2}`` that minimise
  ``Σ_k ‖d_k − v_k·dt·(cos h_k, sin h_k)‖² + jerk_penalty · Σ_j (a_{j+1} − a_j)²``;
- :func:`fit_curvature_profiles`: ``_fit_initial_curvature_and_curvature_rate_profile`` —
  ``κ_0`` and the rates ``κ̇_0 … κ̇_{M−2}`` that minimise
  ``Σ_k (Δh_k − κ_k·v_k·dt)² + curvature_rate_penalty · Σ_j κ̇_j² + 10⁻¹⁰ · κ_0²``;
- :func:`integrate_profiles`: ``_generate_profile_from_initial_condition_and_derivatives``;
- :func:`longitudinal_lqr`: ``_longitudinal_lqr_controller`` — ``a = N·dt·q / ((N·dt)²·q + r) ·
  (v_ref − v)``;
- :func:`lateral_lqr`: ``_lateral_lqr_controller`` + ``_solve_one_step_lateral_lqr`` — state
  (lateral error, heading error, steering angle), input the steering rate, the small-angle
  bicycle ``e_y' = v·e_ψ, e_ψ' = v·(δ/L − κ), δ' = rate`` Euler-composed over the horizon into
  ``x_N = A x_0 + B u + g``, angles of ``x_N`` wrapped, ``u = −Bᵀ Q x_N / (Bᵀ Q B + r)``.

The devkits build the design matrix ``A`` (2M × M for the speed, M × M for the curvature),
form ``AᵀA`` and solve the regularised normal equations with ``np.linalg.pinv``.  Here ``AᵀA``
and ``Aᵀy`` are built from suffix sums (the designs' structure: :func:`_normal_equations`), and
the equations — positive definite (the penalties) — are solved directly; both give the devkits'
solution to rounding (tests/motion/test_lqr.py keeps the dense form as the reference).
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt

__all__ = [
    "INITIAL_CURVATURE_PENALTY",
    "curvature_gram",
    "fit_curvature_profiles",
    "fit_speed_profiles",
    "integrate_profiles",
    "jerk_gram",
    "lateral_lqr",
    "longitudinal_lqr",
]

F64 = npt.NDArray[np.float64]

#: ``INITIAL_CURVATURE_PENALTY`` of tracker_utils.py / batch_lqr_utils.py: the weight on κ_0².
INITIAL_CURVATURE_PENALTY = 1e-10


def _solve(lhs: F64, rhs: F64) -> F64:
    """``pinv(lhs) @ rhs`` for the batch (B, K, K), (B, K) of positive definite systems."""
    return np.asarray(np.linalg.solve(lhs, rhs[..., None])[..., 0], dtype=np.float64)


def integrate_profiles(initial: F64, rates: F64, dt_s: float) -> F64:
    """(B, K+1): each ``initial`` (B,) followed by its integration over ``rates`` (B, K)."""
    cumsum = np.cumsum(rates * dt_s, axis=-1)
    start = np.zeros((*cumsum.shape[:-1], 1), dtype=np.float64)
    return np.asarray(initial[..., None] + np.concatenate([start, cumsum], axis=-1), np.float64)


@functools.lru_cache(maxsize=32)
def _later_of(m: int) -> npt.NDArray[np.intp]:
    """(m, m) ``max(i, j)``: where the design's column pair (i, j) starts to share rows."""
    index = np.arange(m)
    out = np.maximum.outer(index, index)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=32)
def jerk_gram(m: int, jerk_penalty: float) -> F64:
    """``jerk_penalty · JᵀJ`` (m, m) of the first differences of the accelerations ``a_j`` (the
    unknowns 1 … m−1)."""
    jerk = np.zeros((max(m - 2, 0), m), dtype=np.float64)
    for j in range(m - 2):
        jerk[j, j + 1], jerk[j, j + 2] = -1.0, 1.0
    out = jerk_penalty * (jerk.T @ jerk)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=32)
def curvature_gram(m: int, curvature_rate_penalty: float) -> F64:
    """The curvature fit's penalty (m, m): ``curvature_rate_penalty`` on the rates' diagonal,
    :data:`INITIAL_CURVATURE_PENALTY` on ``κ_0``'s."""
    out = curvature_rate_penalty * np.eye(m)
    out[0, 0] = INITIAL_CURVATURE_PENALTY
    out.flags.writeable = False
    return out


def _suffix_sums(x: F64) -> F64:
    """(B, m): ``Σ_{k≥l} x_k`` for each l."""
    return np.asarray(np.cumsum(x[:, ::-1], axis=1)[:, ::-1], dtype=np.float64)


def _normal_equations(weights: F64, products: F64, dt_s: float) -> tuple[F64, F64]:
    """``AᵀA`` (B, m, m) and ``Aᵀy`` (B, m) of both fits' design without forming it.

    Both designs are, per residual k, a weight times ``c(k) = (dt, dt², …, dt², 0, …)`` (``dt``
    for the initial value, ``dt²`` for each rate before step k): the speed fit's rows are
    ``(cos h_k, sin h_k) ⊗ c(k)`` (weight ``cos² h_k + sin² h_k`` in ``AᵀA``, ``y`` projected on
    the heading in ``Aᵀy``), the curvature fit's ``v_k · c(k)`` (weight ``v_k²``, and
    ``v_k · Δh_k``).  So ``(AᵀA)_ij = s_i s_j Σ_{k ≥ max(i, j)} w_k`` and ``(Aᵀy)_i = s_i Σ_{k≥i}
    p_k`` with ``s_0 = dt``, ``s_i = dt²`` — suffix sums, O(m²) for the matrix instead of the
    O(m³) product (equal to rounding)."""
    m = weights.shape[1]
    scale = np.full(m, dt_s * dt_s)
    scale[0] = dt_s
    lhs = _suffix_sums(weights)[:, _later_of(m)] * np.multiply.outer(scale, scale)[None]
    return lhs, _suffix_sums(products) * scale[None]


def fit_speed_profiles(
    xy_disp: F64, headings_rad: F64, *, dt_s: float, jerk_penalty: float
) -> tuple[F64, F64]:
    """Initial speeds (B,) and accelerations (B, M−1) fitted to the displacements ``xy_disp``
    (B, M, 2) of poses ``dt_s`` apart whose headings are ``headings_rad`` (B, M)."""
    m = xy_disp.shape[1]
    cos, sin = np.cos(headings_rad), np.sin(headings_rad)
    lhs, rhs = _normal_equations(
        cos * cos + sin * sin, cos * xy_disp[..., 0] + sin * xy_disp[..., 1], dt_s
    )
    x = _solve(lhs + jerk_gram(m, float(jerk_penalty))[None], rhs)
    return x[:, 0], x[:, 1:]


def fit_curvature_profiles(
    heading_disp_rad: F64, speeds_mps: F64, *, dt_s: float, curvature_rate_penalty: float
) -> tuple[F64, F64]:
    """Initial curvatures (B,) and curvature rates (B, M−1) fitted to the heading changes
    ``heading_disp_rad`` (B, M, principal values) at the speeds ``speeds_mps`` (B, M)."""
    m = heading_disp_rad.shape[1]
    lhs, rhs = _normal_equations(speeds_mps * speeds_mps, speeds_mps * heading_disp_rad, dt_s)
    x = _solve(lhs + curvature_gram(m, float(curvature_rate_penalty))[None], rhs)
    return x[:, 0], x[:, 1:]


def longitudinal_lqr(
    speed_mps: F64, reference_mps: F64, *, horizon_s: float, q: float, r: float
) -> F64:
    """The acceleration (m/s²) held over ``horizon_s`` that the one-step LQR on speed gives."""
    b = horizon_s
    return np.asarray(-(b * q) / (b * q * b + r) * (speed_mps - reference_mps), dtype=np.float64)


def lateral_lqr(
    initial: F64,
    speeds_mps: F64,
    *,
    curvatures_1pm: F64,
    dt_s: float,
    wheelbase_m: float,
    q: F64,
    r: float,
) -> F64:
    """Steering rates (B,) from the lateral states ``initial`` (B, 3: lateral error m, heading
    error rad, steering angle rad) over the horizon's speeds and curvatures (B, H); ``q`` (3,)
    the diagonal of Q."""
    # A = Π M_k with M_k = [[1, v dt, 0], [0, 1, v dt / L], [0, 0, 1]] stays unit upper
    # triangular: each entry is a sum over the steps of what the earlier steps accumulated
    batch, horizon = speeds_mps.shape
    m01 = speeds_mps * dt_s
    m12 = speeds_mps * dt_s / wheelbase_m
    steps = np.arange(horizon, dtype=np.float64)

    def before(x: F64) -> F64:  # Σ_{j<k} x_j
        return np.asarray(np.cumsum(x, axis=1) - x, dtype=np.float64)

    b1_terms = m12 * steps * dt_s  # the steering angle's share before step k is k·dt
    g1_terms = -speeds_mps * curvatures_1pm * dt_s
    a = np.zeros((batch, 3, 3))
    a[:, 0, 0] = a[:, 1, 1] = a[:, 2, 2] = 1.0
    a[:, 0, 1] = m01.sum(axis=1)
    a[:, 0, 2] = (m01 * before(m12)).sum(axis=1)
    a[:, 1, 2] = m12.sum(axis=1)
    b = np.stack(
        [
            (m01 * before(b1_terms)).sum(axis=1),
            b1_terms.sum(axis=1),
            np.full(batch, horizon * dt_s),
        ],
        axis=-1,
    )
    g = np.stack(
        [(m01 * before(g1_terms)).sum(axis=1), g1_terms.sum(axis=1), np.zeros(batch)], axis=-1
    )
    err = np.einsum("bij,bj->bi", a, initial) + g
    err[:, 1:] = np.arctan2(np.sin(err[:, 1:]), np.cos(err[:, 1:]))
    bq = b * np.asarray(q, dtype=np.float64)[None]
    return np.asarray(-(bq * err).sum(-1) / ((bq * b).sum(-1) + r), dtype=np.float64)
