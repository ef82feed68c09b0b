"""A simulated pinhole camera: sky, textured ground and shaded boxes, with a depth buffer.

Rendering is analytic and vectorised (no GPU, no Embree): every pixel's ray is intersected with
the ground plane z = 0 (colour looked up in the :class:`~redrive.sim.scene.GroundMap`) or, above
the horizon, coloured by a sky gradient; then every box is ray-traced (slab test) over the pixels
of its projected 2D bounds only, and kept where it is nearer than what the depth buffer holds —
so near boxes hide far ones and boxes hide the ground.  Faces are shaded by normal · sun
direction (Lambert + ambient) times the box ``colors``; distance fades everything into a haze.

Pixels follow OpenCV / ROS conventions: the image lives in the optical frame (z forward,
x right, y down), pixel (u, v) = (column, row) has its centre at integer coordinates, so a
point projects with :func:`redrive.geometry.project_points` and ``K`` to the pixel it lands in.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from types import MappingProxyType
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from redrive.errors import SimulationError
from redrive.geometry import compose, invert
from redrive.sim.mesh import box_vertices
from redrive.sim.rig import CameraIntrinsics, SensorSpec
from redrive.sim.scene import GroundLabel, GroundMap, Scene
from redrive.types import Image, SensorType
from redrive.types._arrays import frozen_array

__all__ = ["GROUND_COLORS", "CameraFrame", "CameraModel"]

#: RGB albedo of the ground by label.
GROUND_COLORS: Mapping[GroundLabel, tuple[int, int, int]] = MappingProxyType(
    {
        GroundLabel.GRASS: (78, 128, 58),
        GroundLabel.ROAD: (82, 84, 88),
        GroundLabel.LANE_MARKING: (235, 235, 228),
        GroundLabel.SIDEWALK: (170, 168, 160),
        GroundLabel.STOP_LINE: (240, 240, 235),
    }
)
_GROUND_LUT = np.zeros((256, 3), dtype=np.float32)
for _label, _rgb in GROUND_COLORS.items():
    _GROUND_LUT[int(_label)] = _rgb

_GROUND_LUT_BY_CHANNEL = tuple(np.ascontiguousarray(_GROUND_LUT[:, ch]) for ch in range(3))

_SKY_HORIZON = np.array([205.0, 222.0, 236.0], dtype=np.float32)
_SKY_ZENITH = np.array([78.0, 130.0, 205.0], dtype=np.float32)
_SKY_SPAN = _SKY_ZENITH - _SKY_HORIZON
_NEAR_M = 0.05


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraFrame:
    """One rendered frame.

    Attributes:
        stamp_ns: when it was taken.
        frame_id: its optical frame.
        image: rgb8 (H, W, 3).
        depth_m: (H, W) float32 depth along the optical axis, metres; +inf for sky.
        pixels_per_object: object id → visible pixels, for every object of the scene.
    """

    stamp_ns: int
    frame_id: str
    image: Image
    depth_m: npt.NDArray[np.float32]
    pixels_per_object: Mapping[int, int]

    def __post_init__(self) -> None:
        shape = (self.image.height, self.image.width)
        depth = frozen_array(
            self.depth_m, name="CameraFrame.depth_m", dtype=np.float32, shape=shape
        )
        object.__setattr__(self, "depth_m", depth)


class CameraModel:
    """A camera of the rig.

    Args:
        intrinsics: size and pinhole parameters.
        base_from_optical: 4×4 optical frame → base_link (see
            :meth:`~redrive.sim.rig.SensorSpec.base_from_optical`).
        fog_distance_m: distance at which 63 % of a surface's colour has faded into haze.
        sun_direction: (3,) map-frame direction *towards* the sun.
        frame_id: frame id of the images.
        workers: threads that draw the image, in bands of rows (default: up to 2, the CPUs
            there are); 1 draws it on the calling thread.  The image is the same either way.
    """

    def __init__(
        self,
        intrinsics: CameraIntrinsics,
        *,
        base_from_optical: npt.ArrayLike,
        fog_distance_m: float = 250.0,
        sun_direction: tuple[float, float, float] = (0.4, 0.3, 0.87),
        frame_id: str = "camera_optical",
        workers: int | None = None,
    ) -> None:
        if workers is not None and workers < 1:
            msg = f"CameraModel: workers must be >= 1, got {workers}"
            raise SimulationError(msg)
        self.intrinsics = intrinsics
        self.workers = workers if workers is not None else max(1, min(2, os.cpu_count() or 1))
        self._pool: ThreadPoolExecutor | None = None
        self.base_from_optical = np.asarray(base_from_optical, dtype=np.float64)
        self.fog_distance_m = float(fog_distance_m)
        sun = np.asarray(sun_direction, dtype=np.float64)
        self.sun = sun / np.linalg.norm(sun)
        self.frame_id = frame_id
        k = intrinsics
        u = (np.arange(k.width, dtype=np.float64) - k.cx) / k.fx
        v = (np.arange(k.height, dtype=np.float64) - k.cy) / k.fy
        rays = np.empty((k.height, k.width, 3), dtype=np.float32)
        rays[..., 0] = u[None, :]
        rays[..., 1] = v[:, None]
        rays[..., 2] = 1.0
        #: (H, W, 3) optical-frame rays with z = 1 (so distance along a ray = depth).
        self.rays = rays
        self._x = u.astype(np.float32)
        self._y = v.astype(np.float32)
        self._ray_len = np.linalg.norm(rays, axis=2)

    @classmethod
    def from_spec(cls, spec: SensorSpec) -> CameraModel:
        if spec.kind is not SensorType.CAMERA or spec.camera is None:
            msg = f"sensor {spec.name!r} is a {spec.kind.value}, not a camera"
            raise SimulationError(msg)
        return cls(
            spec.camera,
            base_from_optical=spec.base_from_optical(),
            frame_id=f"{spec.name}_optical",
        )

    def map_from_optical(self, map_from_base: npt.ArrayLike) -> npt.NDArray[np.float64]:
        return compose(map_from_base, self.base_from_optical)

    def image_from_map(self, map_from_base: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """3×4 projection of map points into this camera's pixels."""
        return self.intrinsics.matrix() @ invert(self.map_from_optical(map_from_base))[:3, :]

    def render(self, scene: Scene, *, map_from_base: npt.ArrayLike | None = None) -> CameraFrame:
        """Render ``scene`` from the ego pose ``map_from_base`` (default: the scene's).

        The image is drawn in bands of rows, on :attr:`workers` threads when more than one
        (numpy releases the GIL in its loops); every pixel is computed by the same arithmetic
        whichever band holds it, so the image does not depend on the number of threads.
        """
        pose = scene.map_from_base if map_from_base is None else np.asarray(map_from_base)
        map_from_opt = self.map_from_optical(pose)
        k = self.intrinsics
        h, w = k.height, k.width
        color = np.empty((h, w, 3), dtype=np.float32)
        depth = np.full((h, w), np.inf, dtype=np.float32)
        owner = np.full((h, w), -1, dtype=np.int32)
        bufs = _Buffers(color=color, depth=depth, owner=owner)
        boxes = self._box_rects(scene, map_from_opt)
        bands = _bands(h, self.workers)
        if len(bands) == 1:
            self._render_rows(scene, map_from_opt, boxes, rows=bands[0], bufs=bufs)
        else:
            pool = self._thread_pool()
            futures = [
                pool.submit(self._render_rows, scene, map_from_opt, boxes, rows=rows, bufs=bufs)
                for rows in bands
            ]
            for future in futures:
                future.result()
        np.add(color, 0.5, out=color)
        np.clip(color, 0, 255, out=color)
        pixels = color.astype(np.uint8)
        ids = scene.objects.object_ids
        counts = np.bincount(owner[owner >= 0], minlength=len(ids))
        per_object = MappingProxyType({int(i): int(c) for i, c in zip(ids, counts, strict=True)})
        return CameraFrame(
            stamp_ns=scene.stamp_ns,
            frame_id=self.frame_id,
            image=Image(pixels=pixels, encoding="rgb8"),
            depth_m=depth,
            pixels_per_object=per_object,
        )

    def _thread_pool(self) -> ThreadPoolExecutor:
        if self._pool is None:
            self._pool = ThreadPoolExecutor(self.workers, thread_name_prefix="camera-render")
        return self._pool

    def _render_rows(
        self,
        scene: Scene,
        map_from_opt: npt.NDArray[np.float64],
        boxes: list[tuple[int, float, tuple[int, int, int, int]]],
        *,
        rows: tuple[int, int],
        bufs: _Buffers,
    ) -> None:
        """Sky, ground, then the boxes, for the image rows ``rows`` = [r0, r1)."""
        r0, r1 = rows
        w = self.intrinsics.width
        n = (r1 - r0) * w
        rot = map_from_opt[:3, :3].astype(np.float32)
        cam = map_from_opt[:3, 3]
        # map-frame rays (optical z = 1) per component, from the pixel grid: R @ (x, y, 1)
        x, y = self._x[None, :], self._y[r0:r1, None]
        dz = (rot[2, 0] * x + rot[2, 1] * y + rot[2, 2]).reshape(-1)
        ray_len = self._ray_len[r0:r1].reshape(-1)
        color = bufs.color[r0:r1].reshape(n, 3)
        depth = bufs.depth[r0:r1].reshape(n)
        ground = (dz < -1e-6) if cam[2] > 0 else np.zeros(n, dtype=bool)
        # sky: gradient by elevation
        sky = _selection(~ground)
        elev = dz[sky] / ray_len[sky]
        np.maximum(elev, 0.0, out=elev)
        np.minimum(elev, 1.0, out=elev)
        np.sqrt(elev, out=elev)
        sky_color = color[sky]  # a view when the sky is one run of pixels
        for ch in range(3):  # one channel at a time: no (N, 3) temporaries
            np.multiply(elev, _SKY_SPAN[ch], out=sky_color[:, ch])
            sky_color[:, ch] += _SKY_HORIZON[ch]
        if not isinstance(sky, slice):
            color[sky] = sky_color
        # ground: ray / plane z = 0, label colour, haze with distance
        g = _selection(ground)
        if np.any(ground):
            dx = (rot[0, 0] * x + rot[0, 1] * y + rot[0, 2]).reshape(-1)
            dy = (rot[1, 0] * x + rot[1, 1] * y + rot[1, 2]).reshape(-1)
            t = (-cam[2] / dz[g]).astype(np.float32)
            labels = _ground_labels(scene.ground, cam[0] + dx[g] * t, cam[1] + dy[g] * t)
            fog = np.exp(t * ray_len[g] * np.float32(-1.0 / self.fog_distance_m))
            haze = np.float32(1.0) - fog
            ground_color = color[g]
            for ch in range(3):  # albedo · fog + horizon · (1 − fog), a channel at a time
                np.multiply(
                    np.take(_GROUND_LUT_BY_CHANNEL[ch], labels), fog, out=ground_color[:, ch]
                )
                ground_color[:, ch] += _SKY_HORIZON[ch] * haze
            if not isinstance(g, slice):
                color[g] = ground_color
            depth[g] = t
        for i, z_min, (u0, box_v0, u1, box_v1) in boxes:
            v0, v1 = max(box_v0, r0), min(box_v1, r1)
            if v0 >= v1:
                continue
            if not np.any(bufs.depth[v0:v1, u0:u1] > z_min):
                continue  # everything in the rectangle is nearer than the box can be
            self._draw_box(scene, i, map_from_opt=map_from_opt, rect=(u0, v0, u1, v1), bufs=bufs)

    def _box_rects(
        self, scene: Scene, map_from_opt: npt.NDArray[np.float64]
    ) -> list[tuple[int, float, tuple[int, int, int, int]]]:
        """The boxes to draw, nearest first: index, nearest depth of the box in front of the
        camera, pixel rectangle (u0, v0, u1, v1) bounding its projection."""
        objs = scene.objects
        if len(objs) == 0:
            return []
        k = self.intrinsics
        h, w = k.height, k.width
        corners = box_vertices(objs.centers, objs.sizes, objs.yaws_rad)  # (N, 8, 3)
        opt_from_map = invert(map_from_opt)
        local = corners @ opt_from_map[:3, :3].T + opt_from_map[:3, 3]  # (N, 8, 3) optical
        # near boxes first: they fill the depth buffer and reject the pixels of those behind
        order = np.argsort(np.linalg.norm(objs.centers - map_from_opt[:3, 3], axis=1))
        kmat = k.matrix()
        out = []
        for i in order:
            pts = _clip_to_near(local[i])
            if pts.shape[0] == 0:
                continue
            uv = pts[:, :2] / pts[:, 2:3] * kmat[[0, 1], [0, 1]] + kmat[:2, 2]
            lo = np.floor(uv.min(axis=0)).astype(int) - 1
            hi = np.ceil(uv.max(axis=0)).astype(int) + 2
            u0, v0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
            u1, v1 = min(int(hi[0]), w), min(int(hi[1]), h)
            if u0 >= u1 or v0 >= v1:
                continue
            # a hit's depth t is the optical z of a point of the box: never below the nearest
            # corner's (and the near plane's)
            z_min = max(float(pts[:, 2].min()), _NEAR_M) * (1.0 - 1e-4)
            out.append((int(i), z_min, (u0, v0, u1, v1)))
        return out

    def _draw_box(
        self,
        scene: Scene,
        i: int,
        *,
        map_from_opt: npt.NDArray[np.float64],
        rect: tuple[int, int, int, int],
        bufs: _Buffers,
    ) -> None:
        """Slab-test the rays of ``rect`` against box ``i``; keep the hits nearer than ``depth``."""
        objs = scene.objects
        k = self.intrinsics
        u0, v0, u1, v1 = rect
        yaw = float(objs.yaws_rad[i])
        c, s = math.cos(yaw), math.sin(yaw)
        box_from_map = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        r_local = box_from_map @ map_from_opt[:3, :3]  # box frame from optical
        o_local = box_from_map @ (map_from_opt[:3, 3] - objs.centers[i])
        half = 0.5 * objs.sizes[i]
        x = ((np.arange(u0, u1) - k.cx) / k.fx).astype(np.float32)[None, :]
        y = ((np.arange(v0, v1) - k.cy) / k.fy).astype(np.float32)[:, None]
        near_axis = []
        far_axis = []
        inverses = []  # 1 / the ray component along each box axis: its sign picks the face
        for a in range(3):
            r = r_local[a].astype(np.float32)
            inv = r[0] * x + r[1] * y  # (h, w) ray component along box axis a ...
            inv += r[2]
            inv[inv == 0.0] = np.float32(1e-12)
            np.divide(np.float32(1.0), inv, out=inv)  # ... inverted in place (same sign)
            t1 = np.float32(-half[a] - o_local[a]) * inv
            t2 = np.float32(half[a] - o_local[a]) * inv
            near_axis.append(np.minimum(t1, t2))
            far_axis.append(np.maximum(t1, t2, out=t1))
            inverses.append(inv)
        tmin = np.maximum(near_axis[0], near_axis[1])
        np.maximum(tmin, near_axis[2], out=tmin)
        tmax = np.minimum(far_axis[0], far_axis[1], out=far_axis[0])
        np.minimum(tmax, far_axis[2], out=tmax)
        region = bufs.depth[v0:v1, u0:u1]
        hit = tmax >= tmin
        hit &= tmin > _NEAR_M
        hit &= tmin < region
        if not hit.any():
            return
        t = tmin[hit]
        # which slab was entered last = the face hit; its normal faces the camera
        axis = np.zeros(t.shape[0], dtype=np.int64)
        axis[near_axis[1][hit] == t] = 1
        axis[near_axis[2][hit] == t] = 2
        d_axis = np.choose(axis, [inv[hit] for inv in inverses])
        face_normals = np.concatenate([box_from_map, -box_from_map])  # rows: +x, +y, +z, -x, ...
        face = np.where(d_axis > 0, axis + 3, axis)
        normals = face_normals[face]
        lambert = np.clip(normals @ self.sun, 0.0, 1.0)
        ambient = 0.35 + 0.15 * normals[:, 2]  # the sky lights the tops a little more
        shade = (ambient + 0.65 * lambert).astype(np.float32)
        fog = np.exp(-(t * self._ray_len[v0:v1, u0:u1][hit]) / self.fog_distance_m)[:, None]
        albedo = objs.colors[i].astype(np.float32)
        rgb = np.clip(albedo * shade[:, None], 0.0, 255.0) * fog + _SKY_HORIZON * (1.0 - fog)
        bufs.color[v0:v1, u0:u1][hit] = rgb
        region[hit] = t
        bufs.owner[v0:v1, u0:u1][hit] = i


class _Buffers(NamedTuple):
    """The frame being drawn: colour (H, W, 3) float32, depth (H, W) float32, owner (H, W)."""

    color: npt.NDArray[np.float32]
    depth: npt.NDArray[np.float32]
    owner: npt.NDArray[np.int32]


def _bands(height: int, workers: int) -> list[tuple[int, int]]:
    """Row ranges [r0, r1) covering ``height`` rows: one, or two per worker (interleaved so
    that the sky, the ground and the boxes near the horizon spread over the threads)."""
    count = 1 if workers <= 1 else min(2 * workers, height)
    edges = [round(height * b / count) for b in range(count + 1)]
    return [(edges[b], edges[b + 1]) for b in range(count) if edges[b] < edges[b + 1]]


def _selection(mask: npt.NDArray[np.bool_]) -> slice | npt.NDArray[np.intp]:
    """The indices where ``mask`` holds: a slice when they are one run (the ground and the sky
    of an upright camera are), which reads and writes without gathering."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return slice(0, 0)
    first, last = int(idx[0]), int(idx[-1])
    if last - first + 1 == idx.size:
        return slice(first, last + 1)
    return idx


def _ground_labels(
    ground: GroundMap, x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]
) -> npt.NDArray[np.uint8]:
    """:meth:`GroundMap.label_at` (same arithmetic) for points given as two 1-D arrays."""
    h, w = ground.labels.shape
    col = np.floor((x - ground.origin_xy[0]) / ground.resolution_m).astype(np.int64)
    row = np.floor((y - ground.origin_xy[1]) / ground.resolution_m).astype(np.int64)
    inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    labels = np.take(ground.labels.reshape(-1), np.where(inside, row * w + col, 0))
    out: npt.NDArray[np.uint8] = np.where(inside, labels, np.uint8(GroundLabel.GRASS))
    return out


_EDGES = np.array(
    [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]]
)


def _clip_to_near(corners: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Corners (8, 3) of a box in the optical frame → points bounding its part with z > near."""
    z = corners[:, 2]
    front = z > _NEAR_M
    if front.all() or not front.any():
        return corners[front]
    a, b = corners[_EDGES[:, 0]], corners[_EDGES[:, 1]]
    za, zb = a[:, 2], b[:, 2]
    cross = (za > _NEAR_M) != (zb > _NEAR_M)
    f = ((_NEAR_M - za[cross]) / (zb[cross] - za[cross]))[:, None]
    cut = a[cross] + f * (b[cross] - a[cross])
    cut[:, 2] = _NEAR_M * 1.0001
    return np.concatenate([corners[front], cut])
