"""Triangles of the scene's boxes and an Embree scene to cast rays against them.

Every box becomes 12 triangles (two per face), built for all boxes at once; triangle ``k``
belongs to box ``k // 12``.  The ground plane z = 0 is not meshed: sensors intersect it
analytically (exact, and it bounds every downward ray before Embree sees it).

Embree gets each box's 8 corners once and the triangles as indices into them (its indexed
triangle mesh): the same triangles, vertex for vertex, as 36 corners a box, hence the same hits,
for a third of the vertices embreex copies one element at a time.  The index rows are handed over
as a cached object array of tuples — embreex reads them as ``indices[i][k]`` on an untyped
array, and a tuple answers that without a numpy view a row — and the corners as float64, which
embreex casts to float32 as numpy would (round to nearest).  Every scene shares one Embree device.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from embreex import mesh_construction, rtcore, rtcore_scene

from redrive.geometry.boxes import BOX_CORNER_SIGNS
from redrive.types import ObjectColumns

__all__ = [
    "TRIANGLES_PER_BOX",
    "BoxMesh",
    "box_triangle_indices",
    "box_triangles",
    "box_vertices",
]

TRIANGLES_PER_BOX = 12

# Two triangles per face, counter-clockwise seen from outside (normals point out).
_FACES = np.array(
    [
        [0, 3, 2], [0, 2, 1],  # bottom (−z)
        [4, 5, 6], [4, 6, 7],  # top (+z)
        [0, 4, 7], [0, 7, 3],  # front (+x)
        [1, 2, 6], [1, 6, 5],  # rear (−x)
        [0, 1, 5], [0, 5, 4],  # left (+y)
        [3, 7, 6], [3, 6, 2],  # right (−y)
    ],
    dtype=np.int64,
)  # fmt: skip


_cache_lock = threading.Lock()
_device: rtcore.EmbreeDevice | None = None
_index_rows: npt.NDArray[np.object_] = np.empty(0, dtype=object)


def _embree_device() -> rtcore.EmbreeDevice:
    """The Embree device every :class:`BoxMesh` is built on (made on first use)."""
    global _device  # noqa: PLW0603 -- one device for the process, made lazily
    with _cache_lock:
        if _device is None:
            _device = rtcore.EmbreeDevice()
        return _device


def box_triangle_indices(num_boxes: int) -> npt.NDArray[np.object_]:
    """(num_boxes·12,) object array: triangle ``k``'s three corner indices as a tuple of ints.

    Corner ``j`` of box ``b`` is vertex ``8·b + j`` of :func:`box_vertices` flattened; the rows
    are those of :func:`box_triangles`, in its order.  Cached (and grown on demand): a view of
    the first ``num_boxes`` boxes' rows is returned, never to be written.
    """
    global _index_rows  # noqa: PLW0603 -- grown in place of a per-call build
    need = num_boxes * TRIANGLES_PER_BOX
    with _cache_lock:
        if len(_index_rows) < need:
            size = max(need, 2 * len(_index_rows), 64 * TRIANGLES_PER_BOX)
            rows = _FACES[None, :, :] + 8 * np.arange(size // TRIANGLES_PER_BOX)[:, None, None]
            grown = np.empty(size, dtype=object)
            grown[:] = [tuple(r) for r in rows.reshape(-1, 3).tolist()]
            _index_rows = grown
        return _index_rows[:need]


def box_vertices(
    centers: npt.NDArray[np.float64],
    sizes: npt.NDArray[np.float64],
    yaws_rad: npt.NDArray[np.float64],
) -> npt.NDArray[np.float64]:
    """(N, 8, 3) float64 corners of N boxes (order of :func:`redrive.geometry.box_corners`)."""
    local = BOX_CORNER_SIGNS[None, :, :] * (0.5 * sizes)[:, None, :]
    c, s = np.cos(yaws_rad)[:, None], np.sin(yaws_rad)[:, None]
    out = np.empty_like(local)
    out[..., 0] = c * local[..., 0] - s * local[..., 1] + centers[:, None, 0]
    out[..., 1] = s * local[..., 0] + c * local[..., 1] + centers[:, None, 1]
    out[..., 2] = local[..., 2] + centers[:, None, 2]
    return out


def box_triangles(
    centers: npt.NDArray[np.float64],
    sizes: npt.NDArray[np.float64],
    yaws_rad: npt.NDArray[np.float64],
    *,
    origin: npt.NDArray[np.float64] | None = None,
) -> npt.NDArray[np.float32]:
    """(N·12, 3, 3) float32 triangles of N boxes, relative to ``origin`` (3,) when given.

    Subtracting a nearby origin before the float32 cast keeps map coordinates of several km
    exact to the millimetre.
    """
    verts = box_vertices(centers, sizes, yaws_rad)
    if origin is not None:
        verts = verts - origin
    tris = verts[:, _FACES, :].reshape(-1, 3, 3)
    return np.ascontiguousarray(tris, dtype=np.float32)


@dataclass(frozen=True, slots=True)
class BoxMesh:
    """An Embree scene of boxes, in a frame shifted by ``origin`` (map = local + origin).

    Attributes:
        scene: the committed Embree scene (None when there are no boxes: every ray misses).
        origin: (3,) float64 map coordinates of the local origin.
        num_boxes: boxes in the scene; primitive ``k`` is box ``k // 12``.
    """

    scene: rtcore_scene.EmbreeScene | None
    origin: npt.NDArray[np.float64]
    num_boxes: int

    @classmethod
    def from_objects(
        cls, objects: ObjectColumns, *, origin: npt.NDArray[np.float64] | None = None
    ) -> BoxMesh:
        """Every box of ``objects`` (:meth:`from_boxes`)."""
        return cls.from_boxes(objects.center_m, objects.size_m, objects.yaw_rad, origin=origin)

    @classmethod
    def from_boxes(
        cls,
        centers: npt.NDArray[np.float64],
        sizes: npt.NDArray[np.float64],
        yaws_rad: npt.NDArray[np.float64],
        *,
        origin: npt.NDArray[np.float64] | None = None,
    ) -> BoxMesh:
        """Build from N boxes' (N, 3) centres, (N, 3) sizes and (N,) yaws (≈ 1–2 ms for 100
        boxes, with Embree's BVH build on the first cast: rebuild it every sweep).

        The triangles are :func:`box_triangles`'s: corners relative to ``origin`` rounded to
        float32, triangle ``k`` of box ``k // 12``.
        """
        org = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
        n = len(centers)
        if n == 0:
            return cls(None, org, 0)
        corners = (box_vertices(centers, sizes, yaws_rad) - org).reshape(-1, 3)
        scene = rtcore_scene.EmbreeScene(_embree_device())
        try:
            mesh_construction.TriangleMesh(scene, corners, box_triangle_indices(n))
        except (TypeError, ValueError):  # an embreex whose indices are a typed buffer
            scene = rtcore_scene.EmbreeScene(_embree_device())
            rows = np.asarray(box_triangle_indices(n).tolist(), dtype=np.uint32)
            mesh_construction.TriangleMesh(scene, corners.astype(np.float32), rows)
        return cls(scene, org, n)

    def cast(
        self,
        origins: npt.NDArray[np.float32],
        directions: npt.NDArray[np.float32],
        tfar: npt.NDArray[np.float32],
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.int32], npt.NDArray[np.float32]]:
        """Embree's answers as they come (local frame; directions unit length), without per-ray
        post-processing.

        ``tfar`` (R,) float32 holds each ray's limit and is overwritten.  Returns ``(tfar,
        primitive, normal)``: (R,) float32 distance (the limit where nothing was hit before it),
        (R,) int32 primitive index (box ``k // 12``) or −1, (R, 3) float32 geometric normal (not
        normalised, arbitrary sign; zeros where nothing can be hit, undefined on other misses).
        """
        n = origins.shape[0]
        if self.scene is None or n == 0:
            return tfar, np.full(n, -1, np.int32), np.zeros((n, 3), np.float32)
        res = self.scene.run(origins, directions, dists=tfar, output=1)
        prim: npt.NDArray[np.int32] = res["primID"]
        return res["tfar"], prim, res["Ng"]
