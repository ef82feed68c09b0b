"""Log and pipeline names that become paths: ``..mcap``, ``...mcap``, ``a b.mcap``, two logs of one
stem and a case-only clash each keep their own cell directory inside ``runs/``; a pipeline named
``..`` is refused; a cell never removes a directory that holds anything but a run (issue 37)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from redrive.batch import CellStatus, expand_logs, make_pipeline_item, read_batch_manifest
from redrive.batch.spec import load_batch_spec, safe_name
from redrive.errors import ConfigError
from redrive.results import RunStatus, read_manifest

from .conftest import PIPELINE_A
from .outputs import batch


@pytest.fixture
def hostile_logs(logs: list[Path], tmp_path: Path) -> list[Path]:
    folder = tmp_path / "drives"
    (folder / "other").mkdir(parents=True)
    names = ["..bag", "...bag", "a b.bag", "a_b.bag", "drive.bag", "other/drive.bag", "Drive.bag"]
    out = []
    for name, src in zip(names, logs * 2, strict=False):
        shutil.copyfile(src, folder / name)
        out.append(folder / name)
    return out


def test_safe_names() -> None:
    assert safe_name(".") == "_"
    assert safe_name("..") == "__"
    assert safe_name(".hidden") == "_hidden"
    assert safe_name("a b/c") == "a_b_c"
    assert safe_name("") == "log"


def test_every_hostile_log_gets_its_own_directory(hostile_logs: list[Path]) -> None:
    items = expand_logs([str(p) for p in hostile_logs])
    ids = [x.log_id for x in items]
    assert len(ids) == len(hostile_logs)
    assert len({i.casefold() for i in ids}) == len(ids)
    for log_id in ids:
        assert "/" not in log_id
        assert not log_id.startswith(".")
    assert ids[0] == "_"
    assert ids[1] == "__"
    # "a b" and "a_b", "drive" twice and "Drive": each gets a hash of its path
    assert ids[2].startswith("a_b-")
    assert ids[3].startswith("a_b-")
    assert ids[4].startswith("drive-")
    assert ids[5].startswith("drive-")
    assert ids[6].startswith("Drive-")


def test_a_batch_over_hostile_names_keeps_every_cells_results(
    hostile_logs: list[Path], tmp_path: Path
) -> None:
    logs = hostile_logs[:5]
    out = tmp_path / "batch"
    pipeline = tmp_path / "a.toml"
    pipeline.write_text(PIPELINE_A, encoding="utf-8")
    assert batch(out, *map(str, logs), "--pipeline", str(pipeline), "--workers", "2") == 0
    manifest = read_batch_manifest(out)
    assert [c.status for c in manifest.cells] == [CellStatus.COMPLETE] * len(logs)
    for cell in manifest.cells:
        run_dir = (out / cell.run_dir).resolve()
        assert run_dir.parent.parent.parent == (out / "runs").resolve()
        run = read_manifest(run_dir)  # every cell's run is still there, complete
        assert run.status is RunStatus.COMPLETE
        assert run.frames_done == cell.frames
    assert sorted(Path(read_manifest(out / c.run_dir).log.path).name for c in manifest.cells) == (
        sorted(p.name for p in logs)
    )
    # --force redoes every cell and still loses none
    assert batch(out, *map(str, logs), "--pipeline", str(pipeline), "--force") == 0
    again = read_batch_manifest(out)
    assert all(read_manifest(out / c.run_dir).status is RunStatus.COMPLETE for c in again.cells)


def test_a_cell_never_removes_what_the_batch_did_not_make(logs: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "batch"
    pipeline = tmp_path / "a.toml"
    pipeline.write_text(PIPELINE_A, encoding="utf-8")
    mine = out / "runs" / "a" / "open" / "drive0"
    mine.mkdir(parents=True)
    (mine / "notes.txt").write_text("my notes", encoding="utf-8")
    assert batch(out, str(logs[0]), "--pipeline", str(pipeline)) != 0
    assert (mine / "notes.txt").read_text(encoding="utf-8") == "my notes"
    cell = read_batch_manifest(out).cells[0]
    assert cell.status is CellStatus.FAILED
    assert "no redrive run" in (cell.error or "")


@pytest.mark.parametrize("name", ["..", ".", ".hidden", "a/b"])
def test_a_pipeline_named_like_a_path_is_refused(name: str, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="pipeline name"):
        make_pipeline_item(name=name, planning=["idm-planner"])
    spec = tmp_path / "batch.toml"
    spec.write_text(
        f'logs = ["urban"]\n[[pipeline]]\nname = "{name}"\nplanning = ["idm-planner"]\n',
        encoding="utf-8",
    )
    with pytest.raises(ConfigError, match="pipeline name"):
        load_batch_spec(spec)
