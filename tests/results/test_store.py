"""The run directory: write records, read them back, determinism, errors."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from redrive.errors import ConfigError
from redrive.results import (
    SCHEMAS,
    TABLES,
    FrameRecord,
    RunStatus,
    RunWriter,
    StepRecord,
    open_run,
)
from redrive.types import PlannedPath
from tests.results._records import EVIL, SETUP, T0_NS, frame, resources, same_object


def write_run(path: Path, n: int = 6, *, flush_every: int = 4, planning: bool = True) -> None:
    with RunWriter(path, setup=SETUP, flush_every=flush_every) as writer:
        for i in range(n):
            writer.write_frame(frame(i, planning=planning))
        writer.write_resources(resources(3))


def test_round_trip_values(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    write_run(run_dir)
    run = open_run(run_dir)
    assert run.manifest.status is RunStatus.COMPLETE
    assert run.manifest.frames_done == 6
    assert run.manifest.log == SETUP.log
    assert run.manifest.setup == SETUP
    assert set(run.tables()) == set(TABLES)
    for name in TABLES:
        assert run.table(name).schema == SCHEMAS[name], name
    # two flushes of 4 and 2 frames → parts 0 and 1
    assert [p.name for p in run.part_paths("frames")] == [
        "part-00000.parquet",
        "part-00001.parquet",
    ]

    frames = run.table("frames")
    assert frames.column("frame_index").to_pylist() == list(range(6))
    assert frames.column("stamp_ns").to_pylist()[5] == T0_NS + 500_000_000
    assert frames.column("late").to_pylist() == [False, False, True, False, False, False]
    assert frames.column("n_ground_truth").to_pylist() == [2, 2, 2, 0, None, 2]

    steps = run.table("steps")
    assert steps.num_rows == 6 * 4
    # sorted by frame, then algorithm
    assert steps.column("algorithm").to_pylist()[:4] == ["bad_det", "ctrl", "det", "planner"]
    err = steps.filter(np.array(steps.column("status").to_pylist()) == "error").to_pylist()
    assert len(err) == 3
    assert err[0]["error_message"] == EVIL
    assert err[0]["error_type"] == "ZeroDivisionError"
    assert err[0]["traceback"].startswith("Traceback (most recent call last)")
    det_rows = [r for r in steps.to_pylist() if r["algorithm"] == "det"]
    assert [r["n_outputs"] for r in det_rows] == [i % 3 for i in range(6)]
    assert [r["latency_ns"] for r in det_rows] == [1_000_000 + i for i in range(6)]

    # data model readers
    lights = run.traffic_lights()
    assert sorted(lights) == [0, 1, 3, 4, 5]  # frame 2 had none
    assert [(t.id, t.state.value) for t in lights[3]] == [("w", "red"), ("s", "green")]
    assert lights[4][0].state.value == "green"
    dets = run.detections("det")
    assert sorted(dets) == list(range(6))
    for i in range(6):
        want = frame(i).steps[0].output
        assert isinstance(want, tuple)
        assert len(dets[i]) == len(want)
        assert all(same_object(a, b) for a, b in zip(dets[i], want, strict=True))
    assert dets[2][1].bbox_2d is None
    assert dets[2][0].bbox_2d == (0.0, 20.0, 33.3, 44.4)
    assert run.detections("bad_det") == {1: (), 3: (), 5: ()}  # failed frames are absent
    with pytest.raises(ValueError, match="no algorithm 'nope'"):
        run.detections("nope")

    gt = run.ground_truth()
    assert sorted(gt) == [0, 1, 2, 3, 5]
    assert gt[3] == ()
    for i in (0, 1, 2, 5):
        want_gt = frame(i).ground_truth
        assert want_gt is not None
        assert all(same_object(a, b) for a, b in zip(gt[i], want_gt, strict=True))
    assert gt[1][0].num_lidar_points == 41
    assert gt[1][0].visible is True
    assert gt[1][1].num_lidar_points is None
    assert gt[1][1].visible is None

    paths = run.paths("planner")
    assert sorted(paths) == list(range(6))
    want_path = frame(4).steps[2].output
    assert isinstance(want_path, PlannedPath)
    assert np.array_equal(paths[4].waypoints, want_path.waypoints)
    assert paths[4].stamp_ns == T0_NS + 400_000_000
    assert paths[4].frame_id == "base_link"

    commands = run.commands("ctrl")
    assert sorted(commands) == [0, 2, 3, 4, 5]  # skipped on frame 1
    assert commands[3].steering_angle_rad == -0.03

    ego = run.ego()
    assert ego[5].position.tolist() == [512_350.678, 5_412_345.125, 101.5]
    assert ego[5].stamp_ns == T0_NS + 500_000_000
    assert ego[5].frame_id == "map"
    logged = run.logged_ego()
    assert sorted(logged) == [1, 3, 5]
    assert logged[5].position.tolist() == [512_349.678, 5_412_345.125, 101.5]
    assert logged[5].heading_rad == ego[5].heading_rad
    assert run.road_map() is None  # nothing wrote one

    res = run.table("resources")
    assert res.num_rows == 3
    assert res.column("rss_bytes").to_pylist() == [2**30] * 3


def test_summary(tmp_path: Path) -> None:
    write_run(tmp_path / "run")
    run = open_run(tmp_path / "run")
    rows = {r["algorithm"]: r for r in run.summary().to_pylist()}
    assert list(rows) == ["det", "bad_det", "planner", "ctrl"]  # pipeline order
    det = rows["det"]
    assert (det["frames"], det["ok"], det["error"], det["outputs"]) == (
        6,
        6,
        0,
        0 + 1 + 2 + 0 + 1 + 2,
    )
    lat = np.array([1_000_000 + i for i in range(6)]) / 1e6
    assert det["latency_mean_ms"] == pytest.approx(lat.mean())
    assert det["latency_p95_ms"] == pytest.approx(np.percentile(lat, 95))
    assert det["latency_max_ms"] == pytest.approx(1.000005)
    assert det["cpu_mean_ms"] == pytest.approx(0.9)
    assert (rows["bad_det"]["error"], rows["bad_det"]["ok"]) == (3, 3)
    assert (rows["ctrl"]["skipped"], rows["ctrl"]["outputs"]) == (1, 5)
    assert rows["planner"]["outputs"] == 6
    # the manifest carries the same summary, computed at close
    manifest = json.loads((tmp_path / "run" / "manifest.json").read_text())
    assert manifest["summary"]["frames"] == 6
    assert manifest["summary"]["late_frames"] == 1
    assert manifest["summary"]["algorithms"][2]["algorithm"] == "planner"
    assert manifest["finished"]
    assert manifest["created"].endswith("+00:00")
    assert set(manifest["host"]) == {"hostname", "platform", "python", "cpu_count"}


def test_empty_output_kinds_have_schemas(tmp_path: Path) -> None:
    write_run(tmp_path / "run", n=3, planning=False)
    run = open_run(tmp_path / "run")
    assert "paths" not in run.tables()
    assert "commands" not in run.tables()
    for name in ("paths", "commands"):
        table = run.table(name)
        assert table.num_rows == 0
        assert table.schema == SCHEMAS[name]
    empty = tmp_path / "empty"
    RunWriter(empty, setup=SETUP).close(status=RunStatus.COMPLETE)
    run = open_run(empty)
    assert run.tables() == ()
    assert run.summary().num_rows == 0
    assert run.table("detections").schema == SCHEMAS["detections"]
    assert run.ground_truth() == {}


def test_parts_are_deterministic(tmp_path: Path) -> None:
    write_run(tmp_path / "a", n=9)
    write_run(tmp_path / "b", n=9)
    files_a = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*.parquet"))
    files_b = sorted(p.relative_to(tmp_path / "b") for p in (tmp_path / "b").rglob("*.parquet"))
    # 3 flushes × 8 tables (traffic_lights too) (resources come with the last); frame 8 has empty ground truth;
    # ego_logged and closed_loop (odd frames) in the first two
    assert files_a == files_b
    assert len(files_a) == 3 * 8 + 2 * 2
    for rel in files_a:
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes(), rel
    # no wall-clock metadata in the files
    meta = pq.ParquetFile(tmp_path / "a" / files_a[0]).schema_arrow.metadata or {}
    assert all(b"created" not in k for k in meta)


def test_refuses_non_run_directory(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match=r"not empty and holds no redrive run.*--out"):
        RunWriter(tmp_path, setup=SETUP)
    with pytest.raises(ConfigError, match="not empty and holds no redrive run"):
        RunWriter(tmp_path, setup=SETUP, resume=True)
    with pytest.raises(ConfigError, match="is not a redrive run"):
        open_run(tmp_path)
    with pytest.raises(ConfigError, match="no such run directory"):
        open_run(tmp_path / "missing")


def test_refuses_existing_run_without_resume(tmp_path: Path) -> None:
    write_run(tmp_path / "run", n=2)
    with pytest.raises(ConfigError, match="already holds a run; use --resume"):
        RunWriter(tmp_path / "run", setup=SETUP)


def test_refuses_mismatching_resume(tmp_path: Path) -> None:
    write_run(tmp_path / "run", n=2)
    algos = SETUP.algorithms
    other = replace(
        SETUP,
        log=replace(SETUP.log, sha256="def"),
        algorithms=(replace(algos[0], config_hash="c9"), *algos[1:]),
    )
    with pytest.raises(ConfigError, match=r"log\.sha256: run has \"abc\", now \"def\""):
        RunWriter(tmp_path / "run", setup=other, resume=True)
    for key, value in (("stop_frame", 100), ("first_frame", 5)):
        ranged = replace(SETUP, pipeline=replace(SETUP.pipeline, **{key: value}))
        with pytest.raises(ConfigError, match=f"pipeline.{key}: run has"):
            RunWriter(tmp_path / "run", setup=ranged, resume=True)
    reconfigured = replace(
        SETUP, algorithms=(*algos[:2], replace(algos[2], config_hash="c9"), algos[3])
    )
    with pytest.raises(ConfigError, match="algorithms: run has"):
        RunWriter(tmp_path / "run", setup=reconfigured, resume=True)
    # a change outside RESUME_KEYS is fine (the log moved, another stage layout)
    moved = replace(
        SETUP,
        log=replace(SETUP.log, path="/elsewhere/drive.mcap"),
        pipeline=replace(SETUP.pipeline, stages=("c", "p")),
    )
    RunWriter(tmp_path / "run", setup=moved, resume=True).close(status=RunStatus.COMPLETE)


def test_one_writer_at_a_time(tmp_path: Path) -> None:
    writer = RunWriter(tmp_path / "run", setup=SETUP)
    with pytest.raises(ConfigError, match="another process is writing this run"):
        RunWriter(tmp_path / "run", setup=SETUP, resume=True)
    writer.close(status=RunStatus.COMPLETE)
    RunWriter(tmp_path / "run", setup=SETUP, resume=True).close(status=RunStatus.COMPLETE)


def test_status_from_context_manager(tmp_path: Path) -> None:
    def failing_run() -> None:
        with RunWriter(tmp_path / "failed", setup=SETUP) as w:
            w.write_frame(frame(0))
            raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        failing_run()
    failed = open_run(tmp_path / "failed")
    assert failed.manifest.status is RunStatus.FAILED
    assert failed.manifest.error == "RuntimeError: boom"
    assert failed.manifest.frames_done == 1  # buffered frames were flushed

    with pytest.raises(KeyboardInterrupt), RunWriter(tmp_path / "int", setup=SETUP):
        raise KeyboardInterrupt
    assert open_run(tmp_path / "int").manifest.status is RunStatus.INTERRUPTED


def test_bad_input_is_refused(tmp_path: Path) -> None:
    writer = RunWriter(tmp_path / "run", setup=SETUP, flush_every=2)
    writer.write_frame(frame(0))
    with pytest.raises(ValueError, match="frame 0 was already written"):
        writer.write_frame(frame(0))  # buffered
    writer.write_frame(frame(1))
    assert writer.done_frames == {0, 1}
    with pytest.raises(ValueError, match="frame 1 was already written"):
        writer.write_frame(frame(1))  # committed
    with pytest.raises(ValueError, match="status 'done'"):
        writer.close(status="done")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="status 'running'"):
        writer.close(status=RunStatus.RUNNING)
    with pytest.raises(ValueError, match=r"summary keys \['speed'\]"):
        writer.close(status=RunStatus.COMPLETE, summary={"speed": 1})
    with pytest.raises(ValueError, match=r"summary\.wall_s"):
        writer.close(status=RunStatus.COMPLETE, summary={"wall_s": "fast"})
    writer.close(status=RunStatus.COMPLETE)
    writer.close(status=RunStatus.FAILED)  # a second close does nothing
    assert open_run(tmp_path / "run").manifest.status is RunStatus.COMPLETE
    with pytest.raises(ValueError, match="closed"):
        writer.write_frame(frame(2))
    with pytest.raises(ValueError, match="planning step's output must be PlannedPath"):
        StepRecord(algorithm="p", stage="s", role="planning", status="ok", output=())
    with pytest.raises(ValueError, match="role 'sensing'"):
        StepRecord(algorithm="p", stage="s", role="sensing", status="ok")
    step = StepRecord(algorithm="p", stage="s", role="control", status="ok")
    with pytest.raises(ValueError, match="appears twice"):
        FrameRecord(frame_index=0, stamp_ns=0, steps=(step, step))


def test_readers_ignore_tmp_and_orphan_parts(tmp_path: Path) -> None:
    write_run(tmp_path / "run", n=4, flush_every=2)
    run_dir = tmp_path / "run"
    (run_dir / "frames" / "part-00009.parquet.tmp").write_bytes(b"half a file")
    # a steps part whose flush never committed its frames part
    (run_dir / "steps" / "part-00009.parquet").write_bytes(
        (run_dir / "steps" / "part-00001.parquet").read_bytes()
    )
    run = open_run(run_dir)
    assert run.table("steps").num_rows == 4 * 4
    assert run.table("frames").column("frame_index").to_pylist() == [0, 1, 2, 3]
