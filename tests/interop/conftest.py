"""A short synthetic log and a run of the reference pipeline over it, made once per session."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pytest

pytest.importorskip("foxglove", reason="needs foxglove-sdk (pip install 'redrive[foxglove]')")


@pytest.fixture(scope="session")
def short_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """1 s of the built-in ``urban`` scenario (seed 7, 10 frames), by the real simulator."""
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize

    out = tmp_path_factory.mktemp("fg_log") / "urban.mcap"
    synthesize(load_scenario("urban"), out, duration_s=1.0, seed=7)
    return out


@pytest.fixture(scope="session")
def short_run(short_log: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference pipeline over :func:`short_log` as ``redrive run`` writes it, with one
    stored bookmark (frame 5) as ``redrive evaluate`` stores them."""
    from redrive.cli.main import main
    from redrive.results import open_run
    from redrive.results.evaluation import BOOKMARKS, store_metric

    out = tmp_path_factory.mktemp("fg_run") / "run"
    assert main(["run", str(short_log), "--out", str(out), "--no-progress"]) == 0
    stamp = open_run(out).table("frames").column("stamp_ns")[5].as_py()
    marks = pa.Table.from_pylist(
        [
            {
                "frame_index": 5,
                "stamp_ns": stamp,
                "kind": "missed_object",
                "metric": "detection",
                "algorithm": "tracker",
                "detail": "car 12.3 m ahead not detected",
                "severity": 1.0,
            }
        ],
        schema=BOOKMARKS,
    )
    store_metric(out, record={"name": "detection", "version": "1"}, tables={"bookmarks": marks})
    return out


@pytest.fixture(scope="session")
def luminar_run(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference perception (clusters → tracker) over the real Luminar bag of
    ``../shared/data``, as ``redrive run`` writes it: its clouds' header stamps (2020-03-12) are
    237.8 days before their log times (2020-11-04), and nothing in the bag connects their frame
    ``luminar_lidar`` to ``base_link``."""
    from redrive.cli.main import main

    bag = shared_data / "rosbag1_real" / "embag_luminar_test.bag"
    out = tmp_path_factory.mktemp("fg_luminar") / "luminar"
    args = ["run", str(bag), "--out", str(out), "--no-progress"]
    args += ["--perception", "cluster-detector", "--perception", "kalman-tracker"]
    assert main(args) == 0
    return out
