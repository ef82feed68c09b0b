"""``redrive batch --executor ray`` on a real local Ray cluster (started once for the module):
the same cells as the local pool, and a SIGKILLed Ray worker fails only its cell."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from redrive.batch import CellStatus, read_batch_manifest
from redrive.cli.batch import EXIT_CELLS_FAILED
from redrive.results import RunStatus, read_manifest
from redrive.testing.demo_log import write_demo_bag

from .outputs import batch, batch_outputs

ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'redrive[ray]')")

PLUGINS = Path(__file__).with_name("plugins.py")


@pytest.fixture(scope="module", autouse=True)
def ray_cluster() -> Iterator[None]:
    """A real local Ray cluster of 2 CPUs; `redrive batch` uses it (Ray is initialised)."""
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        yield
    finally:
        ray.shutdown()


def test_ray_gives_the_local_pools_outputs(
    two_workers: Path, logs: list[Path], pipelines: list[Path], tmp_path: Path
) -> None:
    args = [str(p) for p in logs]
    for p in pipelines:
        args += ["--pipeline", str(p)]
    out = tmp_path / "ray"
    assert batch(out, *args, "--executor", "ray", "--workers", "2") == 0
    manifest = read_batch_manifest(out)
    assert manifest.executor == "ray"
    assert {c.status for c in manifest.cells} == {CellStatus.COMPLETE}
    on_ray = batch_outputs(out)
    assert len(on_ray) == 8
    assert on_ray == batch_outputs(two_workers)
    assert ray.is_initialized()  # a cluster the batch did not start is left running


def test_a_sigkilled_ray_worker_fails_only_its_cell(logs: list[Path], tmp_path: Path) -> None:
    long_log = tmp_path / "long.bag"
    write_demo_bag(long_log, duration_s=3.0)  # reaches frame 25, where KillAtFrame kills
    out = tmp_path / "batch"
    status = batch(
        out,
        str(logs[0]),
        str(long_log),
        "--planning",
        f"{PLUGINS}:KillAtFrame",
        "--executor",
        "ray",
        "--workers",
        "2",
        "--retries",
        "1",
    )
    assert status == EXIT_CELLS_FAILED
    cells = {c.log_id: c for c in read_batch_manifest(out).cells}
    killed = cells["long"]
    assert killed.status is CellStatus.FAILED
    assert killed.attempts == 2
    assert killed.error is not None
    assert killed.error.startswith("WorkerDied: the Ray worker died (2 attempt(s))")
    assert cells["drive0"].status is CellStatus.COMPLETE
    assert read_manifest(out / cells["drive0"].run_dir).status is RunStatus.COMPLETE
