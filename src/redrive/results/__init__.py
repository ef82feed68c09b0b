"""The results store (L2): one run directory per run, shared by engine, evaluation and GUI.

The engine writes a run with :class:`RunWriter` (records of :mod:`redrive.results.records`);
evaluation and the GUI read it with :func:`open_run`; :func:`export_run` turns it into Parquet,
CSV or Excel files.  Nothing here imports the engine, the algorithms or the log readers.

Layout of a run directory (columns: ``docs/results.md``)::

    RUN/manifest.json              a RunManifest (redrive.results.manifest): schema_version,
                                   redrive_version, created/finished (ISO UTC), status (a
                                   RunStatus: running | complete | interrupted | failed), host,
                                   log, sensors, seed, pipeline, algorithms (the engine's
                                   RunSetup), frames_done, resumes, summary, error
    RUN/frames/part-00000.parquet  one row per frame: frame_index, stamp_ns, wall_ns, late,
                                   n_ground_truth
    RUN/steps/part-…               one row per algorithm per frame: status, latency, errors
    RUN/detections/part-…          one row per object a perception algorithm returned
    RUN/ground_truth/part-…        one row per ground-truth object
    RUN/ego/part-…                 one row per frame with an ego state
    RUN/ego_logged/part-…          closed loop: the logged ego state where it differs from the
                                   driven one (optional: older runs have no such table)
    RUN/paths/part-…               one row per waypoint of a planned path
    RUN/commands/part-…            one row per control command
    RUN/closed_loop/part-…         closed loop: one row per frame, what moved the ego after it
                                   (control, tracker or fallback and why) and its deviation
    RUN/resources/part-…           one row per process resource sample
    RUN/map.json                   optional: the road map (lanes, drivable areas; see
                                   redrive.results.roadmap), written by RunWriter.write_map
    RUN/sensors.mcap               optional: a sensor-level closed loop's rendered sensors,
                                   named by the manifest's closed_loop.sensor_log (written by
                                   redrive.closedloop, not by RunWriter)
    RUN/.lock                      held by the writing process

Each flush of the writer adds part N of every table that has rows, and always ``frames`` part
N, written last; parts are written to ``*.tmp`` and renamed.  A part counts only when the
``frames`` part of its number exists, so a killed writer leaves a readable run that
``RunWriter(..., resume=True)`` continues.  Parquet files hold no wall-clock metadata: the same
records give the same bytes.
"""

from __future__ import annotations

from redrive.results.export import EXPORT_FORMATS, export_run
from redrive.results.manifest import (
    SCHEMA_VERSION,
    AlgorithmEntry,
    PipelineInfo,
    RunManifest,
    RunSetup,
    RunStatus,
    RunSummary,
    SourceLog,
    read_manifest,
)
from redrive.results.records import (
    ROLES,
    STATUSES,
    ClosedLoopRecord,
    FrameRecord,
    ResourceSample,
    StepOutput,
    StepRecord,
)
from redrive.results.resume import RESUME_KEYS
from redrive.results.roadmap import MAP_NAME, read_road_map, write_road_map
from redrive.results.schema import SCHEMAS, TABLES
from redrive.results.store import FINAL_STATUSES, Run, RunWriter, open_run

__all__ = [
    "EXPORT_FORMATS",
    "FINAL_STATUSES",
    "MAP_NAME",
    "RESUME_KEYS",
    "ROLES",
    "SCHEMAS",
    "SCHEMA_VERSION",
    "STATUSES",
    "TABLES",
    "AlgorithmEntry",
    "ClosedLoopRecord",
    "FrameRecord",
    "PipelineInfo",
    "ResourceSample",
    "Run",
    "RunManifest",
    "RunSetup",
    "RunStatus",
    "RunSummary",
    "RunWriter",
    "SourceLog",
    "StepOutput",
    "StepRecord",
    "export_run",
    "open_run",
    "read_manifest",
    "read_road_map",
    "write_road_map",
]
