"""The typed run manifest: round trip, every damaged-file refusal, the schema-1 upgrade."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from redrive.errors import ConfigError
from redrive.results import RunStatus, RunWriter, open_run
from redrive.results.manifest import (
    MANIFEST_NAME,
    SCHEMA_VERSION,
    RunManifest,
    RunSummary,
    read_manifest,
    write_manifest,
)
from redrive.types import Role, SensorType
from tests.results._records import SETUP, frame


def closed_run(run_dir: Path) -> RunManifest:
    with RunWriter(run_dir, setup=SETUP) as writer:
        for i in range(3):
            writer.write_frame(frame(i))
    return read_manifest(run_dir)


def on_disk(run_dir: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((run_dir / MANIFEST_NAME).read_text())
    return data


def rewrite(run_dir: Path, data: Any) -> None:
    (run_dir / MANIFEST_NAME).write_text(json.dumps(data))


def test_round_trip(tmp_path: Path) -> None:
    manifest = closed_run(tmp_path / "run")
    assert manifest.schema_version == SCHEMA_VERSION == 2
    assert manifest.status is RunStatus.COMPLETE
    assert manifest.setup == SETUP
    assert manifest.algorithms[2].role is Role.PLANNING
    assert manifest.summary is not None
    assert manifest.summary.frames == 3
    data = on_disk(tmp_path / "run")
    assert data["schema_version"] == 2
    assert data["status"] == "complete"
    assert data["algorithms"][0]["role"] == "perception"
    assert RunManifest.from_json(data, path=tmp_path) == manifest
    assert manifest.to_json() == data
    # written back unchanged, atomically (no temp file left)
    write_manifest(tmp_path / "run", manifest)
    assert on_disk(tmp_path / "run") == data
    assert not list((tmp_path / "run").glob("*.tmp"))


def test_sensors_and_live_log(tmp_path: Path) -> None:
    from dataclasses import replace

    live = replace(
        SETUP,
        log=replace(SETUP.log, format="live", sha256=None, topics={"/velo": "sensor_msgs/msg/X"}),
        sensors={"lidar_top": SensorType.LIDAR},
    )
    RunWriter(tmp_path / "run", setup=live).close(status=RunStatus.INTERRUPTED)
    manifest = read_manifest(tmp_path / "run")
    assert manifest.setup == live
    assert manifest.status is RunStatus.INTERRUPTED
    assert on_disk(tmp_path / "run")["sensors"] == {"lidar_top": "lidar"}


@pytest.mark.parametrize(
    ("damage", "expected"),
    [
        (lambda d: d.pop("status"), r"has no field `status`"),
        (lambda d: d.update(status="paused"), r"field `status` is a string \('paused'\), "
         r"expected one of running, complete, interrupted, failed"),
        (lambda d: d.update(frames_done="3"), r"field `frames_done` is a string \('3'\), "
         r"expected an integer"),
        (lambda d: d.update(frames_done=True), r"field `frames_done` is a boolean"),
        (lambda d: d["log"].pop("path"), r"has no field `log.path`"),
        (lambda d: d.update(log=[]), r"field `log` is a list \(\[\]\), expected an object"),
        (lambda d: d["pipeline"].update(first_frame=1.5), r"`pipeline.first_frame` is a number "
         r"\(1.5\), expected an integer or null"),
        (lambda d: d["algorithms"][1].update(role="sensing"), r"`algorithms\[1\].role` is a "
         r"string \('sensing'\), expected one of perception, planning, control"),
        (lambda d: d["algorithms"][0].pop("config_hash"), r"no field `algorithms\[0\].config_hash`"),
        (lambda d: d["sensors"].update(cam="sonar"), r"`sensors.cam.type` is a string \('sonar'\)"),
        (lambda d: d["summary"].update(frames=None), r"`summary.frames` is null"),
        (lambda d: d.update(resumes=[{"at": "x"}]), r"no field `resumes\[0\].previous_status`"),
    ],
)  # fmt: skip
def test_damaged_field_is_named(tmp_path: Path, damage: Any, expected: str) -> None:
    run_dir = tmp_path / "run"
    closed_run(run_dir)
    data = on_disk(run_dir)
    damage(data)
    rewrite(run_dir, data)
    with pytest.raises(ConfigError, match=expected) as info:
        open_run(run_dir)
    message = str(info.value)
    assert str(run_dir / MANIFEST_NAME) in message
    assert "re-run `redrive run" in message


def test_unreadable_files(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    with pytest.raises(ConfigError, match=r"is not a redrive run: it has no manifest.json"):
        read_manifest(run_dir)
    (run_dir / MANIFEST_NAME).write_text('{"schema_version": 2, ')
    with pytest.raises(ConfigError, match=r"manifest.json: run manifest cannot be read as JSON"):
        read_manifest(run_dir)
    rewrite(run_dir, [1, 2])
    with pytest.raises(ConfigError, match=r"is not a JSON object \(found list\)"):
        read_manifest(run_dir)


def test_unversioned_and_newer_manifests_are_refused(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    closed_run(run_dir)
    data = on_disk(run_dir)
    del data["schema_version"]
    rewrite(run_dir, data)
    with pytest.raises(ConfigError, match="has no `schema_version`") as info:
        read_manifest(run_dir)
    assert "re-run `redrive run LOG --out NEW_DIR`" in str(info.value)
    rewrite(run_dir, {**data, "schema_version": 3})
    with pytest.raises(ConfigError, match=r"schema_version 3, newer than this redrive") as info:
        read_manifest(run_dir)
    assert "upgrade redrive" in str(info.value)
    rewrite(run_dir, {**data, "schema_version": "2"})
    with pytest.raises(ConfigError, match=r"field `schema_version` is '2', expected 1 or 2"):
        read_manifest(run_dir)


#: a manifest as redrive wrote it before the typed model (schema 1, before live runs: no
#: `sensors`, no `pipeline.mode_manager`, algorithms without `source`/`inputs`); the run was
#: interrupted and never closed since, so its summary is empty.
V1 = {
    "schema_version": 1,
    "redrive_version": "0.3.0",
    "created": "2025-01-31T12:00:00.123+00:00",
    "finished": None,
    "status": "running",
    "host": {"hostname": "h", "platform": "Linux", "python": "3.11.9", "cpu_count": 2},
    "seed": 0,
    "pipeline": {"mode": "sequential", "executor": "threads", "step_timeout_s": None,
                 "fail_fast": False, "first_frame": None, "stop_frame": None, "rate": None,
                 "stages": ["perception"]},
    "algorithms": [{"name": "det", "stage": "perception", "role": "perception",
                    "plugin": "cluster-detector", "class": "m:C", "version": "1",
                    "config": {"k": 1}, "config_hash": "c1"}],
    "log": {"path": "/data/drive.mcap", "size_bytes": 10, "sha256": "abc", "format": "mcap"},
    "frames_done": 20,
    "resumes": [],
    "summary": {},
}  # fmt: skip


def test_schema_1_is_upgraded(tmp_path: Path) -> None:
    run_dir = tmp_path / "old"
    run_dir.mkdir()
    rewrite(run_dir, V1)
    manifest = open_run(run_dir).manifest
    assert manifest.schema_version == 2
    assert manifest.status is RunStatus.RUNNING
    assert manifest.sensors == {}
    assert manifest.pipeline.mode_manager == "replay"
    assert manifest.pipeline.stages == ("perception",)
    assert manifest.algorithms[0].role is Role.PERCEPTION
    assert manifest.algorithms[0].source == ""
    assert manifest.algorithms[0].config == {"k": 1}
    assert manifest.summary is None
    assert manifest.frames_done == 20
    # a closed v1 run keeps its summary; what cannot be filled in is still refused
    closed = {**V1, "status": "complete", "summary": {"frames": 20, "late_frames": 0,
                                                      "wall_s": 1.5}}  # fmt: skip
    rewrite(run_dir, closed)
    summary = read_manifest(run_dir).summary
    assert summary == RunSummary(frames=20, late_frames=0, wall_s=1.5)
    rewrite(run_dir, {**V1, "log": {"sha256": "abc"}})
    with pytest.raises(ConfigError, match=r"has no field `log\.path`"):
        read_manifest(run_dir)
