"""Resuming a run: what must be equal for a run directory to be continued, and the manifest of
a run that runs again (``redrive run … --resume``)."""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Any

from redrive.results.manifest import (
    AlgorithmEntry,
    ResumeRecord,
    RunManifest,
    RunSetup,
    RunStatus,
)

__all__ = ["RESUME_KEYS", "resume_mismatches", "with_resume"]

#: what must be equal for a run to be resumed (dotted paths into the manifest); for
#: ``algorithms`` each entry's ``name``, ``version`` and ``config_hash`` are compared in order.
RESUME_KEYS = ("log.sha256", "algorithms", "pipeline.first_frame", "pipeline.stop_frame")


def _algorithms_key(algorithms: tuple[AlgorithmEntry, ...]) -> list[dict[str, str]]:
    return [
        {"name": a.name, "version": a.version, "config_hash": a.config_hash} for a in algorithms
    ]


def resume_mismatches(old: RunSetup, new: RunSetup) -> list[str]:
    """Human-readable differences in :data:`RESUME_KEYS` between a run's setup and a new one."""
    pairs: dict[str, tuple[Any, Any]] = {
        "log.sha256": (old.log.sha256, new.log.sha256),
        "algorithms": (_algorithms_key(old.algorithms), _algorithms_key(new.algorithms)),
        "pipeline.first_frame": (old.pipeline.first_frame, new.pipeline.first_frame),
        "pipeline.stop_frame": (old.pipeline.stop_frame, new.pipeline.stop_frame),
    }
    assert tuple(pairs) == RESUME_KEYS
    return [
        f"{key}: run has {json.dumps(a)}, now {json.dumps(b)}"
        for key, (a, b) in pairs.items()
        if a != b
    ]


def with_resume(manifest: RunManifest, record: ResumeRecord) -> RunManifest:
    """``manifest`` running again after ``record``."""
    return replace(
        manifest,
        status=RunStatus.RUNNING,
        finished=None,
        frames_done=record.frames_done,
        resumes=(*manifest.resumes, record),
    )
