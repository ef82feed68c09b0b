"""A ROS 1 bag chunk whose header lies about its size and an MCAP of only its magic (issue 37):
every command says so, with the documented exit status; a lying size loses no message."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.errors import LogDamagedError, LogError
from redrive.io import open_log
from redrive.io.rosbag1.reader import Ros1BagReader
from tests.hostile.generator import (
    MCAP_MAGIC,
    _mcap_records,
    first_bag_chunk_size,
    lying_bag_chunk,
    unindexed_bag,
)
from tests.io._damage_helpers import write_string_bag, write_string_mcap

JACKAL = "rosbag1_real/robot_localization_test2_jackal.bag"


def _all(path: Path) -> list[tuple[str, int, bytes]]:
    with open_log(path, strict=False) as log:
        return [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages()]


@pytest.fixture
def lying_bag(shared_data: Path, tmp_path: Path) -> tuple[Path, Path]:
    """The real Jackal bag (bz2 chunks) and a copy whose first chunk claims 0xFFFFFF00 bytes."""
    src = tmp_path / "jackal.bag"
    shutil.copyfile(shared_data / JACKAL, src)
    lying = tmp_path / "chunk_lies_size.bag"
    lying.write_bytes(lying_bag_chunk(src.read_bytes()))
    return src, lying


def test_a_chunk_claiming_4_gib_is_damage_that_loses_nothing(
    lying_bag: tuple[Path, Path],
) -> None:
    src, lying = lying_bag
    _, chunk_at = first_bag_chunk_size(lying.read_bytes())
    with Ros1BagReader(lying, strict=False) as log:
        (damage,) = log.damage_report  # found at open: `info` does not decompress
        assert damage.start_byte == chunk_at
        assert damage.messages_lost == 0
        assert "declares 4294967040 bytes uncompressed" in damage.what
    assert _all(lying) == _all(src)  # every message read, from the chunk's data


@pytest.mark.parametrize(
    ("argv", "status", "said"),
    [
        (["info", "{log}"], 5, "declares 4294967040 bytes"),
        (["info", "--json", "{log}"], 5, "declares 4294967040 bytes"),
        (["info", "--strict", "{log}"], 1, "--strict refuses"),
        (["convert", "{log}", "{tmp}/c.mcap"], 1, "--skip-damaged"),
        (["convert", "--skip-damaged", "{log}", "{tmp}/c.mcap"], 0, "6121 messages"),
        (["repair", "{log}", "-o", "{tmp}/r.mcap"], 5, "6121 messages"),
    ],
)
def test_every_command_reports_the_lying_size(
    lying_bag: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    *,
    argv: list[str],
    status: int,
    said: str,
) -> None:
    _, lying = lying_bag
    assert main([a.format(log=lying, tmp=tmp_path) for a in argv]) == status
    out = capsys.readouterr()
    assert said in " ".join((out.out + out.err).split())


def test_redrive_run_warns_of_the_lying_size(
    lying_bag: tuple[Path, Path], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    _, lying = lying_bag
    main(["run", str(lying), "--out", str(tmp_path / "run"), "--no-progress"])
    assert any("declares 4294967040 bytes" in r.getMessage() for r in caplog.records)


def test_a_small_lie_is_found_when_the_chunk_is_decompressed(tmp_path: Path) -> None:
    """A compressed chunk claiming one byte more than it holds is within the budget: found when
    it is read (all its messages kept; strict reading stops after them)."""
    src = tmp_path / "strings.bag"
    write_string_bag(src, messages=100, compression="bz2")
    data = src.read_bytes()
    size, chunk_at = first_bag_chunk_size(data)
    lying = tmp_path / "lying.bag"
    lying.write_bytes(lying_bag_chunk(data, size=size + 1))
    with Ros1BagReader(lying, strict=False) as log:
        assert log.damage_report == ()
        got = [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages()]
        (damage,) = log.damage_report
    assert got == _all(src)
    assert damage.start_byte == chunk_at
    assert damage.messages_lost == 0
    assert f"says it holds {size + 1} bytes uncompressed, but its data decompress to {size}" in (
        damage.what
    )
    with Ros1BagReader(lying, strict=True) as log, pytest.raises(LogDamagedError):
        list(log.messages())


@pytest.mark.parametrize("compression", ["none", "bz2"])
def test_the_sequential_walk_finds_the_lie_too(tmp_path: Path, compression: str) -> None:
    src = tmp_path / "strings.bag"
    write_string_bag(src, messages=100, compression=compression)
    data = unindexed_bag(src.read_bytes())
    size, chunk_at = first_bag_chunk_size(data)
    lying = tmp_path / "lying.bag"
    lying.write_bytes(lying_bag_chunk(data, size=size + 7))
    with Ros1BagReader(lying, strict=False) as log:
        assert not log.indexed
        lies = [d for d in log.damage_report if "says it holds" in d.what]
    assert [(d.start_byte, d.messages_lost) for d in lies] == [(chunk_at, 0)]
    assert _all(lying) == _all(src)


def test_an_intact_bag_has_no_size_damage(tmp_path: Path) -> None:
    for compression in ("none", "bz2", "lz4"):
        src = tmp_path / f"{compression}.bag"
        write_string_bag(src, messages=100, compression=compression)
        for bag in (src, tmp_path / "walked.bag"):
            if bag != src:
                bag.write_bytes(unindexed_bag(src.read_bytes()))
            with Ros1BagReader(bag, strict=True) as log:
                list(log.messages())
                assert [d for d in log.damage_report if "size" in d.what] == []


def test_an_mcap_of_only_its_magic_is_an_empty_log(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "magic_only.mcap"
    path.write_bytes(MCAP_MAGIC)
    with pytest.raises(LogError, match="only the 8-byte MCAP magic"):
        open_log(path, strict=False)
    for argv in (
        ["info", str(path)],
        ["info", "--json", str(path)],
        ["convert", str(path), str(tmp_path / "c.mcap")],
        ["convert", "--skip-damaged", str(path), str(tmp_path / "c.mcap")],
        ["repair", str(path), "-o", str(tmp_path / "r.mcap")],
        ["run", str(path), "--out", str(tmp_path / "run"), "--no-progress"],
    ):
        assert main(argv) == 1, argv
        assert "an empty log" in capsys.readouterr().err
    assert not (tmp_path / "c.mcap").exists()


def test_convert_refuses_any_damage_unless_told_to_skip_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An MCAP cut right after a chunk loses no message but its summary: `info` says it is
    damaged (5), so `convert` refuses it (1) as `info --strict` does, and `--skip-damaged`
    converts every message."""
    src = tmp_path / "log.mcap"
    write_string_mcap(src, messages=50, compression="zstd")
    data = src.read_bytes()
    cut = tmp_path / "cut.mcap"
    data_end = next(at for at, op, _ in _mcap_records(data) if op == 0x0F)
    cut.write_bytes(data[:data_end])  # every chunk, no data end record, no summary
    with open_log(cut, strict=False) as log:
        assert log.damage_report
        assert all(d.messages_lost == 0 for d in log.damage_report)
    out = tmp_path / "converted.mcap"
    assert main(["convert", str(cut), str(out)]) == 1
    assert "--skip-damaged" in capsys.readouterr().err
    assert not out.exists()
    assert main(["convert", "--skip-damaged", str(cut), str(out)]) == 0
    assert "50 messages" in capsys.readouterr().out
