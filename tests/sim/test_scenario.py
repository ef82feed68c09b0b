"""Scenario TOML loading and its errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.errors import ConfigError
from redrive.sim.roads import HighwayLayout, UrbanLayout
from redrive.sim.scenario import list_scenarios, load_scenario

EXPECTED = {"urban", "highway", "cut_in", "pedestrian_from_occlusion", "lead_vehicle_hard_brake", "red_light"}  # fmt: skip


def test_catalogue_lists_and_loads() -> None:
    assert set(list_scenarios()) == EXPECTED
    for name in list_scenarios():
        sc = load_scenario(name)
        assert sc.name == name
        assert sc.duration_s > 0
        assert set(sc.sensor_rates_hz) == {"lidar_top", "camera_front", "imu", "gnss", "odom", "lidar_2d"}  # fmt: skip
        assert sc.sensor_rates_hz["imu"] == 100.0
        assert sc.rig["lidar_top"]["xyz"] == [1.2, 0.0, 1.9]
    assert isinstance(load_scenario("urban").road, UrbanLayout)
    assert isinstance(load_scenario("highway").road, HighwayLayout)
    cut = load_scenario("cut_in").agents[0]
    assert cut.lane_change_route == "forward_1"


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "mine.toml"
    path.write_text(text, encoding="utf-8")
    return path


MINIMAL = """
duration_s = 3.0
[ego]
route = "west_east_0"
"""


def test_minimal_file_by_path(tmp_path: Path) -> None:
    sc = load_scenario(_write(tmp_path, MINIMAL))
    assert sc.name == "mine"
    assert sc.ego.set_speed_mps == 12.0
    assert sc.agents == ()


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("colour = 3\n" + MINIMAL, "colour"),
        (MINIMAL + "set_sped_mps = 3\n", "ego.set_sped_mps"),
        (
            MINIMAL + "[[agents]]\nkind = 'vehicle'\nroute = 'west_east_0'\nspeed = 3\n",
            "agents[0].speed",
        ),
        (MINIMAL + "[[agents]]\nkind = 'bus'\nroute = 'west_east_0'\n", "agents[0].kind"),
        (MINIMAL + "[[agents]]\nkind = 'vehicle'\nroute = 'nowhere'\n", "agents[0].route"),
        (MINIMAL.replace("3.0", "'long'"), "duration_s"),
        (MINIMAL.replace("3.0", "-1.0"), "duration_s"),
        (MINIMAL.replace("west_east_0", "forward_9"), "ego.route"),
        (MINIMAL + "[road]\nlayout = 'maze'\n", "road.layout"),
        (MINIMAL + "[lights]\ngreen_s = 0.0\n", "lights"),
        (MINIMAL + "[rig.cam]\nrate_hz = 0\n", "rig.cam.rate_hz"),
        ("duration_s = 3.0\n", "ego"),
    ],
)
def test_bad_values_name_file_and_key(tmp_path: Path, text: str, key: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert str(path) in msg
    assert f"'{key}'" in msg


def test_bad_toml_and_unknown_names(tmp_path: Path) -> None:
    path = _write(tmp_path, "duration_s = = 3\n")
    with pytest.raises(ConfigError, match="not valid TOML") as info:
        load_scenario(path)
    assert str(path) in str(info.value)
    with pytest.raises(ConfigError, match="urban"):
        load_scenario("no_such_scenario")
    with pytest.raises(ConfigError, match="no such scenario file"):
        load_scenario(tmp_path / "missing.toml")
