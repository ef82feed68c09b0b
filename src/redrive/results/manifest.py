"""``manifest.json``: what a run is (log, pipeline, algorithms, seed) and how far it got.

:class:`RunManifest` is the typed, versioned model of the file.  The engine supplies a
:class:`RunSetup` (log, sensors, seed, pipeline, algorithms); the store adds the rest
(``schema_version``, ``redrive_version``, ``created``/``finished`` ISO 8601 UTC, ``status``,
``host``, ``frames_done``, ``resumes``, ``summary``, ``error``).  :func:`write_manifest` writes
atomically (temp file + ``os.replace``); :func:`read_manifest` validates every field and raises a
:class:`~redrive.errors.ConfigError` naming the file, the field, what it found and what to do.

Versions (``schema_version``):

* **2** (:data:`SCHEMA_VERSION`): every field of :class:`RunManifest` is present (optional ones
  as ``null``); ``summary`` is ``null`` until the run is closed.
* **1** (redrive before the typed manifest): the same keys, but the engine's part was free-form
  and may lack keys added over time.  Schema-1 manifests are **read**, not refused: the explicit
  :func:`upgrade_v1` fills the keys older releases did not write (``sensors``,
  ``pipeline.mode_manager`` …, ``summary`` ``{}`` → ``null``) and the result is validated as
  version 2, so a user's existing runs keep working.  A resume rewrites the file as version 2.
* no ``schema_version``, or one newer than :data:`SCHEMA_VERSION`: refused (re-run, or upgrade).

Keys a manifest holds beyond the model are ignored when reading.
"""

from __future__ import annotations

import enum
import json
import os
import platform
import socket
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

from redrive.results._fields import DAMAGED_ADVICE, Fields, manifest_error
from redrive.results._files import write_json_atomic
from redrive.types import Role, SensorType, to_jsonable

__all__ = [
    "MANIFEST_NAME",
    "SCHEMA_VERSION",
    "AlgorithmEntry",
    "HostInfo",
    "PipelineInfo",
    "ResumeRecord",
    "RunManifest",
    "RunSetup",
    "RunStatus",
    "RunSummary",
    "SourceLog",
    "StepFailure",
    "host_info",
    "now_iso",
    "read_manifest",
    "redrive_version",
    "upgrade_v1",
    "write_json_atomic",
    "write_manifest",
]

MANIFEST_NAME = "manifest.json"
#: version of the manifest format; bumped on any incompatible change.
SCHEMA_VERSION = 2

_ROLES = ", ".join(r.value for r in Role)
_SENSOR_TYPES = ", ".join(t.value for t in SensorType)


class RunStatus(enum.StrEnum):
    """Where a run is: ``running`` until the writer closes it as one of the three others."""

    RUNNING = "running"
    COMPLETE = "complete"
    INTERRUPTED = "interrupted"  # Ctrl-C or a cancel; `--resume` continues it
    FAILED = "failed"  # `error` says why

    @property
    def is_final(self) -> bool:
        return self is not RunStatus.RUNNING


_STATUSES = ", ".join(s.value for s in RunStatus)


def now_iso() -> str:
    """The current time, ISO 8601 UTC with milliseconds (``2025-01-31T12:00:00.123+00:00``)."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def redrive_version() -> str:
    try:
        return metadata.version("redrive")
    except metadata.PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True, slots=True, kw_only=True)
class HostInfo:
    """The machine a run was created on."""

    hostname: str
    platform: str
    python: str
    cpu_count: int | None

    @classmethod
    def _parse(cls, f: Fields) -> HostInfo:
        return cls(
            hostname=f.text("hostname"),
            platform=f.text("platform"),
            python=f.text("python"),
            cpu_count=f.opt_integer("cpu_count"),
        )


def host_info() -> HostInfo:
    """This machine."""
    return HostInfo(
        hostname=socket.gethostname(),
        platform=platform.platform(),
        python=sys.version.split()[0],
        cpu_count=os.cpu_count(),
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class SourceLog:
    """The log a run replayed: a file or directory (``sha256`` and ``size_bytes`` of its bytes), or
    a live session (``format`` ``live``, no hash; ``source``, ``topics`` and ``record`` set).

    ``scenario``: what a ``redrive synth`` log was synthesized from (``name``, ``seed``,
    ``duration_s``; its reader's ``scenario`` capability, :mod:`redrive.io.content`), empty for
    other logs —
    ``redrive compare`` pairs an open-loop run of the log with a closed-loop run of the scenario.
    """

    path: str
    format: str
    sha256: str | None
    size_bytes: int | None = None
    source: str | None = None
    topics: Mapping[str, str] = field(default_factory=dict)  # live: topic → message type
    record: str | None = None  # live: the MCAP the session was recorded to
    scenario: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def _parse(cls, f: Fields) -> SourceLog:
        return cls(
            path=f.text("path"),
            format=f.text("format"),
            sha256=f.opt_text("sha256"),
            size_bytes=f.opt_integer("size_bytes"),
            source=f.opt_text("source"),
            topics=f.text_map("topics"),
            record=f.opt_text("record"),
            scenario=f.mapping("scenario", {}),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class PipelineInfo:
    """How the stages ran, and over which frames ``[first_frame, stop_frame)``."""

    mode: str = "sequential"  # sequential | pipelined
    executor: str = "threads"  # threads | processes
    step_timeout_s: float | None = None
    fail_fast: bool = False
    first_frame: int | None = None
    stop_frame: int | None = None
    rate: float | None = None  # real-time factor paced at; None: as fast as possible
    stages: tuple[str, ...] = ()  # stage names in execution order
    mode_manager: str = "replay"  # the Mode Manager's mode: replay | realtime | …
    # algorithms of the pipeline left out because the log cannot feed them: name → why
    skipped: Mapping[str, str] = field(default_factory=dict)
    #: inputs the log has but no frame could get (``vehicle_state`` / ``ground_truth`` on
    #: another clock than the frames', :mod:`redrive.assembly.clocks`): input → why
    unusable_inputs: Mapping[str, str] = field(default_factory=dict)
    #: stage → the memory bound (MiB, resident) of each of its algorithms' worker processes
    max_rss_mb: Mapping[str, float] = field(default_factory=dict)

    @classmethod
    def _parse(cls, f: Fields) -> PipelineInfo:
        return cls(
            mode=f.text("mode"),
            executor=f.text("executor"),
            step_timeout_s=f.opt_number("step_timeout_s"),
            fail_fast=f.flag("fail_fast"),
            first_frame=f.opt_integer("first_frame"),
            stop_frame=f.opt_integer("stop_frame"),
            rate=f.opt_number("rate"),
            stages=f.texts("stages"),
            mode_manager=f.text("mode_manager"),
            skipped=f.text_map("skipped", {}),
            unusable_inputs=f.text_map("unusable_inputs", {}),
            max_rss_mb=f.number_map("max_rss_mb", {}),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class AlgorithmEntry:
    """One algorithm of the run, in pipeline order (JSON key ``class`` for ``class_name``)."""

    name: str
    role: Role
    version: str
    config_hash: str  # sha256 of the canonical JSON of ``config``
    stage: str = ""
    plugin: str = ""  # what the user named: entry point, ``module:Class`` or ``file.py:Class``
    class_name: str = ""  # ``module:QualName``
    source: str = ""  # the class's source file
    inputs: tuple[str, ...] = ()
    config: Mapping[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "stage": self.stage,
            "role": self.role.value,
            "plugin": self.plugin,
            "class": self.class_name,
            "source": self.source,
            "version": self.version,
            "inputs": list(self.inputs),
            "config": _plain(self.config),
            "config_hash": self.config_hash,
        }

    @classmethod
    def _parse(cls, f: Fields) -> AlgorithmEntry:
        return cls(
            name=f.text("name"),
            stage=f.text("stage"),
            role=f.enum("role", Role, _ROLES),
            plugin=f.text("plugin"),
            class_name=f.text("class"),
            source=f.text("source"),
            version=f.text("version"),
            inputs=f.texts("inputs"),
            config=f.mapping("config"),
            config_hash=f.text("config_hash"),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class RunSetup:
    """What the engine knows of a run before its first frame (all of it is in the manifest)."""

    log: SourceLog
    pipeline: PipelineInfo = field(default_factory=PipelineInfo)
    algorithms: tuple[AlgorithmEntry, ...] = ()
    seed: int | None = None
    sensors: Mapping[str, SensorType] = field(default_factory=dict)  # sensor id → its type
    #: closed loop: the simulator's description (backend, agents, ego model and limits, tracker
    #: and gains, seed); empty for a replay
    closed_loop: Mapping[str, Any] = field(default_factory=dict)
    road_map: Mapping[str, Any] = field(default_factory=dict)  # manifest `map`: engine.user_map

    def algorithm(self, name: str) -> AlgorithmEntry | None:
        """The entry of algorithm ``name``, or None."""
        return next((a for a in self.algorithms if a.name == name), None)

    def names(self, role: Role | None = None) -> list[str]:
        """The algorithms' names in pipeline order (only those of ``role`` if given)."""
        return [a.name for a in self.algorithms if role is None or a.role is role]


@dataclass(frozen=True, slots=True, kw_only=True)
class ResumeRecord:
    """One resume of the run."""

    at: str  # ISO 8601 UTC
    previous_status: RunStatus
    frames_done: int  # committed frames found on disk
    hostname: str
    removed_incomplete_files: int

    @classmethod
    def _parse(cls, f: Fields) -> ResumeRecord:
        return cls(
            at=f.text("at"),
            previous_status=f.enum("previous_status", RunStatus, _STATUSES),
            frames_done=f.integer("frames_done"),
            hostname=f.text("hostname"),
            removed_incomplete_files=f.integer("removed_incomplete_files"),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class StepFailure:
    """The step that stopped a ``fail_fast`` run."""

    frame_index: int
    algorithm: str
    status: str
    error_type: str
    error_message: str

    @classmethod
    def _parse(cls, f: Fields) -> StepFailure:
        return cls(
            frame_index=f.integer("frame_index"),
            algorithm=f.text("algorithm"),
            status=f.text("status"),
            error_type=f.text("error_type"),
            error_message=f.text("error_message"),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class RunSummary:
    """Frame counts and timing, written when the run is closed: computed from the stored tables
    (``frames``, ``late_frames``, ``algorithms``), overlaid with what the engine reports (then
    ``frames`` counts the frames of the last invocation, ``algorithms`` its per-algorithm stats)."""

    frames: int
    late_frames: int
    algorithms: tuple[Mapping[str, Any], ...] = ()  # per algorithm: counts and latencies (ms)
    wall_s: float | None = None
    frames_per_s: float | None = None
    log_span_s: float | None = None
    realtime_factor: float | None = None  # log time / wall time
    failure: StepFailure | None = None
    skipped_frames: int | None = None  # real-time mode: frames skipped (pipeline too slow)
    failed_frames: int | None = None  # frames with a failed (error/timeout) step
    #: input → frames without a sample of it within the tolerance (stale or absent there)
    missing_inputs: Mapping[str, int] = field(default_factory=dict)
    undecodable_messages: Mapping[str, int] = field(default_factory=dict)  # topic → count
    #: topic → the non-finite (NaN, ±inf) points of its clouds: clouds, points, non_finite,
    #: clouds_with_non_finite, clouds_over (over the warning fraction), max_fraction
    #: (:mod:`redrive.assembly.non_finite`); only topics with any
    non_finite_points: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    error: str | None = None  # ``Type: message`` of what ended a failed or interrupted run
    #: closed loop: the deviation thresholds, how many frames passed them (``deviated_frames``),
    #: the first such frame and the largest deviations
    closed_loop: Mapping[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["algorithms"] = [_plain(a) for a in self.algorithms]
        out["failure"] = None if self.failure is None else _asdict(self.failure)
        out["undecodable_messages"] = dict(self.undecodable_messages)
        out["non_finite_points"] = {t: dict(c) for t, c in self.non_finite_points.items()}
        out["missing_inputs"] = dict(self.missing_inputs)
        out["closed_loop"] = to_jsonable(self.closed_loop)
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any], *, path: Path) -> RunSummary:
        """Validate a summary object (``path`` names the file in errors)."""
        f = Fields(data, path=path, where="summary")
        failure = f.opt_obj("failure", None)
        return cls(
            frames=f.integer("frames"),
            late_frames=f.integer("late_frames"),
            algorithms=tuple(a.data for a in f.objs("algorithms", [])),
            wall_s=f.opt_number("wall_s", None),
            frames_per_s=f.opt_number("frames_per_s", None),
            log_span_s=f.opt_number("log_span_s", None),
            realtime_factor=f.opt_number("realtime_factor", None),
            failure=None if failure is None else StepFailure._parse(failure),
            skipped_frames=f.opt_integer("skipped_frames", None),
            failed_frames=f.opt_integer("failed_frames", None),
            missing_inputs=f.int_map("missing_inputs", {}),
            undecodable_messages=f.int_map("undecodable_messages", {}),
            non_finite_points=f.object_map("non_finite_points", {}),
            error=f.opt_text("error", None),
            closed_loop=f.mapping("closed_loop", {}),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class RunManifest(RunSetup):
    """``RUN/manifest.json``: the :class:`RunSetup` plus what the store records."""

    redrive_version: str
    created: str  # ISO 8601 UTC
    status: RunStatus
    host: HostInfo
    finished: str | None = None  # ISO 8601 UTC; None while running
    frames_done: int = 0  # committed frames, updated at every flush
    resumes: tuple[ResumeRecord, ...] = ()
    summary: RunSummary | None = None  # None until the run is closed
    error: str | None = None  # ``Type: message`` of the exception that failed the run
    schema_version: int = SCHEMA_VERSION

    @classmethod
    def start(cls, setup: RunSetup) -> RunManifest:
        """The manifest of a new run of ``setup`` on this machine, now."""
        kept = {f.name: getattr(setup, f.name) for f in fields(RunSetup)}
        return cls(
            **kept,
            redrive_version=redrive_version(),
            created=now_iso(),
            status=RunStatus.RUNNING,
            host=host_info(),
        )

    @property
    def setup(self) -> RunSetup:
        return RunSetup(**{f.name: getattr(self, f.name) for f in fields(RunSetup)})

    def partial_note(self) -> str | None:
        """What part of its log the run covers when it did not finish (None when complete):
        numbers evaluated from it hold for those frames only."""
        frames = f"the {self.frames_done} frames it stored"
        if self.status is RunStatus.COMPLETE:
            return None
        if self.status is RunStatus.INTERRUPTED:
            how = (
                "continue it (`redrive run LOG --out RUN --resume` with the run's flags) and "
                "evaluate again"
                if self.pipeline.mode_manager != "closed_loop"
                else "closed-loop runs do not resume: run it again to the end"
            )
            return f"the run was interrupted: it covers {frames}, not the whole log; {how}"
        if self.status is RunStatus.FAILED:
            why = f" ({self.error})" if self.error else ""
            return f"the run failed{why}: it covers {frames}, not the whole log"
        return f"the run is {self.status.value}: it covers {frames} so far"

    def to_json(self) -> dict[str, Any]:
        """The JSON object written to ``manifest.json``."""
        return {
            "schema_version": self.schema_version,
            "redrive_version": self.redrive_version,
            "created": self.created,
            "finished": self.finished,
            "status": self.status.value,
            "host": _asdict(self.host),
            "sensors": {k: v.value for k, v in self.sensors.items()},
            "seed": self.seed,
            "pipeline": to_jsonable(_asdict(self.pipeline)),
            "algorithms": [a.to_json() for a in self.algorithms],
            "log": to_jsonable(_asdict(self.log)),
            "closed_loop": to_jsonable(self.closed_loop),
            "map": to_jsonable(self.road_map),
            "frames_done": self.frames_done,
            "resumes": [
                {**_asdict(r), "previous_status": r.previous_status.value} for r in self.resumes
            ],
            "summary": None if self.summary is None else self.summary.to_json(),
            "error": self.error,
        }

    @classmethod
    def from_json(cls, data: Any, *, path: Path) -> RunManifest:
        """Validate the parsed JSON of ``path`` (schema 1 is upgraded first, see the module).

        Raises:
            ConfigError: not an object, no or an unsupported ``schema_version``, or a field
                missing or of the wrong type (the message names the field and what it holds).
        """
        if not isinstance(data, Mapping):
            raise manifest_error(path, f"is not a JSON object (found {type(data).__name__})")
        version = data.get("schema_version")
        if version is None:
            raise manifest_error(
                path,
                "has no `schema_version`: it was written by a pre-release redrive or is not a "
                "run manifest",
                "re-run `redrive run LOG --out NEW_DIR` to make the run with this redrive",
            )
        if not isinstance(version, int) or isinstance(version, bool) or version < 1:
            raise manifest_error(path, f"field `schema_version` is {version!r}, expected 1 or 2")
        if version > SCHEMA_VERSION:
            raise manifest_error(
                path,
                f"is schema_version {version}, newer than this redrive {redrive_version()} "
                f"reads (up to {SCHEMA_VERSION})",
                "upgrade redrive (`pip install -U redrive`) to read it",
            )
        if version == 1:
            data = upgrade_v1(data)
        return cls._parse(Fields(data, path=path))

    @classmethod
    def _parse(cls, f: Fields) -> RunManifest:
        summary = f.opt_obj("summary")
        return cls(
            schema_version=SCHEMA_VERSION,
            redrive_version=f.text("redrive_version"),
            created=f.text("created"),
            finished=f.opt_text("finished"),
            status=f.enum("status", RunStatus, _STATUSES),
            host=HostInfo._parse(f.obj("host")),
            sensors={
                k: Fields({"type": v}, path=f.path, where=f"sensors.{k}").enum(
                    "type", SensorType, _SENSOR_TYPES
                )
                for k, v in f.mapping("sensors").items()
            },
            seed=f.opt_integer("seed"),
            pipeline=PipelineInfo._parse(f.obj("pipeline")),
            algorithms=tuple(AlgorithmEntry._parse(a) for a in f.objs("algorithms")),
            log=SourceLog._parse(f.obj("log")),
            closed_loop=f.mapping("closed_loop", {}),
            road_map=f.mapping("map", {}),
            frames_done=f.integer("frames_done"),
            resumes=tuple(ResumeRecord._parse(r) for r in f.objs("resumes")),
            summary=None if summary is None else RunSummary.from_json(summary.data, path=f.path),
            error=f.opt_text("error"),
        )


#: keys a schema-1 manifest may lack (added while the format stayed at 1), with what they meant
#: when absent.
_V1_DEFAULTS: dict[str, Any] = {"sensors": {}, "error": None}
_V1_PIPELINE_DEFAULTS: dict[str, Any] = {
    "mode": "sequential",
    "executor": "threads",
    "step_timeout_s": None,
    "fail_fast": False,
    "first_frame": None,
    "stop_frame": None,
    "rate": None,
    "stages": [],
    "mode_manager": "replay",  # before live runs, every run was a replay
}
_V1_ALGORITHM_DEFAULTS: dict[str, Any] = {
    "stage": "",
    "plugin": "",
    "class": "",
    "source": "",
    "inputs": [],
    "config": {},
}
_V1_LOG_DEFAULTS: dict[str, Any] = {
    "format": "unknown",
    "size_bytes": None,
    "source": None,  # the live-only keys: absent for a file log
    "topics": {},
    "record": None,
}


def upgrade_v1(data: Mapping[str, Any]) -> dict[str, Any]:
    """A schema-1 manifest as schema 2: the keys older releases did not write are filled with
    what their absence meant, an empty ``summary`` (a run never closed) becomes null.  What
    cannot be filled (``log.path``, an algorithm's ``name``, ``role`` …) stays missing, and
    validation names it."""
    out = {**_V1_DEFAULTS, **data, "schema_version": SCHEMA_VERSION}
    if isinstance(out.get("pipeline"), Mapping):
        out["pipeline"] = {**_V1_PIPELINE_DEFAULTS, **out["pipeline"]}
    if isinstance(out.get("log"), Mapping):
        out["log"] = {**_V1_LOG_DEFAULTS, **out["log"]}
    if isinstance(out.get("algorithms"), list):
        out["algorithms"] = [
            {**_V1_ALGORITHM_DEFAULTS, **a} if isinstance(a, Mapping) else a
            for a in out["algorithms"]
        ]
    if out.get("summary") == {}:
        out["summary"] = None
    return out


def write_manifest(run_dir: Path, manifest: RunManifest) -> None:
    """Write ``RUN/manifest.json`` atomically (temp file + ``os.replace``)."""
    write_json_atomic(run_dir / MANIFEST_NAME, manifest.to_json())


def read_manifest(run_dir: Path) -> RunManifest:
    """The validated manifest of ``run_dir``.

    Raises:
        ConfigError: there is none, it is not JSON, or :meth:`RunManifest.from_json` refuses it.
    """
    path = run_dir / MANIFEST_NAME
    if not path.is_file():
        msg = f"{run_dir} is not a redrive run: it has no {MANIFEST_NAME} (give the directory a "
        msg += "`redrive run --out` wrote)"
        raise manifest_error(path, "is missing", msg) from None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise manifest_error(path, f"cannot be read as JSON ({err})", DAMAGED_ADVICE) from err
    return RunManifest.from_json(data, path=path)


def _asdict(obj: Any) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in fields(obj)}


def _plain(data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` through JSON (tuples become lists), so it equals a manifest read back."""
    try:
        out = json.loads(json.dumps(dict(data), allow_nan=False))
    except (TypeError, ValueError) as err:
        msg = f"run manifest values must be JSON-serialisable (no NaN): {err}"
        raise ValueError(msg) from err
    assert isinstance(out, dict)
    return out
