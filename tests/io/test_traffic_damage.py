"""Cut or damaged recorded-traffic files end in a LogError (or MapError for a map) that names
the file — never in another exception — whatever the byte they are damaged at."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import LogError, MapError
from redrive.io import open_log
from redrive.io.content import log_road_map
from redrive.io.datasets.tfrecord import write_tfrecord

pytestmark = pytest.mark.shared_data

_OFFSETS = np.random.default_rng(34).uniform(0.0, 1.0, size=6)


def _read_all(path: Path) -> None:
    with open_log(path) as log:
        for _ in log.messages():
            pass
        log_road_map(log)


@pytest.mark.parametrize("fraction", _OFFSETS)
def test_a_cut_womd_file(shared_data: Path, tmp_path: Path, fraction: float) -> None:
    source = shared_data / "womd" / "motion_data_one_scenario.tfrecord"
    if not source.is_file():
        pytest.skip("no WOMD scenario")
    raw = source.read_bytes()
    cut = tmp_path / "cut.tfrecord"
    cut.write_bytes(raw[: max(1, int(fraction * len(raw)))])
    with pytest.raises(LogError, match=r"cut\.tfrecord"):
        _read_all(cut)


def test_a_record_with_good_crcs_but_no_scenario_in_it(tmp_path: Path) -> None:
    path = tmp_path / "noise.tfrecord"
    write_tfrecord(path, [np.random.default_rng(1).bytes(4000)])
    with pytest.raises(LogError, match=r"noise\.tfrecord"):
        _read_all(path)


@pytest.mark.parametrize("fraction", _OFFSETS)
def test_a_cut_commonroad_file(shared_data: Path, tmp_path: Path, fraction: float) -> None:
    pytest.importorskip("commonroad.common.reader.file_reader_xml")
    source = shared_data / "commonroad" / "USA_Peach-4_8_T-1.xml"
    if not source.is_file():
        pytest.skip("no CommonRoad scenario")
    raw = source.read_bytes()
    cut = tmp_path / "cut.xml"
    cut.write_bytes(raw[: max(200, int(fraction * len(raw)))])
    with pytest.raises(LogError, match=r"cut\.xml"):
        _read_all(cut)


@pytest.mark.parametrize(
    "name",
    [
        "city_SE3_egovehicle.feather",
        "annotations.feather",
        "calibration/egovehicle_SE3_sensor.feather",
        "map/log_map_archive_*.json",
    ],
)
@pytest.mark.parametrize("fraction", _OFFSETS[:3])
def test_a_cut_av2_file(shared_data: Path, tmp_path: Path, name: str, fraction: float) -> None:
    source = shared_data / "av2_sensor_val" / "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"
    if not source.is_dir():
        pytest.skip("no AV2 log")
    log = Path(shutil.copytree(source, tmp_path / source.name))
    (path,) = log.glob(name)
    raw = path.read_bytes()
    path.chmod(0o644)
    path.write_bytes(raw[: int(fraction * len(raw))])
    with pytest.raises((LogError, MapError), match=path.name.replace(".", r"\.")):
        _read_all(log)
