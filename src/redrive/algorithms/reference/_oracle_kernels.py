"""The noisy oracle's draws and arithmetic for one frame as one numba kernel (compiled once,
cached next to the module).

Random numbers come from a counter-based generator: SplitMix64's output function (Steele, Lea &
Flood, "Fast splittable pseudorandom number generators", OOPSLA 2014; the generator that seeds
xoshiro) applied to ``key + (counter + 1) · γ``, γ = 0x9E3779B97F4A7C15, where ``key`` mixes the
oracle's seed and the frame index (:func:`frame_key`).  Draw ``c`` of a frame is a pure function
of (seed, frame index, c): SplitMix64's stream is that function read at c = 0, 1, 2, …, and it
passes BigCrush.  Each ground-truth row owns the counters ``32·row …`` (its miss, class
confusion, then two a normal: the three centre, three size, yaw and two velocity normals), the
false positives those from ``2^40`` on, so an object's noise does not depend on which other objects are in the
frame.  A uniform in [0, 1) is the top 53 bits × 2⁻⁵³ (as numpy's ``random()``), a standard
normal is Box–Muller on two uniforms (the cosine branch), the Poisson count adds exponential
gaps until they pass the mean (exact for any mean, O(mean)).

Until issue 15's h-obj7 the oracle drew from ``numpy.random.default_rng([seed, frame.index])``
(16 µs to seed a frame, then eight generator calls); the distributions are the same, the
numbers are not.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

__all__ = [
    "FP_BASE",
    "ROW_STRIDE",
    "frame_key",
    "normal_at",
    "oracle_frame",
    "oracle_frame_packed",
    "uniform_at",
]

_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
_BOOL = npt.NDArray[np.bool_]

#: counters a ground-truth row (or a false positive) owns (20 used)
ROW_STRIDE = 32
#: the false positives' first counter (the Poisson count's draws, then 32 a false positive)
FP_BASE = 1 << 40
_FP_COUNT_DRAWS = 1 << 20  # counters the Poisson count may use before the boxes' own
_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_UNIT = 1.0 / 9007199254740992.0  # 2^-53


@numba.njit(cache=True, nogil=True)
def _mix(z: np.uint64) -> np.uint64:  # pragma: no cover - compiled
    """SplitMix64's output function (a bijection of 64-bit words)."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@numba.njit(cache=True, nogil=True)
def frame_key(seed: int, index: int) -> np.uint64:  # pragma: no cover - compiled
    """The key of frame ``index`` of an oracle seeded ``seed`` (both ≥ 0)."""
    k = _mix(np.uint64(seed) * _GAMMA + _GAMMA)
    return _mix(k ^ (np.uint64(index) * _GAMMA + _M1))


@numba.njit(cache=True, nogil=True)
def uniform_at(key: np.uint64, counter: int) -> float:  # pragma: no cover - compiled
    """Draw ``counter`` of the frame ``key`` as a uniform in [0, 1)."""
    z = _mix(key + (np.uint64(counter) + np.uint64(1)) * _GAMMA)
    return float(z >> _S11) * _UNIT


@numba.njit(cache=True, nogil=True)
def normal_at(key: np.uint64, counter: int) -> float:  # pragma: no cover - compiled
    """A standard normal from draws ``counter`` and ``counter + 1`` (Box–Muller)."""
    u1 = 1.0 - uniform_at(key, counter)  # (0, 1]: the log is finite
    u2 = uniform_at(key, counter + 1)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@numba.njit(cache=True, nogil=True)
def _normalize_angle(angle_rad: float) -> float:  # pragma: no cover - compiled
    # redrive.geometry.normalize_angle, compiled: numba has no math.fmod, so not njit(that)
    wrapped: float = np.fmod(angle_rad + math.pi, 2.0 * math.pi)  # exact: any fmod, these bits
    if wrapped < 0.0:
        wrapped += 2.0 * math.pi
    return wrapped - math.pi


@numba.njit(cache=True, nogil=True)
def oracle_frame(  # noqa: PLR0917 - numba takes no keyword-only parameters
    seed: int,
    index: int,
    centers: _F64,
    sizes: _F64,
    yaws: _F64,
    velocities: _F64,
    orientations: _F64,
    eligible: _BOOL,
    params: _F64,
    fp_probs: _F64,
    fp_sizes: _F64,
) -> tuple[_I64, _F64, _F64, _F64, _F64, _F64, _F64, _I64, _F64, _F64, _F64]:  # pragma: no cover
    """Frame ``index`` of the noisy oracle seeded ``seed`` (its key: :func:`frame_key`).

    ``params`` = (centre std m, relative size std, yaw std rad, velocity std m/s, miss
    probability, class-confusion probability, false-positive rate, false positives' nearest and
    farthest range m, the detection range m (inf: none)).  Each ground-truth row r (of the
    (n, 3) / (n,) columns) that is ``eligible`` (seen) and whose centre's horizontal distance
    (``hypot``) is within the detection range is missed when its uniform (counter 32r) is below the miss probability; a kept one gets
    ``centre + N·σ`` on x, y, z, ``max(size·(1 + N·σ_rel), 0.1·size)``, ``yaw + N·σ``
    normalised to [-π, π) (orientation's yaw too), ``v + N·σ`` on vx, vy.

    Returns the kept rows (k,), each one's class-confusion uniform (k,), their centres, sizes,
    yaws, velocities and orientations; then the false positives: their class index into
    ``fp_probs`` (m,), centres (m, 3) (at a range uniform between the two bounds, a bearing
    uniform in [-π, π), standing on z = 0), sizes (m, 3) (``fp_sizes[class]`` perturbed as
    above) and yaws (m,) uniform in [-π, π)."""
    key = frame_key(seed, index)
    s_center, s_size, s_yaw, s_vel = params[0], params[1], params[2], params[3]
    p_miss, max_range = params[4], params[9]
    n = centers.shape[0]
    keep = np.zeros(n, dtype=np.bool_)
    k = 0
    for r in range(n):
        if not (eligible[r] and math.hypot(centers[r, 0], centers[r, 1]) <= max_range):
            continue
        if not uniform_at(key, ROW_STRIDE * r) < p_miss:
            keep[r] = True
            k += 1
    rows = np.empty(k, dtype=np.int64)
    confuse = np.empty(k)
    out_c = np.empty((k, 3))
    out_s = np.empty((k, 3))
    out_y = np.empty(k)
    out_v = np.empty((k, 3))
    out_o = np.empty((k, 3))
    j = 0
    for r in range(n):
        if not keep[r]:
            continue
        base = ROW_STRIDE * r
        rows[j] = r
        confuse[j] = uniform_at(key, base + 1)
        for a in range(3):
            out_c[j, a] = centers[r, a] + normal_at(key, base + 2 + 2 * a) * s_center
            noisy = sizes[r, a] * (1.0 + normal_at(key, base + 8 + 2 * a) * s_size)
            out_s[j, a] = max(noisy, 0.1 * sizes[r, a])
            out_v[j, a] = velocities[r, a]
            out_o[j, a] = orientations[r, a]
        d_yaw = normal_at(key, base + 14) * s_yaw
        out_v[j, 0] += normal_at(key, base + 16) * s_vel
        out_v[j, 1] += normal_at(key, base + 18) * s_vel
        out_y[j] = _normalize_angle(yaws[r] + d_yaw)
        out_o[j, 0] = _normalize_angle(orientations[r, 0] + d_yaw)
        j += 1
    # false positives: a Poisson count (exponential gaps until they pass the rate), then each
    # box from its own counters
    rate = params[6]
    m = 0
    if rate > 0.0:
        total = 0.0
        c = FP_BASE
        while c < FP_BASE + _FP_COUNT_DRAWS:
            total -= math.log(1.0 - uniform_at(key, c))
            c += 1
            if total > rate:
                break
            m += 1
    near, far = params[7], params[8]
    fp_class = np.empty(m, dtype=np.int64)
    fp_c = np.empty((m, 3))
    fp_s = np.empty((m, 3))
    fp_y = np.empty(m)
    n_classes = fp_probs.shape[0]
    for i in range(m):
        base = FP_BASE + _FP_COUNT_DRAWS + ROW_STRIDE * i
        u = uniform_at(key, base)
        cls = n_classes - 1
        acc = 0.0
        for q in range(n_classes):
            acc += fp_probs[q]
            if u < acc:
                cls = q
                break
        fp_class[i] = cls
        range_m = near + (far - near) * uniform_at(key, base + 1)
        bearing = -math.pi + 2.0 * math.pi * uniform_at(key, base + 2)
        fp_y[i] = -math.pi + 2.0 * math.pi * uniform_at(key, base + 3)
        for a in range(3):
            typical = fp_sizes[cls, a]
            noisy = typical * (1.0 + normal_at(key, base + 4 + 2 * a) * s_size)
            fp_s[i, a] = max(noisy, 0.1 * typical)
        fp_c[i, 0] = range_m * math.cos(bearing)
        fp_c[i, 1] = range_m * math.sin(bearing)
        fp_c[i, 2] = 0.5 * fp_s[i, 2]
    return rows, confuse, out_c, out_s, out_y, out_v, out_o, fp_class, fp_c, fp_s, fp_y


@numba.njit(cache=True, nogil=True)
def oracle_frame_packed(  # noqa: PLR0917 - numba takes no keyword-only parameters
    seed: int,
    index: int,
    centers: _F64,
    sizes: _F64,
    yaws: _F64,
    velocities: _F64,
    orientations: _F64,
    eligible: _BOOL,
    params: _F64,
    fp_probs: _F64,
    fp_sizes: _F64,
) -> tuple[int, int, _I64, _F64]:  # pragma: no cover - compiled
    """:func:`oracle_frame`'s eleven arrays in two (numba boxes every array it returns at a
    cost of its own, a pickled type read back each time): the k kept rows and m false
    positives, the ints (k rows, then m classes) and the floats, one array after another
    (confusion uniforms k, centres 3k, sizes 3k, yaws k, velocities 3k, orientations 3k, then
    the false positives' centres 3m, sizes 3m, yaws m) — the same values."""
    rows, confuse, c, s, y, v, o, fp_class, fp_c, fp_s, fp_y = oracle_frame(
        seed, index, centers, sizes, yaws, velocities, orientations, eligible, params,
        fp_probs, fp_sizes,
    )  # fmt: skip
    k, m = rows.shape[0], fp_class.shape[0]
    ints = np.empty(k + m, dtype=np.int64)
    ints[:k] = rows
    ints[k:] = fp_class
    floats = np.empty(14 * k + 7 * m)
    at = 0
    for part in (confuse, c.ravel(), s.ravel(), y, v.ravel(), o.ravel()):
        floats[at : at + part.shape[0]] = part
        at += part.shape[0]
    for part in (fp_c.ravel(), fp_s.ravel(), fp_y):
        floats[at : at + part.shape[0]] = part
        at += part.shape[0]
    return k, m, ints, floats
