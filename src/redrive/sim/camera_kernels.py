"""Compiled pixel loops of :class:`~redrive.sim.camera.CameraModel` (numba, ``nogil``).

The camera's arithmetic, pixel by pixel, in the precision and order the numpy renderer used —
float32 where it computed in float32, float64 where numpy promoted (a float64 scalar against a
float32 array), the constants cast as numpy cast them — so the image is the same bytes.  The one
function not computed here is ``exp``: numba's float32 ``exp`` goes through float64 and rounds
differently from numpy's SIMD ``expf`` in about half of the arguments, so the kernels write the
argument of each pixel's fog and the caller runs ``np.exp`` on the whole image at once.

Every kernel works on a band of rows ``[r0, r1)`` and writes only there, so bands can be drawn
on threads at the same time (``nogil``).
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
import numpy.typing as npt

__all__ = [
    "KIND_BOX",
    "KIND_GROUND",
    "KIND_SKY",
    "draw_boxes",
    "draw_ground_and_sky",
    "shade",
]

KIND_SKY = 0
KIND_GROUND = 1
KIND_BOX = 2

_F32 = np.float32


@numba.njit(cache=True, nogil=True, inline="always")
def _np_minimum(a: Any, b: Any) -> Any:  # pragma: no cover - compiled
    """``np.minimum`` of two scalars: a NaN on either side wins."""
    if math.isnan(a):
        return a
    if math.isnan(b):
        return b
    return a if a <= b else b


@numba.njit(cache=True, nogil=True, inline="always")
def _np_maximum(a: Any, b: Any) -> Any:  # pragma: no cover - compiled
    """``np.maximum`` of two scalars: a NaN on either side wins."""
    if math.isnan(a):
        return a
    if math.isnan(b):
        return b
    return a if a >= b else b


@numba.njit(cache=True, nogil=True)
def draw_ground_and_sky(  # noqa: PLR0917  # pragma: no cover - compiled
    r0: int,
    r1: int,
    x: npt.NDArray[np.float32],
    y: npt.NDArray[np.float32],
    rot: npt.NDArray[np.float32],
    cam: npt.NDArray[np.float64],
    ray_len: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    ground_origin: npt.NDArray[np.float64],
    ground_res: float,
    grass: int,
    fog_scale: np.float32,
    sky_horizon: npt.NDArray[np.float32],
    sky_span: npt.NDArray[np.float32],
    color: npt.NDArray[np.float32],
    depth: npt.NDArray[np.float32],
    fog_arg: npt.NDArray[np.float32],
    kind: npt.NDArray[np.uint8],
    label_of: npt.NDArray[np.uint8],
    owner: npt.NDArray[np.int32],
) -> None:
    """Rows ``[r0, r1)``: the sky's colour (depth +inf), or the ground's depth, label and fog
    argument; no object owns any pixel yet (``owner`` −1).

    ``rot`` is map_from_optical's rotation as float32, ``cam`` its translation (float64); the
    ground is hit where the map-frame ray points down (and the camera is above z = 0).
    """
    h_lab, w_lab = labels.shape
    above = cam[2] > 0.0
    minus_cz = -cam[2]
    down = _F32(-1e-6)
    zero, one, inf = _F32(0.0), _F32(1.0), _F32(np.inf)
    for r in range(r0, r1):
        yr = y[r]
        for c in range(x.shape[0]):
            owner[r, c] = -1
            xc = x[c]
            dz = rot[2, 0] * xc + rot[2, 1] * yr + rot[2, 2]
            rl = ray_len[r, c]
            if above and dz < down:
                dx = rot[0, 0] * xc + rot[0, 1] * yr + rot[0, 2]
                dy = rot[1, 0] * xc + rot[1, 1] * yr + rot[1, 2]
                t = _F32(minus_cz / np.float64(dz))
                gx = cam[0] + np.float64(dx * t)
                gy = cam[1] + np.float64(dy * t)
                col = math.floor((gx - ground_origin[0]) / ground_res)
                row = math.floor((gy - ground_origin[1]) / ground_res)
                lab = grass
                if col >= 0 and col < w_lab and row >= 0 and row < h_lab:
                    lab = labels[row, col]
                label_of[r, c] = lab
                depth[r, c] = t
                fog_arg[r, c] = t * rl * fog_scale
                kind[r, c] = KIND_GROUND
            else:
                elev = dz / rl
                elev = _np_maximum(elev, zero)
                elev = _np_minimum(elev, one)
                elev = _F32(math.sqrt(elev))
                for ch in range(3):
                    color[r, c, ch] = elev * sky_span[ch] + sky_horizon[ch]
                depth[r, c] = inf
                fog_arg[r, c] = zero
                kind[r, c] = KIND_SKY


@numba.njit(cache=True, nogil=True)
def draw_boxes(  # noqa: PLR0917  # pragma: no cover - compiled
    r0: int,
    r1: int,
    x: npt.NDArray[np.float32],
    y: npt.NDArray[np.float32],
    rects: npt.NDArray[np.int64],
    z_min: npt.NDArray[np.float32],
    r_local: npt.NDArray[np.float32],
    slab_lo: npt.NDArray[np.float32],
    slab_hi: npt.NDArray[np.float32],
    near_m: np.float32,
    ray_len: npt.NDArray[np.float32],
    fog_distance: np.float32,
    depth: npt.NDArray[np.float32],
    owner: npt.NDArray[np.int32],
    face: npt.NDArray[np.uint8],
    kind: npt.NDArray[np.uint8],
    fog_arg: npt.NDArray[np.float32],
) -> None:
    """Slab-test the boxes, in the order given (nearest first), over their pixel rectangles
    within rows ``[r0, r1)``; a hit nearer than the depth buffer takes the pixel.

    Per box ``b``: ``rects[b]`` = (index into the scene's objects, u0, v0, u1, v1);
    ``r_local[b]`` (3, 3) the box frame from the optical frame; the slab of axis ``a`` is
    ``[slab_lo[b, a], slab_hi[b, a]]`` relative to the camera, ``z_min[b]`` the nearest depth
    any of it can have.  ``face`` gets the face hit: the axis of the slab entered last, + 3
    when the ray runs along that axis (the face whose normal is the axis's negative);
    ``fog_arg`` the fog's argument −(t · |ray|) / fog distance.
    """
    tiny = _F32(1e-12)
    one = _F32(1.0)
    for b in range(rects.shape[0]):
        i, u0, v0, u1, v1 = rects[b, 0], rects[b, 1], rects[b, 2], rects[b, 3], rects[b, 4]
        v0 = max(v0, r0)
        v1 = min(v1, r1)
        if v0 >= v1:
            continue
        zb = z_min[b]
        farther = False  # does any pixel of the rectangle hold something behind the box's
        for r in range(v0, v1):  # nearest possible depth?  if not, it cannot show
            for c in range(u0, u1):
                if depth[r, c] > zb:
                    farther = True
                    break
            if farther:
                break
        if not farther:
            continue
        for r in range(v0, v1):
            yr = y[r]
            for c in range(u0, u1):
                d = depth[r, c]
                xc = x[c]
                tmin = tmax = near1 = near2 = inv0 = inv1 = inv2 = _F32(0.0)
                for a in range(3):
                    inv = r_local[b, a, 0] * xc + r_local[b, a, 1] * yr
                    inv = inv + r_local[b, a, 2]
                    if inv == 0.0:
                        inv = tiny
                    inv = one / inv
                    t1 = slab_lo[b, a] * inv
                    t2 = slab_hi[b, a] * inv
                    near = _np_minimum(t1, t2)
                    far = _np_maximum(t1, t2)
                    if a == 0:
                        inv0 = inv
                        tmin, tmax = near, far
                    elif a == 1:
                        near1, inv1 = near, inv
                        tmin = _np_maximum(tmin, near)
                        tmax = _np_minimum(tmax, far)
                    else:
                        near2, inv2 = near, inv
                        tmin = _np_maximum(tmin, near)
                        tmax = _np_minimum(tmax, far)
                if not (tmax >= tmin > near_m and tmin < d):
                    continue
                axis = 0
                d_axis = inv0
                if near1 == tmin:
                    axis, d_axis = 1, inv1
                if near2 == tmin:
                    axis, d_axis = 2, inv2
                face[r, c] = axis + 3 if d_axis > 0.0 else axis
                depth[r, c] = tmin
                owner[r, c] = i
                kind[r, c] = KIND_BOX
                fog_arg[r, c] = -(tmin * ray_len[r, c]) / fog_distance


@numba.njit(cache=True, nogil=True)
def shade(  # noqa: PLR0917  # pragma: no cover - compiled
    r0: int,
    r1: int,
    kind: npt.NDArray[np.uint8],
    fog: npt.NDArray[np.float32],
    label_of: npt.NDArray[np.uint8],
    ground_lut: npt.NDArray[np.float32],
    owner: npt.NDArray[np.int32],
    face: npt.NDArray[np.uint8],
    box_rgb: npt.NDArray[np.float32],
    sky_horizon: npt.NDArray[np.float32],
    color: npt.NDArray[np.float32],
    pixels: npt.NDArray[np.uint8],
) -> None:
    """The final colour (ground and boxes hazed by their fog; the sky as drawn), then
    ``uint8(clip(colour + 0.5, 0, 255))``.

    ``box_rgb[i, f]`` is box ``i``'s albedo × the shade of its face ``f``, clipped to 0–255.
    """
    half, lo, hi = _F32(0.5), _F32(0.0), _F32(255.0)
    one = _F32(1.0)
    for r in range(r0, r1):
        for c in range(kind.shape[1]):
            k = kind[r, c]
            if k == KIND_SKY:
                for ch in range(3):
                    value = color[r, c, ch] + half
                    pixels[r, c, ch] = np.uint8(_np_minimum(_np_maximum(value, lo), hi))
                continue
            f = fog[r, c]
            haze = one - f
            if k == KIND_GROUND:
                lab = label_of[r, c]
                for ch in range(3):
                    value = ground_lut[lab, ch] * f + sky_horizon[ch] * haze
                    value = value + half
                    pixels[r, c, ch] = np.uint8(_np_minimum(_np_maximum(value, lo), hi))
            else:
                i, fc = owner[r, c], face[r, c]
                for ch in range(3):
                    value = box_rgb[i, fc, ch] * f + sky_horizon[ch] * haze
                    value = value + half
                    pixels[r, c, ch] = np.uint8(_np_minimum(_np_maximum(value, lo), hi))
