"""The box mesh handed to Embree: indexed corners, the same triangles and hits as 36 corners a box."""

from __future__ import annotations

import numpy as np
import pytest
from embreex import mesh_construction, rtcore_scene

from redrive.sim.mesh import (
    TRIANGLES_PER_BOX,
    BoxMesh,
    box_triangle_indices,
    box_triangles,
    box_vertices,
)
from redrive.types import ObjectClass, ObjectColumns


def _boxes(n: int, rng: np.random.Generator) -> ObjectColumns:
    """N random, often overlapping boxes around a point a few km from the map origin."""
    centers = np.c_[rng.uniform(-40, 40, (n, 2)), rng.uniform(0.3, 3.0, n)] + [3120.7, -845.3, 0]
    return ObjectColumns.of(
        object_id=np.arange(n, dtype=np.int64),
        object_class=(ObjectClass.STATIC,) * n,
        center_m=centers,
        size_m=rng.uniform(0.2, 12.0, (n, 3)),
        yaw_rad=rng.uniform(-np.pi, np.pi, n),
    )


def test_index_rows_rebuild_the_flat_triangles() -> None:
    rng = np.random.default_rng(3)
    objs = _boxes(150, rng)  # more than the first cache holds: it grows
    origin = np.array([3100.0, -850.0, 0.0])
    rows = box_triangle_indices(len(objs))
    assert rows.shape == (150 * TRIANGLES_PER_BOX,)
    idx = np.array(rows.tolist(), dtype=np.int64)
    corners = (box_vertices(objs.center_m, objs.size_m, objs.yaw_rad) - origin).reshape(-1, 3)
    flat = box_triangles(objs.center_m, objs.size_m, objs.yaw_rad, origin=origin)
    np.testing.assert_array_equal(corners.astype(np.float32)[idx], flat)
    assert len(box_triangle_indices(2)) == 2 * TRIANGLES_PER_BOX  # a prefix of the cache


def test_indexed_mesh_casts_as_the_flat_one_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    objs = _boxes(120, rng)
    origin = np.array([3118.0, -841.0, 1.7])
    mesh = BoxMesh.from_objects(objs, origin=origin)
    flat = rtcore_scene.EmbreeScene()
    tris = box_triangles(objs.center_m, objs.size_m, objs.yaw_rad, origin=origin)
    mesh_construction.TriangleMesh(flat, tris)
    n = 20_000
    dirs = rng.normal(size=(n, 3))
    dirs = (dirs / np.linalg.norm(dirs, axis=1)[:, None]).astype(np.float32)
    origins = rng.uniform(-3.0, 3.0, (n, 3)).astype(np.float32)
    limit = np.full(n, 120.0, dtype=np.float32)
    dist, prim, normal = mesh.cast(origins, dirs, limit.copy())
    ref = flat.run(origins, dirs, dists=limit.copy(), output=1)
    hit = prim >= 0
    assert 0.3 < hit.mean() < 1.0  # the rays meet boxes and miss them
    np.testing.assert_array_equal(prim, ref["primID"])
    np.testing.assert_array_equal(dist, ref["tfar"])
    np.testing.assert_array_equal(normal[hit], ref["Ng"][hit])


def test_an_embreex_with_typed_indices_gets_an_integer_array(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rng = np.random.default_rng(5)
    objs = _boxes(30, rng)
    origin = np.array([3118.0, -841.0, 0.0])
    real = mesh_construction.TriangleMesh
    seen: list[np.dtype] = []

    def typed(scene: object, vertices: np.ndarray, indices: np.ndarray) -> object:
        seen.append(indices.dtype)
        if indices.dtype == object:
            msg = "Buffer dtype mismatch, expected 'uint32_t' but got Python object"
            raise ValueError(msg)
        return real(scene, vertices, indices)

    monkeypatch.setattr("redrive.sim.mesh.mesh_construction.TriangleMesh", typed)
    mesh = BoxMesh.from_objects(objs, origin=origin)
    assert seen == [np.dtype(object), np.dtype(np.uint32)]
    monkeypatch.undo()
    ref = BoxMesh.from_objects(objs, origin=origin)
    n = 5_000
    dirs = rng.normal(size=(n, 3))
    dirs = (dirs / np.linalg.norm(dirs, axis=1)[:, None]).astype(np.float32)
    origins = rng.uniform(-3.0, 3.0, (n, 3)).astype(np.float32)
    got = mesh.cast(origins, dirs, np.full(n, 120.0, np.float32))
    want = ref.cast(origins, dirs, np.full(n, 120.0, np.float32))
    assert (got[1] >= 0).any()
    for a, b in zip(got[:2], want[:2], strict=True):
        np.testing.assert_array_equal(a, b)
