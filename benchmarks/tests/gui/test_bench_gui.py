"""``python -m benchmarks gui`` on tiny sizes: it runs, and its JSON has every figure.  No speed is
asserted (a benchmark is not a timed unit test)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyqtgraph")

from benchmarks.cli import main
from benchmarks.cli.gui import _print_report
from benchmarks.gui import bench_gui, bench_log
from redrive.io import open_log


def test_help_has_examples(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["gui", "--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    assert "examples:" in text
    assert "xvfb-run" in text
    assert "--skip-big" in text


def test_bench_log_is_cached_and_readable(tmp_path: Path) -> None:
    first = bench_log(tmp_path, frames=3, points=2_000, boxes=5, image_size=(64, 48))
    again = bench_log(tmp_path, frames=3, points=2_000, boxes=5, image_size=(64, 48))
    assert first.written
    assert not again.written
    assert again.path == first.path
    assert again.file_bytes == first.file_bytes
    with open_log(first.path) as log:
        assert log.topics["/lidar_top"].count == 3
        assert log.topics["/ground_truth/objects"].msgtype.endswith("GroundTruthObjectArray")
        assert log.topics["/camera_front/image_raw"].count == 3


@pytest.mark.slow  # ~30 s: the whole `python -m benchmarks gui`; `make bench` runs it
def test_bench_gui_json(qapp: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    del qapp  # pytest-qt's QApplication; bench_gui uses it
    lines: list[str] = []
    result = bench_gui(
        seconds=1.0,
        cache=tmp_path / "cache",
        big=True,
        big_bytes=30_000_000,
        open_repeats=1,
        points=5_000,
        frames=12,
        progress=lines.append,
    )
    out = json.loads(json.dumps(result.to_json(), allow_nan=False))
    assert lines
    assert set(out) >= {"machine", "playback", "ceilings", "open", "targets", "verdicts"}
    measures = {(p["view"], p["mode"]) for p in out["playback"]}
    assert measures == {
        ("3d", "flat out"),
        ("3d", "timer 8x"),
        ("2d", "flat out"),
        ("2d", "timer 8x"),
    }
    for p in out["playback"]:
        assert p["fps"] > 0
        assert p["frames_painted"] > 0
        for stage in ("loader_read", "loader_build", "gui_show", "window_update"):
            assert p["timings"][stage]["count"] > 0
        assert p["cpu_ms_per_frame"]["gui_thread"] is not None
    timer = next(p for p in out["playback"] if p["mode"] == "timer 8x")
    assert timer["log_frames_per_s"] > 0
    assert timer["skipped_ticks"] is not None
    assert {c["name"] for c in out["ceilings"]} == {"gl_scatter", "raster_image", "camera_image"}
    assert all(c["fps"] > 0 for c in out["ceilings"])
    assert out["open"]["first_frame_s"][0] > 0
    assert out["open"]["first_paint_s"][0] >= out["open"]["first_frame_s"][0]
    assert out["open"]["full_read_s"] > 0
    assert out["open"]["log"]["file_bytes"] > 20_000_000
    assert set(out["verdicts"]) == {"fps_3d", "fps_2d", "open_first_frame_s"}
    assert out["verdicts"]["fps_3d"]["of_ceiling"] > 0
    _print_report(result)
    table = capsys.readouterr().out
    assert "window 3D, flat out" in table
    assert "open → first frame" in table
    # A second run finds both logs in the cache.
    again = bench_gui(
        seconds=0.5,
        cache=tmp_path / "cache",
        big=False,
        points=5_000,
        frames=12,
        timer_mode=False,
    )
    assert not again.playback_log.written
    assert again.open is None
    assert [p.mode for p in again.playback] == ["flat out", "flat out"]
