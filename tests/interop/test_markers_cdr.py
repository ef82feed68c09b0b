"""The MarkerArray's CDR written directly is the bytes rosbags serialises from the message."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from redrive.interop.markers import MARKER_ARRAY, marker_array, marker_array_cdr
from redrive.interop.shapes import BoxShape, LabelShape, LineShape, ShapeSet
from redrive.io.ros.typestore import typestore_for

_BOXES = (
    BoxShape(
        id="a",
        center=(1.0, -2.0, np.float64(0.5)),  # type: ignore[arg-type]  # numpy floats as rows give
        size=(4.5, 1.9, 1.6),
        yaw_rad=0.3,
        color=(0.2, 0.55, 1.0, 0.45),
        velocity=(3.0, 1.0, 0.1),
    ),
    BoxShape(
        id="b",
        center=(7.0, 2.0, 0.5),
        size=(0.8, 0.8, 1.8),
        yaw_rad=-2.0,
        color=(1.0, 0.6, 0.1, 0.55),
        velocity=(0.01, 0.0, 0.0),  # too slow for an arrow
    ),
)
_LINES = (
    LineShape(
        id="l", points=((0.0, 0.0, 0.0), (1.0, 1.5, 0.0), (2.0, 3.0, 0.1)), color=(1, 0, 0, 1)
    ),
)
_LABELS = (
    LabelShape(id="t", position=(1.0, 2.0, 3.0), text="car #12 0.93 — é"),
    LabelShape(id="u", position=(1.0, 2.0, 3.0), text="", size_m=1.5),
)


@pytest.fixture(scope="module")
def store() -> Any:
    return typestore_for(2)[0]


@pytest.mark.parametrize("frame_id", ["base_link", "map", "m", ""])
@pytest.mark.parametrize(
    "parts",
    [
        {},
        {"boxes": _BOXES},
        {"lines": _LINES},
        {"labels": _LABELS},
        {"boxes": _BOXES, "lines": _LINES, "labels": _LABELS},
        {"labels": _LABELS[:1], "lines": _LINES, "boxes": _BOXES[1:]},
    ],
)
def test_cdr_equals_rosbags_serialisation(
    store: Any, frame_id: str, parts: dict[str, tuple[object, ...]]
) -> None:
    shapes = ShapeSet(stamp_ns=1_700_000_000_123_456_789, frame_id=frame_id, **parts)  # type: ignore[arg-type]
    expected = bytes(store.serialize_cdr(marker_array(shapes, store), MARKER_ARRAY))
    assert marker_array_cdr(shapes) == expected
    assert store.deserialize_cdr(marker_array_cdr(shapes), MARKER_ARRAY).markers[0].action == 3
