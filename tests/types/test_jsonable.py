"""to_jsonable: the one conversion of configs, defaults and summaries to JSON."""

from __future__ import annotations

import json

import numpy as np

from redrive.engine.graph import config_hash
from redrive.types import Role, SensorType, to_jsonable


def test_enums_numpy_and_containers() -> None:
    value = {
        "mode": Role.PLANNING,
        "sensor": SensorType.LIDAR,
        "gain": np.float64(3.0),
        "count": np.int32(4),
        "matrix": np.eye(2),
        "sizes": (1, 2),
        "tags": frozenset({"b", "a"}),
        3: None,
        "nested": [{"flag": True}],
    }
    out = to_jsonable(value)
    assert out == {
        "mode": "planning",
        "sensor": "lidar",
        "gain": 3.0,
        "count": 4,
        "matrix": [[1.0, 0.0], [0.0, 1.0]],
        "sizes": [1, 2],
        "tags": ["a", "b"],
        "3": None,
        "nested": [{"flag": True}],
    }
    assert json.loads(json.dumps(out)) == out
    assert type(out["gain"]) is float
    assert to_jsonable(object).startswith("<class")  # anything else: its repr


def test_config_hash_sees_values_not_their_python_types() -> None:
    assert config_hash({"gain": np.float64(3.0), "role": Role.PLANNING}) == config_hash(
        {"gain": 3.0, "role": "planning"}
    )
    assert config_hash({"a": 1, "b": 2}) == config_hash({"b": 2, "a": 1})
    assert config_hash({"a": 1}) != config_hash({"a": 2})
