"""What a log holds beside its messages, asked of the reader: a road map, the scenario it was
synthesized from, a count of its contents (annotated sweeps, tracks, lanes …), and the
fingerprint (sha256 and size) of its files.

A reader that can give a road map says so in its capabilities (``ReaderCapabilities.road_map``)
and has a ``road_map()`` method (:class:`RoadMapSource`); likewise ``scenario`` and
:class:`ScenarioSource`.  Callers (the engine, closed loop) use :func:`log_road_map` and
:func:`log_scenario`, which ask the capability, never the format name or ``getattr``.

>>> from redrive.io import open_log
>>> with open_log("cut_in.mcap") as log:                  # doctest: +SKIP
...     road_map = log_road_map(log)                      # None for a log without one
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

from redrive.errors import LogError
from redrive.io.base import LogReader
from redrive.types import RoadMap

__all__ = [
    "ContentsSource",
    "GoalSource",
    "LogFingerprint",
    "LogScenario",
    "RoadMapSource",
    "ScenarioSource",
    "fingerprint_log",
    "log_contents",
    "log_goal_lanes",
    "log_road_map",
    "log_scenario",
]


@dataclass(frozen=True, slots=True, kw_only=True)
class LogScenario:
    """What a ``redrive synth`` log was synthesized from: scenario name, seed and duration (s)."""

    name: str
    seed: int
    duration_s: float


@runtime_checkable
class RoadMapSource(Protocol):
    """A reader whose capabilities say ``road_map``."""

    def road_map(self) -> RoadMap | None:
        """The log's road map; None when this log holds none (or it is unreadable)."""
        ...


@runtime_checkable
class ScenarioSource(Protocol):
    """A reader whose capabilities say ``scenario``."""

    def scenario(self) -> LogScenario | None:
        """What the log was synthesized from; None when it does not say (or it is unreadable)."""
        ...


@runtime_checkable
class ContentsSource(Protocol):
    """A reader whose capabilities say ``contents``."""

    def contents(self) -> Mapping[str, int | str]:
        """What the log holds, counted, in words: ``{"annotated sweeps": 156, "tracks": 114}``
        (insertion order is the order ``redrive info`` prints)."""
        ...


@runtime_checkable
class GoalSource(Protocol):
    """A reader whose capabilities say ``goal``."""

    def goal_lane_ids(self) -> tuple[str, ...]:
        """The lanes (ids of the log's road map) the ego is to reach; () when the goal names
        none (a goal in time only, or a position on no lane)."""
        ...


def log_goal_lanes(log: LogReader) -> tuple[str, ...]:
    """The lanes of ``log``'s goal when its reader sets one (capability ``goal``), else ().

    Raises:
        LogError: the reader declares the capability without the method.
    """
    if not log.capabilities.goal:
        return ()
    _declared(log, GoalSource, "goal_lane_ids")
    return tuple(log.goal_lane_ids())  # type: ignore[attr-defined]


def _declared(log: LogReader, protocol: type, method: str) -> None:
    if not isinstance(log, protocol):
        msg = (
            f"{log.path}: the {log.format} reader {type(log).__qualname__} declares the "
            f"{method} capability but has no {method}() method; add it or drop the capability"
        )
        raise LogError(msg)


def log_road_map(log: LogReader) -> RoadMap | None:
    """The road map of ``log`` when its reader can give one (capability ``road_map``), else None.

    Raises:
        LogError: the reader declares the capability without the method.
    """
    if not log.capabilities.road_map:
        return None
    _declared(log, RoadMapSource, "road_map")
    return log.road_map()  # type: ignore[attr-defined, no-any-return]


def log_scenario(log: LogReader) -> LogScenario | None:
    """What ``log`` was synthesized from when its reader says (capability ``scenario``), else
    None.

    Raises:
        LogError: the reader declares the capability without the method.
    """
    if not log.capabilities.scenario:
        return None
    _declared(log, ScenarioSource, "scenario")
    return log.scenario()  # type: ignore[attr-defined, no-any-return]


def log_contents(log: LogReader) -> dict[str, int | str]:
    """What ``log`` holds, counted, when its reader says (capability ``contents``), else ``{}``.

    Raises:
        LogError: the reader declares the capability without the method.
    """
    if not log.capabilities.contents:
        return {}
    _declared(log, ContentsSource, "contents")
    return dict(log.contents())  # type: ignore[attr-defined]


@dataclass(frozen=True, slots=True, kw_only=True)
class LogFingerprint:
    """The bytes of a log: ``path`` (absolute), ``sha256`` and ``size_bytes`` of its files."""

    path: str
    sha256: str
    size_bytes: int


def fingerprint_log(path: Path) -> LogFingerprint:
    """Path, size and sha256 of a log file, of every file of a log directory (in name order,
    each name hashed before its bytes), or of the split files a glob names."""
    from redrive.io.mcap.fileset import expand_log_set

    digest = hashlib.sha256()
    if path.is_file():
        files = [path]
    elif path.is_dir():
        files = sorted(p for p in path.rglob("*") if p.is_file())
    else:  # a glob of split files
        files = expand_log_set(path)
    size = 0
    for file in files:
        if file is not path:
            name = file.relative_to(path) if path.is_dir() else Path(file.name)
            digest.update(name.as_posix().encode() + b"\0")
        with file.open("rb") as fh:
            hashlib.file_digest(fh, lambda: digest)  # feeds the whole file into `digest`
        size += file.stat().st_size
    return LogFingerprint(
        path=str(path.absolute() if files and not path.exists() else path.resolve()),
        sha256=digest.hexdigest(),
        size_bytes=size,
    )
