"""`python -m benchmarks record`: its arithmetic on fixed numbers, the CPU of a real process tree, and one
short run against `rosbag record` whose numbers are those of the files it wrote (no timing asserts:
the targets are checked by the benchmark, BENCHMARKS.md)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.record import (
    KITTI_BAG,
    RecordResult,
    TopicCount,
    bench_record,
    compare_counts,
    cpu_by_process,
    tree_cpu_s,
)
from redrive.errors import ConfigError
from tests.live.conftest import ros1_missing

ros1 = pytest.mark.skipif(ros1_missing() is not None, reason=str(ros1_missing()))


def _result(topics: list[TopicCount], reference_cpu_s: float = 2.0) -> RecordResult:
    return RecordResult(
        bag="b.bag", rate=14.0, compression="none", window_s=4.0, topics=topics,
        reference_cpu_s=reference_cpu_s, redrive_cpu_s=3.0, reference_cpu_total_s=2.5,
        redrive_cpu_total_s=4.0, redrive_processes=4, redrive_cpu_by_process={"recorder": 1.0},
        cpus=2, load_before=(1.0, 1.0, 1.0), load_after=(2.0, 2.0, 2.0),
    )  # fmt: skip


def test_counts_lost_and_ratio() -> None:
    rows = compare_counts(
        {"/a": (10, 100), "/b": (5, 50)}, {"/a": (8, 80), "/b": (7, 70), "/c": (1, 1)}
    )
    assert [(r.topic, r.reference, r.redrive, r.lost) for r in rows] == [
        ("/a", 10, 8, 2), ("/b", 5, 7, 0), ("/c", 0, 1, 0),
    ]  # fmt: skip
    r = _result(rows)
    assert r.lost == 2
    assert r.cpu_ratio == pytest.approx(1.5)
    assert r.hz(rows[0]) == pytest.approx(2.5)
    out = json.loads(json.dumps(r.to_json()))
    assert out["lost"] == 2
    assert out["topics"][0] == {
        "topic": "/a", "reference": 10, "redrive": 8, "reference_bytes": 100, "redrive_bytes": 80,
        "lost": 2,
    }  # fmt: skip
    assert _result(rows, reference_cpu_s=0.0).cpu_ratio == float("inf")


def test_cpu_of_a_process_tree_counts_its_children() -> None:
    """A parent that waits on a child which burns a fixed amount of work: the tree's CPU holds the
    child's own, and so does the sum by process."""
    burn = "import sys; sum(i * i for i in range(3_000_000)); print('done', flush=True); sys.stdin.read()"
    parent = subprocess.Popen(
        [sys.executable, "-c",
         "import subprocess, sys; c = subprocess.Popen([sys.executable, '-c', sys.argv[1]], "
         "stdin=subprocess.PIPE); print(c.pid, flush=True); sys.stdin.read(); c.stdin.close(); c.wait()",
         burn],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        import psutil

        assert parent.stdout is not None
        lines = {parent.stdout.readline().strip(), parent.stdout.readline().strip()}
        assert "done" in lines  # the child's line: its work is over, it waits on stdin
        child = psutil.Process(int((lines - {"done"}).pop()))
        own = child.cpu_times()
        assert tree_cpu_s(parent.pid) >= own.user + own.system
        parts = cpu_by_process(parent.pid)
        assert "recorder" in parts
        assert sum(parts.values()) >= own.user + own.system
    finally:
        assert parent.stdin is not None
        parent.stdin.close()
        parent.wait(timeout=30)
    assert tree_cpu_s(parent.pid) == 0.0  # gone


def test_refuses_a_missing_bag(tmp_path: Path) -> None:
    if ros1_missing() is not None:
        pytest.skip(str(ros1_missing()))
    with pytest.raises(ConfigError, match="give --data"):
        bench_record(data_dir=tmp_path, window_s=1.0)


@ros1
@pytest.mark.shared_data
def test_a_short_run_reports_what_the_files_hold(shared_data: Path, tmp_path: Path) -> None:
    from mcap.reader import make_reader
    from rosbags.rosbag1 import Reader

    from redrive.io import open_log

    topic = "/kitti/camera_color_left/image_raw/compressed"  # one scraper: a quicker start
    r = bench_record(
        data_dir=shared_data, window_s=0.5, settle_s=0.3, topics=[topic], workdir=tmp_path
    )
    want: dict[str, int] = {}
    with Reader(tmp_path / "reference.bag") as bag:
        for conn, _, _ in bag.messages():
            want[conn.topic] = want.get(conn.topic, 0) + 1
    got: dict[str, int] = {}
    with open_log(tmp_path / "redrive.mcap") as log:
        for m in log.messages():
            got[m.topic] = got.get(m.topic, 0) + 1
    topics = {topic}
    assert {t.topic for t in r.topics} == topics
    assert {t.topic: t.reference for t in r.topics} == want
    assert {t.topic: t.redrive for t in r.topics} == {t: got.get(t, 0) for t in topics}
    assert r.lost == sum(max(want[t] - got.get(t, 0), 0) for t in topics)
    assert all(n > 0 for n in want.values())
    assert r.reference_cpu_s > 0
    assert r.redrive_cpu_s > 0
    assert r.cpu_ratio == pytest.approx(r.redrive_cpu_s / r.reference_cpu_s)
    assert r.redrive_processes == 2  # redrive live and the topic's scraper
    assert set(r.redrive_cpu_by_process) == {"recorder", *(f"scraper {t}" for t in topics)}
    assert r.bag.endswith(str(KITTI_BAG))
    # the default compression of bench record is none: every chunk of redrive's file says so
    with (tmp_path / "redrive.mcap").open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    assert r.redrive_chunks == {"none": len(summary.chunk_indexes)}
    mb = sum(t.redrive_bytes for t in r.topics) / 1e6
    assert r.cpu_per_mb[1] == pytest.approx(1e3 * r.redrive_cpu_s / mb)
