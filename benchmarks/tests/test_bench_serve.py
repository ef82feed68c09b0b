"""``python -m benchmarks serve``: its arithmetic, and (slow) one whole run on the 1-s log — every
channel's count is what the stream holds, and what arrived is no more than that."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.cli import build_parser
from benchmarks.serve import ChannelCount, ServeBenchResult


def _result(*channels: ChannelCount) -> ServeBenchResult:
    return ServeBenchResult(
        log=Path("urban.mcap"),
        log_span_s=20.0,
        rate=1.0,
        channels=channels,
        server_sent=None,
        play_wall_s=20.0,
        lag_p50_ms=1.0,
        lag_p99_ms=2.0,
        lag_max_ms=3.0,
        server_cpu_s=5.0,
        client_cpu_s=1.0,
        load_before=1.0,
        load_after=1.0,
    )


def test_dropped_frames_count_the_cloud_and_image_channels_only() -> None:
    result = _result(
        ChannelCount(
            topic="/lidar_top", schema="sensor_msgs/msg/PointCloud2", sent=200, received=198
        ),
        ChannelCount(
            topic="/foxglove/cam", schema="foxglove.CompressedImage", sent=200, received=199
        ),
        ChannelCount(topic="/imu", schema="sensor_msgs/msg/Imu", sent=2000, received=1990),
    )
    assert (result.sent, result.received, result.dropped) == (2400, 2387, 13)
    assert (result.frames, result.dropped_frames) == (400, 3)
    assert result.server_cpu_percent == pytest.approx(25.0)
    out = result.to_json()
    assert out["dropped_frames"] == 3
    assert out["frames_received_ratio"] == pytest.approx(397 / 400)
    assert out["realtime_factor"] == pytest.approx(1.0)
    assert out["channels"][2] == {
        "topic": "/imu", "schema": "sensor_msgs/msg/Imu", "sent": 2000, "received": 1990,
        "dropped": 10,
    }  # fmt: skip


@pytest.mark.slow
def test_bench_serve_of_a_short_log(short_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from redrive.interop.stream import open_scene_stream

    args = build_parser().parse_args(["serve", "--log", str(short_log), "--rate", "4", "--json"])
    assert args.func(args) == 0
    out = json.loads(capsys.readouterr().out)
    with open_scene_stream(short_log) as stream:
        counts: dict[str, int] = {}
        for m in stream.messages():
            counts[m.topic] = counts.get(m.topic, 0) + 1
    assert {c["topic"]: c["sent"] for c in out["channels"]} == counts
    assert all(0 <= c["received"] <= c["sent"] for c in out["channels"])
    assert out["received"] > 0
    assert out["server_sent"] == sum(counts.values())
