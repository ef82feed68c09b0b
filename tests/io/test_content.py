"""What a log holds beside its messages is asked of its reader's capabilities (redrive.io.content)."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import pytest

from redrive.errors import LogError
from redrive.io import open_log
from redrive.io.content import fingerprint_log, log_road_map, log_scenario
from redrive.io.mcap.metadata import MAP_METADATA, SCENARIO_METADATA
from redrive.io.mcap.writer import McapWriter
from redrive.testing.demo_log import write_demo_bag


def test_an_mcap_without_records_has_the_capability_and_no_map(tmp_path: Path) -> None:
    path = tmp_path / "plain.mcap"
    with McapWriter(path):
        pass
    with open_log(path) as log:
        assert log.capabilities.road_map
        assert log.capabilities.scenario
        assert log_road_map(log) is None
        assert log_scenario(log) is None


def test_unreadable_records_are_absent_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "bad.mcap"
    with McapWriter(path) as writer:
        writer.add_metadata(MAP_METADATA, {"road_map": "{not json"})
        writer.add_metadata(SCENARIO_METADATA, {"name": "x", "seed": "three"})
    with caplog.at_level(logging.WARNING), open_log(path) as log:
        assert log_road_map(log) is None
        assert log_scenario(log) is None
    assert "road map is unreadable" in caplog.text
    assert "scenario record is unreadable" in caplog.text


class _Claims:
    """A reader that declares a road map but has no road_map()."""

    path = Path("claims.log")
    format = "claims"

    def __init__(self, log: object) -> None:
        self.capabilities = replace(log.capabilities, road_map=True)  # type: ignore[attr-defined]


def test_a_declared_capability_without_its_method_is_an_error(tmp_path: Path) -> None:
    with open_log(write_demo_bag(tmp_path / "demo.bag")) as log:
        claims = _Claims(log)
    with pytest.raises(LogError, match="declares the road_map capability"):
        log_road_map(claims)  # type: ignore[arg-type]


def test_the_fingerprint_of_a_directory_hashes_names_and_bytes(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "x.bin").write_bytes(b"1234")
    first = fingerprint_log(tmp_path / "a")
    assert first.size_bytes == 4
    assert first.path == str((tmp_path / "a").resolve())
    (tmp_path / "a" / "x.bin").rename(tmp_path / "a" / "y.bin")
    assert fingerprint_log(tmp_path / "a").sha256 != first.sha256
