"""``RUN/map.json``: the road map of a run (:class:`~redrive.types.RoadMap`), versioned.

Written atomically (temp file + rename) by :meth:`RunWriter.write_map
<redrive.results.RunWriter.write_map>` or :func:`write_road_map`; read and validated by
:meth:`Run.road_map <redrive.results.Run.road_map>`.  A run without the file has no map (logs
and recorded logs: the closed-loop map metrics are skipped); runs of a synthetic scenario, closed loop or a replay of its `redrive synth` log, store one.

The document is :mod:`redrive.maps.document`'s (schema 1).
"""

from __future__ import annotations

import json
from pathlib import Path

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
    """
    folder = Path(run_dir)
    if not (folder / MANIFEST_NAME).is_file():
        msg = (
            f"{folder}: not a redrive run (no {MANIFEST_NAME}); write the map into a run directory"
        )
        raise ConfigError(msg)
    path = folder / MAP_NAME
    # compact, not indented: a map is mostly coordinates, and json's C encoder (used only
    # without indent) writes them in a third of the CPU, half the bytes (a WOMD scenario's map:
    # 0.49 MB, 21 ms instead of 0.94 MB, 65 ms)
    text = json.dumps(road_map_to_json(road_map), separators=(",", ":"), allow_nan=False)
    write_files([(path, (text + "\n").encode("utf-8"))])
    return path


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
