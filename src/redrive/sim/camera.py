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
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from redrive.errors import SimulationError
from redrive.geometry import compose, invert
from redrive.sim.mesh import box_vertices
from redrive.sim.rig import CameraIntrinsics, SensorSpec
from redrive.sim.scene import GroundLabel, Scene
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
    """

    def __init__(
        self,
        intrinsics: CameraIntrinsics,
        *,
        base_from_optical: npt.ArrayLike,
        fog_distance_m: float = 250.0,
        sun_direction: tuple[float, float, float] = (0.4, 0.3, 0.87),
        frame_id: str = "camera_optical",
    ) -> None:
        self.intrinsics = intrinsics
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
        """Render ``scene`` from the ego pose ``map_from_base`` (default: the scene's)."""
        pose = scene.map_from_base if map_from_base is None else np.asarray(map_from_base)
        map_from_opt = self.map_from_optical(pose)
        k = self.intrinsics
        h, w = k.height, k.width
        rot = map_from_opt[:3, :3].astype(np.float32)
        cam = map_from_opt[:3, 3]
        # map-frame rays (optical z = 1) per component, from the pixel grid: R @ (x, y, 1)
        x, y = self._x[None, :], self._y[:, None]
        dx = (rot[0, 0] * x + rot[0, 1] * y + rot[0, 2]).reshape(-1)
        dy = (rot[1, 0] * x + rot[1, 1] * y + rot[1, 2]).reshape(-1)
        dz = (rot[2, 0] * x + rot[2, 1] * y + rot[2, 2]).reshape(-1)
        ray_len = self._ray_len.reshape(-1)
        color = np.empty((h * w, 3), dtype=np.float32)
        depth = np.full(h * w, np.inf, dtype=np.float32)
        ground = (dz < -1e-6) if cam[2] > 0 else np.zeros(h * w, dtype=bool)
        # sky: gradient by elevation
        sky = np.flatnonzero(~ground)
        elev = np.sqrt(np.clip(dz[sky] / ray_len[sky], 0.0, 1.0))
        color[sky] = _SKY_HORIZON + elev[:, None] * (_SKY_ZENITH - _SKY_HORIZON)
        # ground: ray / plane z = 0, label colour, haze with distance
        g = np.flatnonzero(ground)
        if g.size:
            t = (-cam[2] / dz[g]).astype(np.float32)
            xy = np.empty((g.size, 2))
            xy[:, 0] = cam[0] + dx[g] * t
            xy[:, 1] = cam[1] + dy[g] * t
            albedo = _GROUND_LUT[scene.ground.label_at(xy)]
            fog = np.exp(t * ray_len[g] * np.float32(-1.0 / self.fog_distance_m))[:, None]
            color[g] = albedo * fog + _SKY_HORIZON * (1.0 - fog)
            depth[g] = t
        owner = np.full((h, w), -1, dtype=np.int32)
        bufs = _Buffers(color=color.reshape(h, w, 3), depth=depth.reshape(h, w), owner=owner)
        self._draw_boxes(scene, map_from_opt, bufs=bufs)
        pixels = np.clip(bufs.color + 0.5, 0, 255).astype(np.uint8)
        ids = scene.objects.object_ids
        counts = np.bincount(owner[owner >= 0], minlength=len(ids))
        per_object = MappingProxyType({int(i): int(c) for i, c in zip(ids, counts, strict=True)})
        return CameraFrame(
            stamp_ns=scene.stamp_ns,
            frame_id=self.frame_id,
            image=Image(pixels=pixels, encoding="rgb8"),
            depth_m=bufs.depth,
            pixels_per_object=per_object,
        )

    def _draw_boxes(
        self, scene: Scene, map_from_opt: npt.NDArray[np.float64], *, bufs: _Buffers
    ) -> None:
        objs = scene.objects
        if len(objs) == 0:
            return
        k = self.intrinsics
        h, w = k.height, k.width
        corners = box_vertices(objs.centers, objs.sizes, objs.yaws_rad)  # (N, 8, 3)
        opt_from_map = invert(map_from_opt)
        local = corners @ opt_from_map[:3, :3].T + opt_from_map[:3, 3]  # (N, 8, 3) optical
        # near boxes first: they fill the depth buffer and reject the pixels of those behind
        order = np.argsort(np.linalg.norm(objs.centers - map_from_opt[:3, 3], axis=1))
        kmat = k.matrix()
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
            rect = (u0, v0, u1, v1)
            self._draw_box(scene, int(i), map_from_opt=map_from_opt, rect=rect, bufs=bufs)

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
        comps = []
        near_axis = []
        far_axis = []
        for a in range(3):
            r = r_local[a].astype(np.float32)
            da = r[0] * x + r[1] * y + r[2]  # (h, w) ray component along box axis a
            da = np.where(da == 0.0, np.float32(1e-12), da)
            inv = np.float32(1.0) / da
            t1 = np.float32(-half[a] - o_local[a]) * inv
            t2 = np.float32(half[a] - o_local[a]) * inv
            lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
            comps.append(da)
            near_axis.append(lo)
            far_axis.append(hi)
        tmin = np.maximum(np.maximum(near_axis[0], near_axis[1]), near_axis[2])
        tmax = np.minimum(np.minimum(far_axis[0], far_axis[1]), far_axis[2])
        region = bufs.depth[v0:v1, u0:u1]
        hit = (tmax >= tmin) & (tmin > _NEAR_M) & (tmin < region)
        if not hit.any():
            return
        t = tmin[hit]
        # which slab was entered last = the face hit; its normal faces the camera
        axis = np.zeros(t.shape[0], dtype=np.int64)
        axis[near_axis[1][hit] == t] = 1
        axis[near_axis[2][hit] == t] = 2
        d_axis = np.choose(axis, [comps[0][hit], comps[1][hit], comps[2][hit]])
        sign = np.where(d_axis > 0, -1.0, 1.0)
        face_normals = np.concatenate([box_from_map, -box_from_map])  # rows: +x, +y, +z, -x, ...
        face = np.where(sign > 0, axis, axis + 3)
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
