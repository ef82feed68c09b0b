"""redrive repair / repair_log: a damaged log's intact messages into a valid, indexed MCAP."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from mcap.reader import make_reader

from redrive.cli.main import main
from redrive.errors import LogDamagedError, LogError
from redrive.io import open_log
from redrive.io.repair import repair_log

from ._damage_helpers import write_string_mcap


def _mcap_messages(path: Path) -> list[tuple[str, int, bytes]]:
    with path.open("rb") as fh:
        reader = make_reader(fh)
        assert reader.get_summary() is not None  # indexed: it has a summary
        return [(c.topic, m.log_time, bytes(m.data)) for _, c, m in reader.iter_messages()]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_repair_a_cut_mcap_keeps_every_complete_chunk(tmp_path: Path, compression: str) -> None:
    src = tmp_path / "log.mcap"
    original = write_string_mcap(src, compression=compression)
    data = src.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    stats = repair_log(cut, tmp_path / "fixed.mcap")
    got = _mcap_messages(tmp_path / "fixed.mcap")
    assert 0 < len(got) == stats.messages_written < len(original)
    assert got == original[: len(got)]  # a prefix of the log, byte for byte
    assert any(d.stop_byte == len(data) * 2 // 3 for d in stats.damage)
    with open_log(tmp_path / "fixed.mcap") as log:  # strict: the repaired log is intact
        assert sum(1 for _ in log.messages()) == len(got)
        assert log.damage_report == ()  # type: ignore[attr-defined]


def test_repair_a_corrupt_chunk_counts_what_it_lost(tmp_path: Path) -> None:
    src = tmp_path / "log.mcap"
    original = write_string_mcap(src)
    with src.open("rb") as fh:
        chunk = make_reader(fh).get_summary().chunk_indexes[3]  # type: ignore[union-attr]
    data = bytearray(src.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle : middle + 8] = bytes(b ^ 0x5A for b in data[middle : middle + 8])
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with open_log(bad) as log, pytest.raises(LogDamagedError, match=r"bad\.mcap: damaged at bytes"):
        for _ in log.messages():
            pass
    stats = repair_log(bad, tmp_path / "fixed.mcap")
    (damage,) = stats.damage
    assert damage.start_byte == chunk.chunk_start_offset
    assert damage.messages_lost == len(original) - stats.messages_written > 0
    got = _mcap_messages(tmp_path / "fixed.mcap")
    assert set(got) < set(original)


def test_repair_cli_exit_status_and_output(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "log.mcap"
    write_string_mcap(src, chunked=False, compression="none")
    assert main(["repair", str(src), "-o", str(tmp_path / "same.mcap")]) == 0
    assert "nothing was damaged" in capsys.readouterr().out
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(src.read_bytes()[:5000])
    assert main(["repair", str(cut), "-o", str(tmp_path / "fixed.mcap")]) == 5
    captured = capsys.readouterr()
    assert "wrote" in captured.out
    assert "lost:" in captured.err
    assert "Traceback" not in captured.out + captured.err
    with pytest.raises(LogError, match=r"ending in \.mcap"):
        repair_log(cut, tmp_path / "fixed.bag")


def test_repair_a_bag_keeps_its_ros1_definitions(shared_data: Path, tmp_path: Path) -> None:
    src = shared_data / "rosbag1_real/robot_localization_test2_jackal.bag"  # bz2 chunks
    data = src.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) * 4 // 5])
    stats = repair_log(cut, tmp_path / "fixed.mcap")
    assert stats.messages_written > 0
    assert stats.damage
    with open_log(tmp_path / "fixed.mcap") as log:
        assert {t.encoding for t in log.topics.values()} == {"ros1"}
        messages = list(log.messages())
        assert len(messages) == stats.messages_written
        log.deserialize(messages[-1])  # its definition came along


def test_a_cut_ros2_database_is_read_row_by_row(shared_data: Path, tmp_path: Path) -> None:
    src = shared_data / "rosbag_fixtures/evo_tf_example_ros2"
    bag = tmp_path / "bag"
    shutil.copytree(src, bag)
    db = next(bag.glob("*.db3"))
    db.write_bytes(db.read_bytes()[:-1342])  # its last page is gone: rosbags stops at 500
    with open_log(bag) as log, pytest.raises(LogDamagedError, match="sqlite3 storage") as info:
        for _ in log.messages():
            pass
    with open_log(bag, strict=False) as log:
        read = list(log.messages())
        (damage,) = log.damage_report  # type: ignore[attr-defined]
    assert info.value.messages_read < len(read) < 518
    assert damage.messages_lost == 518 - len(read)
    stats = repair_log(bag, tmp_path / "fixed.mcap")
    assert stats.messages_written == len(read)
