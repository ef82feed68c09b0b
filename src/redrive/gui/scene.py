"""What the views draw, computed off the GUI thread: plain numpy, no Qt.

The frame loader turns a :class:`~redrive.types.Frame` (plus the run's outputs for it) into a
:class:`Scene`: decimated, coloured points; box edges of each layer as line-segment arrays; a
top-down raster for the 2D planview; camera images with projected boxes and LiDAR points burnt
in.  The GUI thread only hands these arrays to pyqtgraph, so a frame costs it no numpy work.

Coordinates: the planview is base_link (x forward, y left, z up; REP-103), metres.
"""

from __future__ import annotations

import enum
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.geometry.boxes import box_corners
from redrive.geometry.projection import project_points
from redrive.types import DetectedObject, PlannedPath

__all__ = [
    "BOX_EDGES",
    "CameraScene",
    "ColorMode",
    "Layer",
    "LayerLines",
    "RasterSpec",
    "Scene",
    "box_edge_segments",
    "color_points",
    "decimate",
    "project_segments",
    "rasterize_top_down",
    "splat_points",
]

Float = npt.NDArray[np.float64]
Rgba = npt.NDArray[np.float32]

#: The 12 edges of :func:`redrive.geometry.boxes.box_corners`' corner order, plus a "nose" line
#: from the box centre of the front face's bottom edge … drawn as the front face's diagonal
#: cross so the heading is visible.
BOX_EDGES: npt.NDArray[np.intp] = np.array(
    [
        [0, 1], [1, 2], [2, 3], [3, 0],
        [4, 5], [5, 6], [6, 7], [7, 4],
        [0, 4], [1, 5], [2, 6], [3, 7],
        [0, 7], [3, 4],
    ],
    dtype=np.intp,
)  # fmt: skip


class ColorMode(enum.Enum):
    """How LiDAR points are coloured."""

    DISTANCE = "distance"
    HEIGHT = "height"
    INTENSITY = "intensity"


class Layer(enum.Enum):
    """What the planview and camera can draw (the "Object Visible" choices)."""

    POINTS = "LiDAR points"
    GROUND_TRUTH = "ground truth"
    DETECTIONS = "detections"
    TRACK_IDS = "track ids"
    EGO = "ego vehicle"
    LOGGED_EGO = "logged ego (ghost)"
    PATH = "planned path"
    ROAD_MAP = "road map"


@dataclass(frozen=True, slots=True)
class RasterSpec:
    """The top-down raster of the 2D planview: square, centred on base_link."""

    half_extent_m: float = 60.0
    cell_m: float = 0.15

    @property
    def size_px(self) -> int:
        return math.ceil(2 * self.half_extent_m / self.cell_m)


@dataclass(frozen=True, slots=True, kw_only=True)
class LayerLines:
    """One layer's boxes: ``segments`` (2K, 3) endpoints, consecutive pairs are one edge."""

    name: str
    color: tuple[int, int, int]
    segments: Float
    labels: tuple[tuple[str, float, float, float], ...] = ()  # text, x, y, z
    #: opacity: below 1 the layer is a ghost (translucent, dashed in 2D).
    alpha: float = 1.0


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraScene:
    """One camera's image with the overlays burnt in / as pixel segments."""

    sensor_id: str
    image: npt.NDArray[np.uint8]  # (H, W, 3) rgb, points splatted in when asked
    segments: dict[str, tuple[tuple[int, int, int], Float]]  # layer → colour, (2K, 2) px
    calibrated: bool


@dataclass(frozen=True, slots=True, kw_only=True)
class Scene:
    """Everything one frame shows."""

    index: int
    stamp_ns: int
    points: npt.NDArray[np.float32]  # (N, 3) base_link, decimated
    colors: Rgba  # (N, 4) 0..1
    point_count: int  # before decimation
    layers: tuple[LayerLines, ...]
    path: Float | None  # (K, 3) base_link
    raster: npt.NDArray[np.uint8] | None  # (S, S, 3), row 0 = +x far edge … see rasterize
    cameras: Mapping[str, CameraScene] = field(default_factory=dict)
    #: the ego pose in the log's world frame (x_m, y_m, heading_rad), None without an ego state.
    pose: tuple[float, float, float] | None = None


def transform_xyz(mat: npt.NDArray[np.float64], xyz: npt.NDArray[np.float32]) -> Float:
    """``mat`` (3×4 or 4×4; rows used: 3) applied to (N, 3) points, column by column — not a
    matmul: numpy hands N×3 @ 3×3 to OpenBLAS, whose threads then spin on the second core the
    GUI and the loader need (``python -m benchmarks gui``)."""
    x, y, z = (xyz[:, i].astype(np.float64) for i in range(3))
    out = np.empty((len(xyz), 3), dtype=np.float64)
    for row in range(3):
        r = mat[row]
        out[:, row] = r[0] * x + r[1] * y + r[2] * z + r[3]
    return out


def decimate(n: int, limit: int) -> npt.NDArray[np.intp] | slice:
    """Indices keeping at most ``limit`` of ``n`` points, evenly strided (deterministic)."""
    if n <= limit:
        return slice(None)
    step = n / limit
    return (np.arange(limit) * step).astype(np.intp)


_TURBO_ANCHORS = np.array(
    [
        [0.19, 0.07, 0.23],
        [0.27, 0.49, 0.98],
        [0.10, 0.85, 0.76],
        [0.55, 0.98, 0.26],
        [0.98, 0.73, 0.21],
        [0.87, 0.26, 0.04],
        [0.48, 0.02, 0.01],
    ],
    dtype=np.float32,
)


def _colormap(values: npt.NDArray[Any], lo: float, hi: float) -> Rgba:
    """Turbo-like ramp (7 anchors, linear between) of ``values`` clipped to [lo, hi]."""
    span = hi - lo if hi > lo else 1.0
    t = np.clip((np.asarray(values, dtype=np.float32) - lo) / span, 0.0, 1.0)
    pos = t * (len(_TURBO_ANCHORS) - 1)
    i0 = np.minimum(pos.astype(np.intp), len(_TURBO_ANCHORS) - 2)
    frac = (pos - i0)[:, None]
    rgb = _TURBO_ANCHORS[i0] * (1 - frac) + _TURBO_ANCHORS[i0 + 1] * frac
    out = np.ones((len(t), 4), dtype=np.float32)
    out[:, :3] = rgb
    return out


def color_points(
    xyz: npt.NDArray[np.float32],
    mode: ColorMode,
    *,
    intensity: npt.NDArray[Any] | None = None,
) -> Rgba:
    """(N, 4) RGBA in [0, 1]: by range (0–60 m), height (−2…+3 m) or intensity (its 1–99 %)."""
    if mode is ColorMode.HEIGHT:
        return _colormap(xyz[:, 2], -2.0, 3.0)
    if mode is ColorMode.INTENSITY and intensity is not None and len(intensity):
        lo, hi = np.percentile(intensity, [1, 99])
        return _colormap(intensity, float(lo), float(hi))
    dist = np.sqrt(np.einsum("ij,ij->i", xyz[:, :2], xyz[:, :2]))
    return _colormap(dist, 0.0, 60.0)


def box_edge_segments(objects: Sequence[DetectedObject]) -> Float:
    """(2·14·K, 3) endpoints of every box's edges (12 edges + a cross on the front face)."""
    if not objects:
        return np.zeros((0, 3), dtype=np.float64)
    corners = np.stack([box_corners(o.box) for o in objects])  # (K, 8, 3)
    return corners[:, BOX_EDGES.reshape(-1)].reshape(-1, 3)


def project_segments(image_from_base: Float, segments: Float, *, near_m: float = 0.3) -> Float:
    """(2M, 2) pixel endpoints of the 3D ``segments`` both of whose ends are in front of the
    camera (depth > ``near_m``); an edge crossing the image plane is clipped at ``near_m``."""
    if len(segments) == 0:
        return np.zeros((0, 2), dtype=np.float64)
    a, b = segments[0::2], segments[1::2]
    mat = np.asarray(image_from_base, dtype=np.float64)
    depth_a = a @ mat[2, :3] + mat[2, 3]
    depth_b = b @ mat[2, :3] + mat[2, 3]
    keep = (depth_a > near_m) | (depth_b > near_m)
    a, b, depth_a, depth_b = a[keep], b[keep], depth_a[keep], depth_b[keep]
    # Clip the part behind the near plane.
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(depth_a < near_m, (near_m - depth_a) / (depth_b - depth_a), 0.0)
        a = a + t[:, None] * (b - a)
        t = np.where(depth_b < near_m, (near_m - depth_b) / (depth_a - depth_b), 0.0)
        b = b + t[:, None] * (a - b)
    both = np.empty((2 * len(a), 3), dtype=np.float64)
    both[0::2], both[1::2] = a, b
    uv, _ = project_points(mat, both)
    return uv


def splat_points(
    image: npt.NDArray[np.uint8],
    image_from_base: Float,
    points_base: npt.NDArray[np.float32],
    *,
    max_depth_m: float = 60.0,
    radius_px: int = 1,
) -> int:
    """Draw LiDAR points into ``image`` (in place) coloured by depth; returns how many landed."""
    if len(points_base) == 0:
        return 0
    mat = np.asarray(image_from_base, dtype=np.float64)
    # Depth first (one row of the projection), then project only the points in front: a
    # forward camera sees about half of a 360° sweep.
    r = mat[2]
    depth_all = (
        r[0] * points_base[:, 0] + r[1] * points_base[:, 1] + r[2] * points_base[:, 2] + r[3]
    )
    front = points_base[depth_all > 0.5]
    homog = transform_xyz(mat, front)
    depth = homog[:, 2]
    h, w = image.shape[:2]
    cols = np.round(homog[:, 0] / depth).astype(np.intp)
    rows = np.round(homog[:, 1] / depth).astype(np.intp)
    inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
    cols, rows, depth = cols[inside], rows[inside], depth[inside]
    # Far points first, so near ones win where they overlap.
    order = np.argsort(-depth)
    cols, rows, depth = cols[order], rows[order], depth[order]
    rgb = (_colormap(depth, 0.0, max_depth_m)[:, :3] * 255).astype(np.uint8)
    for dr in range(-radius_px + 1, radius_px + 1):
        for dc in range(-radius_px + 1, radius_px + 1):
            r = np.clip(rows + dr, 0, h - 1)
            c = np.clip(cols + dc, 0, w - 1)
            image[r, c] = rgb
    return len(cols)


def rasterize_top_down(
    xyz: npt.NDArray[np.float32],
    mode: ColorMode,
    spec: RasterSpec,
    *,
    intensity: npt.NDArray[Any] | None = None,
) -> npt.NDArray[np.uint8]:
    """A (S, S, 3) image of the points seen from above: row 0 is +x (ahead) far edge, column 0
    is +y (left) — so x points up the screen and y left, as a driver sees the road.  Each cell
    is coloured by its highest point (height), its distance from base_link, or its brightest
    return (intensity); empty cells are dark grey.  One pass over the points (a max-scatter, no
    sort)."""
    size = spec.size_px
    out = np.full((size, size, 3), 24, dtype=np.uint8)
    # A 10 m grid in the empty cells (cheaper than the plot's own grid, drawn every repaint).
    lines = np.flatnonzero(
        np.isclose(np.mod((np.arange(size) + 0.5) * spec.cell_m, 10.0), 0.0, atol=spec.cell_m / 2)
    )
    out[lines, :] = 44
    out[:, lines] = 44
    if len(xyz) == 0:
        return out
    rows = ((spec.half_extent_m - xyz[:, 0]) / spec.cell_m).astype(np.intp)
    cols = ((spec.half_extent_m - xyz[:, 1]) / spec.cell_m).astype(np.intp)
    ok = (rows >= 0) & (rows < size) & (cols >= 0) & (cols < size)
    cell = rows[ok] * size + cols[ok]
    use_intensity = mode is ColorMode.INTENSITY and intensity is not None and len(intensity)
    if mode is not ColorMode.HEIGHT and not use_intensity:
        # By distance (also intensity without an intensity channel): a cell's colour is its own.
        out.reshape(-1, 3)[cell] = _distance_lut(spec)[cell]
        return out
    value = np.asarray(intensity, dtype=np.float32)[ok] if use_intensity else xyz[ok, 2]
    best = np.full(size * size, -np.inf, dtype=np.float32)
    np.maximum.at(best, cell, value)
    filled = np.flatnonzero(np.isfinite(best))
    if mode is ColorMode.HEIGHT:
        rgb = _colormap(best[filled], -2.0, 3.0)
    else:
        lo, hi = np.percentile(best[filled], [1, 99])
        rgb = _colormap(best[filled], float(lo), float(hi))
    out.reshape(-1, 3)[filled] = (rgb[:, :3] * 255).astype(np.uint8)
    return out


@functools.lru_cache(maxsize=4)
def _distance_lut(spec: RasterSpec) -> npt.NDArray[np.uint8]:
    """(S·S, 3) uint8: each raster cell's colour by its centre's distance from base_link."""
    size = spec.size_px
    centre = spec.half_extent_m - (np.arange(size) + 0.5) * spec.cell_m
    dist = np.hypot(centre[:, None], centre[None, :]).reshape(-1)
    lut: npt.NDArray[np.uint8] = (_colormap(dist, 0.0, 60.0)[:, :3] * 255).astype(np.uint8)
    lut.setflags(write=False)
    return lut


def path_points(path: PlannedPath | None) -> Float | None:
    """(K, 3) x, y, z of a planned path's waypoints, or None."""
    if path is None or len(path.waypoints) == 0:
        return None
    return np.asarray(path.waypoints[:, :3], dtype=np.float64)
