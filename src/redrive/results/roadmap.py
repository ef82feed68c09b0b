"""``RUN/map.json``: the road map of a run (:class:`~redrive.types.RoadMap`), versioned.

Written atomically (temp file + rename) by :meth:`RunWriter.write_map
<redrive.results.RunWriter.write_map>` or :func:`write_road_map`; read and validated by
:meth:`Run.road_map <redrive.results.Run.road_map>`.  A run without the file has no map (logs
and recorded logs: the closed-loop map metrics are skipped); runs of a synthetic scenario, closed loop or a replay of its `redrive synth` log, store one.

The document is :mod:`redrive.maps.document`'s (schema 1).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import orjson

from redrive.errors import ConfigError
from redrive.maps.document import road_map_from_json, road_map_to_json
from redrive.results._files import write_files
from redrive.results.manifest import MANIFEST_NAME
from redrive.types import RoadMap

__all__ = ["MAP_NAME", "read_road_map", "write_road_map"]

MAP_NAME = "map.json"
_ADVICE = "write it again with RunWriter.write_map / redrive.results.write_road_map"


def write_road_map(run_dir: str | Path, road_map: RoadMap) -> Path:
    """Write ``RUN/map.json`` atomically (replacing an earlier map); returns its path.

    Raises:
        ConfigError: ``run_dir`` is not a run directory.
        ValueError: a number of the map is not finite (JSON has none).
    """
    folder = Path(run_dir)
    if not (folder / MANIFEST_NAME).is_file():
        msg = (
            f"{folder}: not a redrive run (no {MANIFEST_NAME}); write the map into a run directory"
        )
        raise ConfigError(msg)
    path = folder / MAP_NAME
    # compact: a map is mostly coordinates; orjson writes each double as its shortest
    # round-trip text (ryu; json.loads reads back the same doubles as from json.dumps's repr)
    # straight from the map's arrays, ~30x fewer instructions than json's C encoder (whose
    # float repr is ~7k instructions a number: a WOMD scenario's 20.8k of them 0.14 G).  orjson
    # writes NaN and infinities as null: they are refused first, as json's allow_nan=False did
    document = road_map_to_json(road_map, arrays=True)
    _check_finite(document)
    text = orjson.dumps(document, option=orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_APPEND_NEWLINE)
    write_files([(path, text)])
    return path


def _check_finite(document: Any) -> None:
    """Raise ValueError (json.dumps's with ``allow_nan=False``) if a float of ``document`` (of
    dicts, lists, numbers, strings and float arrays) is NaN or infinite: its floats and arrays
    gathered in one pass and tested at once; :func:`_named_not_finite` names the first bad one."""
    floats: list[float] = []
    arrays: list[npt.NDArray[Any]] = []
    stack = [document]
    while stack:
        value = stack.pop()
        kind = type(value)
        if kind is str or value is None:
            continue
        if kind is dict:
            stack.extend(value.values())
        elif kind is list:
            stack.extend(value)
        elif kind is float:
            floats.append(value)
        elif kind is np.ndarray:
            arrays.append(value.ravel())
        elif kind is not int and isinstance(value, dict | list | float | np.ndarray):
            # a subclass (np.float64 …): the slow walk
            _named_not_finite(document)
            return
    finite = all(map(math.isfinite, floats)) and (
        not arrays or bool(np.isfinite(np.concatenate(arrays)).all())
    )
    if not finite:
        _named_not_finite(document)


def _named_not_finite(value: Any) -> None:
    """:func:`_check_finite` one value at a time, in document order: the error names the first
    float or array that is not finite."""
    if isinstance(value, float):
        bad = not math.isfinite(value)
    elif isinstance(value, np.ndarray):
        bad = not bool(np.isfinite(value).all())
    elif isinstance(value, dict):
        for item in value.values():
            _named_not_finite(item)
        return
    elif isinstance(value, list):
        for item in value:
            _named_not_finite(item)
        return
    else:
        return
    if bad:
        msg = f"Out of range float values are not JSON compliant: {value!r}"
        raise ValueError(msg)


def read_road_map(run_dir: str | Path) -> RoadMap | None:
    """The road map of a run, None when it has none.

    Raises:
        ConfigError: ``map.json`` exists but cannot be read or is not a valid map.
    """
    path = Path(run_dir) / MAP_NAME
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        msg = f"{path}: document: cannot be read as JSON ({err}); {_ADVICE}"
        raise ConfigError(msg) from err
    return road_map_from_json(data, path=path, advice=_ADVICE)
