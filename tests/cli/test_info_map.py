"""``redrive info MAPFILE``: a map file's source, extent and element counts."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.maps.document import road_map_to_json
from redrive.sim.roadmap import road_map
from redrive.sim.roads import UrbanLayout, build_network


def test_info_of_the_av2_map(shared_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (path,) = (shared_data / "av2_sensor_val").glob("*/map/log_map_archive_*.json")
    assert main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["format"], info["lanes"], info["areas"], info["crosswalks"]) == (
        "av2",
        183,
        13,
        11,
    )
    assert info["source"] == f"av2:{path}"
    x0, y0, x1, y1 = info["extent_m"]
    assert 400 < x1 - x0 < 600
    assert 300 < y1 - y0 < 500
    assert main(["info", str(path)]) == 0
    assert "lanes:     183 (163 vehicle, 20 bike)" in capsys.readouterr().out


def test_info_of_the_lanelet2_map(shared_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("lanelet2")
    path = shared_data / "lanelet2_maps" / "mapping_example.osm"
    assert main(["info", str(path), "--json", "--map-origin", "49.0,8.4"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["format"], info["lanes"], info["traffic_lights"]) == ("lanelet2", 416, 6)
    assert "origin_note" not in info
    assert main(["info", str(path)]) == 0  # no origin given: the first node's, said so
    out = capsys.readouterr().out
    assert "origin:    the map gives none: its first node" in out
    with pytest.raises(SystemExit) as usage:
        main(["info", str(path), "--map-origin", "91,8"])
    assert usage.value.code == 2
    assert "latitude must be in [-90, 90]" in capsys.readouterr().err


def test_info_of_a_run_map_and_a_damaged_map(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "map.json"
    path.write_text(json.dumps(road_map_to_json(road_map(build_network(UrbanLayout())))))
    assert main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["format"], info["lanes"], info["intersections"], info["stop_lines"]) == (
        "redrive",
        20,
        1,
        4,
    )
    cut = tmp_path / "log_map_archive_cut.json"
    cut.write_text('{"lane_segments": {"1": {"id": 1, ')
    assert main(["info", str(cut)]) == 1
    assert "not complete JSON" in capsys.readouterr().err


def test_info_of_a_real_bag_converted_to_mcap_provides_no_road_map(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An MCAP reader can be asked for a map (a synth log's record), but the Embark bag
    converted to MCAP holds none: `info` must not say it provides one; a log with its map
    (the CommonRoad scenario) still does."""
    out = tmp_path / "lum.mcap"
    bag = shared_data / "rosbag1_real" / "embag_luminar_test.bag"
    assert main(["convert", str(bag), str(out)]) == 0
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["capabilities"]["road_map"] is False
    assert "map" not in info
    assert main(["info", str(out)]) == 0
    provides = next(
        line for line in capsys.readouterr().out.splitlines() if line.startswith("provides")
    )
    assert "road map" not in provides
    assert "ego pose" in provides
    scenario = shared_data / "commonroad" / "USA_US101-3_3_T-1.xml"
    assert main(["info", str(scenario)]) == 0
    assert "road map" in capsys.readouterr().out.splitlines()[2]  # path, format, provides
