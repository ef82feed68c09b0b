"""A simulated pinhole camera: sky, textured ground and shaded boxes, with a depth buffer.

Rendering is analytic, in compiled loops over the pixels (:mod:`redrive.sim.camera_kernels`; no
GPU, no Embree): every pixel's ray is intersected with
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
from redrive.sim import camera_kernels as kernels
from redrive.sim.mesh import box_vertices
from redrive.sim.rig import CameraIntrinsics, SensorSpec
from redrive.sim.scene import GroundLabel, Scene
from redrive.sim.scratch import Scratch
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
        self._scratch = Scratch()  # an image's work arrays, per drawing thread
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
        self._ray_len = np.ascontiguousarray(np.linalg.norm(rays, axis=2), dtype=np.float32)

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

        The image is drawn by compiled loops (:mod:`redrive.sim.camera_kernels`) in bands of
        rows, on :attr:`workers` threads when more than one (the loops release the GIL); every
        pixel is computed by the same arithmetic whichever band holds it, so the image does not
        depend on the number of threads.
        """
        pose = scene.map_from_base if map_from_base is None else np.asarray(map_from_base)
        map_from_opt = self.map_from_optical(pose)
        k = self.intrinsics
        h, w = k.height, k.width
        work = self._scratch  # kept between images; the depth map and the pixels are handed out
        bufs = _Buffers(
            color=work.array("color", (h, w, 3), np.float32),
            depth=np.empty((h, w), dtype=np.float32),
            owner=work.array("owner", (h, w), np.int32),
            kind=work.array("kind", (h, w), np.uint8),
            label=work.array("label", (h, w), np.uint8),
            face=work.array("face", (h, w), np.uint8),
            fog=work.array("fog", (h, w), np.float32),
            pixels=np.empty((h, w, 3), dtype=np.uint8),
        )
        boxes = self._box_table(scene, map_from_opt)
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
        owner = bufs.owner
        ids = scene.objects.object_id
        counts = np.bincount(owner[owner >= 0], minlength=len(ids))
        per_object = MappingProxyType({int(i): int(c) for i, c in zip(ids, counts, strict=True)})
        return CameraFrame(
            stamp_ns=scene.stamp_ns,
            frame_id=self.frame_id,
            image=Image(pixels=bufs.pixels, encoding="rgb8"),
            depth_m=bufs.depth,
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
        boxes: _BoxTable,
        *,
        rows: tuple[int, int],
        bufs: _Buffers,
    ) -> None:
        """Sky and ground, the boxes, the haze, the pixels, for the image rows [r0, r1)."""
        r0, r1 = rows
        ground = scene.ground
        rot = np.ascontiguousarray(map_from_opt[:3, :3], dtype=np.float32)
        cam = np.ascontiguousarray(map_from_opt[:3, 3], dtype=np.float64)
        kernels.draw_ground_and_sky(
            r0,
            r1,
            self._x,
            self._y,
            rot,
            cam,
            self._ray_len,
            ground.labels,
            ground.origin_xy,
            float(ground.resolution_m),
            int(GroundLabel.GRASS),
            np.float32(-1.0 / self.fog_distance_m),
            _SKY_HORIZON,
            _SKY_SPAN,
            bufs.color,
            bufs.depth,
            bufs.fog,
            bufs.kind,
            bufs.label,
            bufs.owner,
        )
        if boxes.rects.shape[0]:
            kernels.draw_boxes(
                r0,
                r1,
                self._x,
                self._y,
                boxes.rects,
                boxes.z_min,
                boxes.r_local,
                boxes.slab_lo,
                boxes.slab_hi,
                np.float32(_NEAR_M),
                self._ray_len,
                np.float32(self.fog_distance_m),
                bufs.depth,
                bufs.owner,
                bufs.face,
                bufs.kind,
                bufs.fog,
            )
        # numpy's float32 exp, as the haze has always been computed (numba's rounds otherwise)
        np.exp(bufs.fog[r0:r1], out=bufs.fog[r0:r1])
        kernels.shade(
            r0,
            r1,
            bufs.kind,
            bufs.fog,
            bufs.label,
            _GROUND_LUT,
            bufs.owner,
            bufs.face,
            boxes.rgb,
            _SKY_HORIZON,
            bufs.color,
            bufs.pixels,
        )

    def _box_table(self, scene: Scene, map_from_opt: npt.NDArray[np.float64]) -> _BoxTable:
        """What the box kernel needs of the boxes to draw (nearest first, :meth:`_box_rects`)
        and every box's colour per face (albedo × Lambert + ambient shade, clipped)."""
        objs, looks = scene.objects, scene.looks
        rects = self._box_rects(scene, map_from_opt)
        n = len(rects)
        table = _BoxTable(
            rects=np.empty((n, 5), dtype=np.int64),
            z_min=np.empty(n, dtype=np.float32),
            r_local=np.empty((n, 3, 3), dtype=np.float32),
            slab_lo=np.empty((n, 3), dtype=np.float32),
            slab_hi=np.empty((n, 3), dtype=np.float32),
            rgb=np.zeros((len(objs), 6, 3), dtype=np.float32),
        )
        rot, origin = map_from_opt[:3, :3], map_from_opt[:3, 3]
        for b, (i, z_min, (u0, v0, u1, v1)) in enumerate(rects):
            yaw = float(objs.yaw_rad[i])
            c, s = math.cos(yaw), math.sin(yaw)
            box_from_map = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
            o_local = box_from_map @ (origin - objs.center_m[i])
            half = 0.5 * objs.size_m[i]
            table.rects[b] = (i, u0, v0, u1, v1)
            table.z_min[b] = z_min
            table.r_local[b] = box_from_map @ rot  # box frame from optical
            table.slab_lo[b] = -half - o_local
            table.slab_hi[b] = half - o_local
            # the faces: +x, +y, +z, −x, −y, −z of the box (the normal facing the camera)
            normals = np.concatenate([box_from_map, -box_from_map])
            lambert = np.clip(normals @ self.sun, 0.0, 1.0)
            ambient = 0.35 + 0.15 * normals[:, 2]  # the sky lights the tops a little more
            shade = (ambient + 0.65 * lambert).astype(np.float32)
            albedo = looks.colors_rgb[i].astype(np.float32)
            table.rgb[i] = np.clip(albedo * shade[:, None], 0.0, 255.0)
        return table

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
        corners = box_vertices(objs.center_m, objs.size_m, objs.yaw_rad)  # (N, 8, 3)
        opt_from_map = invert(map_from_opt)
        local = corners @ opt_from_map[:3, :3].T + opt_from_map[:3, 3]  # (N, 8, 3) optical
        # near boxes first: they fill the depth buffer and reject the pixels of those behind
        order = np.argsort(np.linalg.norm(objs.center_m - map_from_opt[:3, 3], axis=1))
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


class _Buffers(NamedTuple):
    """The frame being drawn (H × W): colour (sky) float32 (H, W, 3), depth float32, the
    object index or −1, what each pixel shows (:data:`~redrive.sim.camera_kernels.KIND_SKY`,
    …), the ground label, the box face, the fog (its argument until ``exp``), the pixels."""

    color: npt.NDArray[np.float32]
    depth: npt.NDArray[np.float32]
    owner: npt.NDArray[np.int32]
    kind: npt.NDArray[np.uint8]
    label: npt.NDArray[np.uint8]
    face: npt.NDArray[np.uint8]
    fog: npt.NDArray[np.float32]
    pixels: npt.NDArray[np.uint8]


class _BoxTable(NamedTuple):
    """The boxes to draw, nearest first (B of them): (B, 5) int64 object index and pixel
    rectangle u0, v0, u1, v1; (B,) float32 nearest depth; (B, 3, 3) float32 box frame from the
    optical frame; (B, 3) float32 slab bounds relative to the camera; and (N, 6, 3) float32
    colour per object and face."""

    rects: npt.NDArray[np.int64]
    z_min: npt.NDArray[np.float32]
    r_local: npt.NDArray[np.float32]
    slab_lo: npt.NDArray[np.float32]
    slab_hi: npt.NDArray[np.float32]
    rgb: npt.NDArray[np.float32]


def _bands(height: int, workers: int) -> list[tuple[int, int]]:
    """Row ranges [r0, r1) covering ``height`` rows: one, or two per worker (interleaved so
    that the sky, the ground and the boxes near the horizon spread over the threads)."""
    count = 1 if workers <= 1 else min(2 * workers, height)
    edges = [round(height * b / count) for b in range(count + 1)]
    return [(edges[b], edges[b + 1]) for b in range(count) if edges[b] < edges[b + 1]]


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
