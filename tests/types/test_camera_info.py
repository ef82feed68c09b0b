"""CameraInfo: shapes and dtypes checked, arrays frozen, the projection it gives."""

from __future__ import annotations

import dataclasses
import pickle
from typing import Any

import numpy as np
import pytest

from redrive.types import CameraInfo

K = np.array([[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]])


def test_defaults_and_frozen_arrays() -> None:
    k = K.copy()
    info = CameraInfo(width=640, height=480, k=k)
    assert (info.width, info.height, info.distortion_model) == (640, 480, "plumb_bob")
    assert info.d.shape == (0,)
    np.testing.assert_array_equal(info.r, np.eye(3))
    np.testing.assert_array_equal(info.p, np.zeros((3, 4)))
    for name in ("k", "d", "r", "p"):
        arr = getattr(info, name)
        assert arr.dtype == np.float64
        assert not arr.flags.writeable
    assert k.flags.writeable  # the caller's array stays theirs
    with pytest.raises(dataclasses.FrozenInstanceError):
        info.width = 1  # type: ignore[misc]
    back = pickle.loads(pickle.dumps(info))
    np.testing.assert_array_equal(back.k, K)
    assert not back.k.flags.writeable


def test_lists_and_integer_arrays_become_float64() -> None:
    info = CameraInfo(
        width=4,
        height=3,
        k=np.array([[2, 0, 1], [0, 2, 1], [0, 0, 1]], dtype=np.int32),
        d=[0.1, 0.0, 0.0, 0.0, 0.0],
        p=[[2, 0, 1, 0], [0, 2, 1, 0], [0, 0, 1, 0]],
    )
    assert info.k.dtype == info.d.dtype == info.p.dtype == np.float64
    assert info.d.shape == (5,)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"k": np.eye(4)}, r"CameraInfo\.k: shape \(4, 4\) does not match \(3, 3\)"),
        ({"k": np.zeros(9)}, r"CameraInfo\.k: shape \(9,\)"),
        ({"d": np.zeros((5, 1))}, r"CameraInfo\.d: shape \(5, 1\) does not match \(N\)"),
        ({"r": np.eye(4)}, r"CameraInfo\.r: shape"),
        ({"p": np.zeros((3, 3))}, r"CameraInfo\.p: shape \(3, 3\) does not match \(3, 4\)"),
        ({"width": -1}, "width must be a non-negative int"),
        ({"height": 2.5}, "height must be a non-negative int"),
        ({"width": True}, "width must be a non-negative int"),
    ],
)
def test_bad_fields_are_refused(changes: dict[str, Any], match: str) -> None:
    fields: dict[str, Any] = {"width": 640, "height": 480, "k": K, **changes}
    with pytest.raises(ValueError, match=match):
        CameraInfo(**fields)


def test_image_from_optical_prefers_p_then_k() -> None:
    no_p = CameraInfo(width=640, height=480, k=K)
    np.testing.assert_array_equal(no_p.image_from_optical(), np.hstack([K, np.zeros((3, 1))]))
    p = np.array([[480.0, 0.0, 300.0, -24.0], [0.0, 480.0, 230.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    with_p = CameraInfo(width=640, height=480, k=K, p=p)
    got = with_p.image_from_optical()
    np.testing.assert_array_equal(got, p)
    assert got.flags.writeable  # a copy the caller may change
    # a point 10 m ahead, 1 m right, 0.5 m down lands at fx·x/z + cx, fy·y/z + cy (+ Tx/z)
    uvw = got @ np.array([1.0, 0.5, 10.0, 1.0])
    np.testing.assert_allclose(uvw[:2] / uvw[2], [300.0 + 48.0 - 2.4, 230.0 + 24.0])


def test_uncalibrated_camera_has_no_projection() -> None:
    info = CameraInfo(width=0, height=0, k=np.zeros((3, 3)))
    assert not info.is_calibrated
    with pytest.raises(ValueError, match="not calibrated"):
        info.image_from_optical()
    assert CameraInfo(width=640, height=480, k=K).is_calibrated
