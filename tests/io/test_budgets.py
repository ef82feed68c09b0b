"""Decompression bombs and many channels (issue 37): chunks are read against a budget
(redrive.io.limits), what is over it is damage with the rest of the log read, and 65,535
channels (the most an MCAP's u16 ids allow) are summarised and converted in seconds."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.writer import Writer

from redrive.io.limits import DEFAULT_MAX_CHUNK_BYTES, MAX_CHUNK_ENV, max_chunk_bytes
from redrive.io.mcap.reader import McapFileReader
from redrive.io.rosbag1.reader import Ros1BagReader

from ._bomb_helpers import write_bomb_mcap
from ._damage_helpers import write_string_bag

_SRC = str(Path(__file__).resolve().parents[2] / "src")
_GIB = 1 << 30


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (_GIB, _GIB))


def _redrive(*args: str | Path, limit: bool = True) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": _SRC}
    return subprocess.run(
        [sys.executable, "-m", "redrive", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,  # a hang guard only
        check=False,
        env=env,
        preexec_fn=_limited if limit else None,
    )


@pytest.fixture(scope="module")
def bomb(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("bomb") / "bomb.mcap"
    size = write_bomb_mcap(path, zeros=2 * _GIB - 4096)
    assert size < 100_000  # a few KB on disk for 2 GiB in memory
    return path


@pytest.mark.parametrize("summary", [True, False], ids=["indexed", "scanned"])
def test_a_bomb_chunk_is_damage_and_its_first_messages_are_read(
    tmp_path: Path, summary: bool
) -> None:
    path = tmp_path / "bomb.mcap"
    write_bomb_mcap(path, zeros=2 * _GIB - 4096, summary=summary)
    with McapFileReader(path, strict=False) as log:
        got = list(log.messages())
        assert [m.topic for m in got] == ["/imu"] * 10
        (damage,) = log.damage_report
    assert "over the budget" in damage.what
    assert MAX_CHUNK_ENV in damage.what


def test_a_chunk_lying_about_its_size_is_damage(tmp_path: Path) -> None:
    path = tmp_path / "lie.mcap"
    write_bomb_mcap(path, zeros=2 * _GIB - 4096, declared=1 << 20)
    with McapFileReader(path, strict=False) as log:
        assert len(list(log.messages())) == 10
        (damage,) = log.damage_report
    assert "the zstd frame declares" in damage.what


def test_zeros_within_the_budget_end_the_chunk_at_once(tmp_path: Path) -> None:
    path = tmp_path / "zeros.mcap"
    write_bomb_mcap(path, zeros=64 << 20)
    with McapFileReader(path, strict=False) as log:
        assert len(list(log.messages())) == 10
        (damage,) = log.damage_report
    assert "opcode 0x00" in damage.what


def test_the_budget_is_a_parameter_and_an_environment_variable(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "zeros.mcap"
    write_bomb_mcap(path, zeros=1 << 20)
    with McapFileReader(path, strict=False, max_chunk_bytes=4096) as log:
        assert len(list(log.messages())) == 10
        assert "over the budget of 4096" in log.damage_report[0].what
    assert max_chunk_bytes() == DEFAULT_MAX_CHUNK_BYTES
    monkeypatch.setenv(MAX_CHUNK_ENV, "512M")
    assert max_chunk_bytes() == 512 << 20
    monkeypatch.setenv(MAX_CHUNK_ENV, "1GiB")
    assert max_chunk_bytes() == _GIB


def test_a_bag_chunk_over_the_budget_is_damage(tmp_path: Path) -> None:
    path = tmp_path / "a.bag"
    write_string_bag(path, messages=200, compression="lz4")
    with Ros1BagReader(path, strict=False) as log:
        assert len(list(log.messages())) == 200
    with Ros1BagReader(path, strict=False, max_chunk_bytes=64) as log:
        assert list(log.messages()) == []
        assert log.damage_report
        # each chunk: its header declares more than the budget (found at open, as `info`
        # says), and its data expand past it (found reading, its messages lost)
        assert all(
            "expands past 64 bytes" in d.what or "over the budget of 64" in d.what
            for d in log.damage_report
        )
        assert any("expands past 64 bytes" in d.what for d in log.damage_report)


@pytest.mark.parametrize(
    ("argv", "status", "said"),
    [
        (["info", "{log}"], 5, "over the budget"),
        (["info", "--json", "{log}"], 5, ""),
        (["convert", "{log}", "{tmp}/c.mcap"], 1, "over the budget"),
        (["convert", "--skip-damaged", "{log}", "{tmp}/c.mcap"], 0, "10 messages"),
        (["repair", "{log}", "-o", "{tmp}/r.mcap"], 5, "over the budget"),
        # the Imu paces the frames (issue 35 item 11) but no reference stage reads an IMU
        (["run", "{log}", "--out", "{tmp}/run"], 1, "no stage of the pipeline can run"),
    ],
)
def test_commands_on_a_bomb_end_under_1_gib(
    bomb: Path, tmp_path: Path, argv: list[str], status: int, said: str
) -> None:
    done = _redrive(*(a.format(log=bomb, tmp=tmp_path) for a in argv))
    assert done.returncode == status, done.stderr[-2000:]
    assert "Traceback" not in done.stderr
    assert said in done.stdout + done.stderr
    if argv[:2] == ["info", "--json"]:
        report = json.loads(done.stdout)
        assert report["topics"][0]["count"] == 10
        assert "over the budget" in report["damage_report"][0]["what"]


def test_65535_channels_in_seconds(tmp_path: Path) -> None:
    path = tmp_path / "many.mcap"
    with path.open("wb") as fh:
        writer = Writer(fh)
        writer.start(profile="ros2", library="redrive tests")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        ids = [writer.register_channel(f"/t{i:05d}", "cdr", schema) for i in range(65535)]
        for k, cid in enumerate(ids[::1000]):
            t = 1_700_000_000_000_000_000 + k * 1000
            writer.add_message(cid, t, b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00", t)
        writer.finish()
    done = _redrive("info", "--json", path, limit=False)
    assert done.returncode == 0, done.stderr[-2000:]
    topics = json.loads(done.stdout)["topics"]
    assert len(topics) == 65535
    assert sum(t["count"] for t in topics) == 66
    done = _redrive("info", path, limit=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "/t65534" in done.stdout
    assert done.stdout.count("\n/t") == 65535
    done = _redrive("convert", path, tmp_path / "out.mcap", limit=False)
    assert done.returncode == 0, done.stderr[-2000:]
    with McapFileReader(tmp_path / "out.mcap") as log:
        assert len(list(log.messages())) == 66
