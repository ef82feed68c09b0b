"""The metadata records redrive writes into an MCAP log, and reads back as reader capabilities.

A ``redrive synth`` log carries the scenario's road map (record :data:`MAP_METADATA`, key
``road_map``: the JSON document of :mod:`redrive.maps.document`) and what it was synthesized from
(record :data:`SCENARIO_METADATA`: ``name``, ``seed``, ``duration_s`` as text).  The MCAP reader
answers :meth:`~redrive.io.content.RoadMapSource.road_map` and
:meth:`~redrive.io.content.ScenarioSource.scenario` from them.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from pathlib import Path

from redrive.errors import ConfigError
from redrive.io.content import LogScenario
from redrive.maps.document import road_map_from_json, road_map_to_json
from redrive.types import RoadMap

__all__ = [
    "MAP_METADATA",
    "SCENARIO_METADATA",
    "road_map_in",
    "road_map_record",
    "scenario_in",
    "scenario_record",
]

logger = logging.getLogger(__name__)

#: the metadata record holding a log's road map (key ``road_map``: its JSON document)
MAP_METADATA = "redrive.road_map"
#: the metadata record saying what a ``redrive synth`` log was synthesized from
SCENARIO_METADATA = "redrive.scenario"


def road_map_record(road_map: RoadMap) -> dict[str, str]:
    """The :data:`MAP_METADATA` record of ``road_map``."""
    return {"road_map": json.dumps(road_map_to_json(road_map), separators=(",", ":"))}


def scenario_record(scenario: LogScenario) -> dict[str, str]:
    """The :data:`SCENARIO_METADATA` record: ``name``, ``seed``, ``duration_s`` as text (``repr``
    of the float, so it reads back equal)."""
    return {
        "name": scenario.name,
        "seed": str(scenario.seed),
        "duration_s": repr(float(scenario.duration_s)),
    }


def road_map_in(record: Mapping[str, str] | None, *, path: Path) -> RoadMap | None:
    """The road map of a :data:`MAP_METADATA` record; None without one, or (with a warning) when
    it is unreadable."""
    if not record or "road_map" not in record:
        return None
    try:
        return road_map_from_json(
            json.loads(record["road_map"]), path=path, advice="synthesize the log again"
        )
    except (ValueError, ConfigError) as err:
        logger.warning("%s: its road map is unreadable, the run has none (%s)", path, err)
        return None


def scenario_in(record: Mapping[str, str] | None, *, path: Path) -> LogScenario | None:
    """The scenario of a :data:`SCENARIO_METADATA` record; None without one, or (with a
    warning) when it is unreadable."""
    if not record:
        return None
    try:
        return LogScenario(
            name=str(record["name"]),
            seed=int(record["seed"]),
            duration_s=float(record["duration_s"]),
        )
    except (KeyError, ValueError) as err:
        logger.warning("%s: its scenario record is unreadable, the run has none (%s)", path, err)
        return None
