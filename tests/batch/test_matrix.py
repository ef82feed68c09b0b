"""The matrix: how log entries expand (paths, globs, directories, .txt lists, scenarios with
seeds), the spec file, closed-loop cells (a scenario driven; a log without the ego's pose fails
its cell with the closed loop's error) and Ray's absence."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest
from rosbags.rosbag1 import Reader, Writer

from redrive.batch import (
    BatchSpec,
    CellStatus,
    expand_logs,
    load_batch_spec,
    make_pipeline_item,
    parse_seeds,
    plan_cells,
    read_batch_manifest,
    run_batch,
)
from redrive.cli.batch import EXIT_CELLS_FAILED, batch_cell
from redrive.errors import ConfigError
from redrive.results import RunStatus, read_manifest

from .outputs import batch


def test_seeds() -> None:
    assert parse_seeds("0-3") == (0, 1, 2, 3)
    assert parse_seeds("7") == (7,)
    assert parse_seeds("0-1,5,1") == (0, 1, 5)
    for bad in ("3-1", "a", "1-"):
        with pytest.raises(ConfigError, match="seeds"):
            parse_seeds(bad)


def test_log_entries_expand_to_unique_logs(logs: list[Path], tmp_path: Path) -> None:
    folder = tmp_path / "fleet"
    (folder / "night").mkdir(parents=True)
    for log in logs[:2]:
        shutil.copy(log, folder / log.name)
    shutil.copy(logs[2], folder / "night" / logs[0].name)  # same name, other directory
    (folder / "notes.md").write_text("not a log", encoding="utf-8")
    listing = tmp_path / "fleet.txt"
    listing.write_text(
        f"# the fleet\nfleet/{logs[0].name}\n{folder / 'night'}  # nightly\n\n", encoding="utf-8"
    )
    items = expand_logs(
        [str(folder), str(tmp_path / "fleet/*.bag"), str(listing), "cut_in@3", "urban"],
        seeds=(1, 2),
    )
    ids = [x.log_id for x in items]
    assert ids[:2] == ["drive0-" + ids[0].rsplit("-", 1)[1], "drive1"]
    assert ids[2].startswith("drive0-")
    assert ids[2] != ids[0]  # two files named drive0.bag: told apart by a hash of their paths
    assert ids[3:] == ["cut_in@3", "urban@1", "urban@2"]
    assert [x.path for x in items[:3]] == [
        str((folder / logs[0].name).resolve()),
        str((folder / logs[1].name).resolve()),
        str((folder / "night" / logs[0].name).resolve()),
    ]
    assert (items[3].scenario, items[3].seed) == ("cut_in", 3)
    with pytest.raises(ConfigError, match="no such log"):
        expand_logs(["missing.bag"])
    with pytest.raises(ConfigError, match="matches no file"):
        expand_logs([str(tmp_path / "*.mcap")])
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ConfigError, match="no logs in it"):
        expand_logs([str(empty)])


def test_a_spec_file_holds_the_matrix(
    logs: list[Path], pipelines: list[Path], tmp_path: Path
) -> None:
    spec_file = tmp_path / "nightly.toml"
    spec_file.write_text(
        f"""\
logs = ["{logs[0]}", "{logs[1]}"]
loop = "open"
out = "out/nightly"
workers = 1
retries = 0

[[pipeline]]
file = "{pipelines[0]}"

[[pipeline]]
name = "idm"
planning = ["idm-planner"]
""",
        encoding="utf-8",
    )
    keys = load_batch_spec(spec_file)
    assert keys["out"] == tmp_path / "out/nightly"
    assert [p.name for p in keys["pipelines"]] == ["a", "idm"]
    assert main_status(["--spec", str(spec_file)]) == 0
    manifest = read_batch_manifest(tmp_path / "out/nightly")
    assert [c.cell_id for c in manifest.cells] == [
        "a/open/drive0",
        "a/open/drive1",
        "idm/open/drive0",
        "idm/open/drive1",
    ]
    assert manifest.workers == 1
    assert manifest.retries == 0
    spec_file.write_text('logs = ["x"]\nspeed = 3\n', encoding="utf-8")
    with pytest.raises(ConfigError, match="unknown key"):
        load_batch_spec(spec_file)


def main_status(args: list[str]) -> int:
    from redrive.cli.main import main

    return main(["batch", *args, "--no-progress"])


def _without_pose(source: Path, out: Path) -> Path:
    """A copy of a demo bag without its odometry: a log with no ego pose."""
    with Reader(source) as reader, Writer(out) as writer:
        conns = {}
        for conn in reader.connections:
            if conn.topic == "/odom":
                continue
            conns[conn.id] = writer.add_connection(
                conn.topic, conn.msgtype, msgdef=conn.msgdef.data, md5sum=conn.digest
            )
        for conn, stamp, data in reader.messages():
            if conn.id in conns:
                writer.write(conns[conn.id], stamp, data)
    return out


def test_closed_loop_cells(logs: list[Path], tmp_path: Path) -> None:
    no_pose = _without_pose(logs[0], tmp_path / "no_pose.bag")
    out = tmp_path / "batch"
    status = batch(
        out,
        "cut_in@1",
        str(no_pose),
        "--loop",
        "both",
        "--duration",
        "1",
        "--planning",
        "idm-planner",
        "--workers",
        "2",
    )
    assert status == EXIT_CELLS_FAILED
    cells = {c.cell_id: c for c in read_batch_manifest(out).cells}
    assert set(cells) == {
        "flags/open/cut_in@1",
        "flags/closed/cut_in@1",
        "flags/open/no_pose",
        "flags/closed/no_pose",
    }
    for cell_id in ("flags/open/cut_in@1", "flags/closed/cut_in@1"):
        assert cells[cell_id].status is CellStatus.COMPLETE, cells[cell_id].error
        assert read_manifest(out / cells[cell_id].run_dir).status is RunStatus.COMPLETE
    closed = read_manifest(out / "runs/flags/closed/cut_in@1")
    assert closed.pipeline.mode_manager == "closed_loop"
    assert (out / "logs/cut_in@1_1s.mcap").is_file()  # the open-loop cell's simulated log
    failed = cells["flags/closed/no_pose"]
    assert failed.status is CellStatus.FAILED
    assert failed.error is not None
    assert failed.error.startswith(f"ConfigError: {no_pose}: closed loop needs the ego's pose")
    # the planner needs the ego state in open loop too: that cell fails on its own reason
    assert "needs vehicle state" in (cells["flags/open/no_pose"].error or "")


def test_ray_missing_is_a_clear_error(
    logs: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    spec = BatchSpec(
        logs=expand_logs([str(logs[0])]),
        pipelines=(make_pipeline_item(name=None, planning=["idm-planner"]),),
    )
    with pytest.raises(ConfigError, match=r"pip install 'redrive\[ray\]'"):
        run_batch(spec, tmp_path / "b", runner=batch_cell, executor="ray", workers=1)
    assert len(plan_cells(spec, tmp_path / "b")) == 1


def test_on_collision_reaches_the_closed_loop_cells_and_their_key(tmp_path: Path) -> None:
    spec_file = tmp_path / "stop.toml"
    spec_file.write_text(
        'logs = ["cut_in"]\nloop = "both"\non_collision = "stop"\nout = "b"\n', encoding="utf-8"
    )
    keys = load_batch_spec(spec_file)
    assert keys["on_collision"] == "stop"
    spec = BatchSpec(
        logs=keys["logs"],
        pipelines=(make_pipeline_item(name="idm", planning=["idm-planner"]),),
        loops=("open", "closed"),
        on_collision="stop",
    )
    tasks = {t.loop: t for t in plan_cells(spec, tmp_path / "b")}
    assert tasks["closed"].on_collision == "stop"
    assert "on_collision=stop" in tasks["closed"].key.options
    assert tasks["open"].key.options == ""
    # the default leaves the key of earlier batches as it was
    default = BatchSpec(logs=spec.logs, pipelines=spec.pipelines, loops=("closed",))
    assert plan_cells(default, tmp_path / "b")[0].key.options == "agents=replay"
