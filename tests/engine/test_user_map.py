"""``redrive run LOG --map FILE``: a ROS bag plus the real Lanelet2 map (Karlsruhe), placed
through the log's ``map`` frame, its tf, or a given origin; stored in the run and named in the
manifest; the map metrics computed on it; damaged maps and ``--no-map``."""

from __future__ import annotations

import hashlib
import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest

from redrive.cli.main import main
from redrive.errors import MapError
from redrive.maps.files import read_map_file
from redrive.maps.index import RoadMapIndex
from redrive.results import open_run
from redrive.types import RoadMap
from tests._map_drive import DRIVE_LANES, drive_poses, write_drive_bag

pytest.importorskip("lanelet2")

ORIGIN = (49.0, 8.4)  # the origin the Lanelet2 examples load this map with


@pytest.fixture(scope="module")
def osm(shared_data: Path) -> Path:
    return shared_data / "lanelet2_maps" / "mapping_example.osm"


@pytest.fixture(scope="module")
def road(osm: Path) -> RoadMap:
    return read_map_file(osm, origin_lat_lon=ORIGIN)


def _run(
    log: Path, out: Path, *extra: str, role: str = "planning", alg: str = "idm-planner"
) -> int:
    return main(["run", str(log), f"--{role}", alg, "--out", str(out), "--no-progress", *extra])


def _lanes_driven(run_dir: Path) -> list[str | None]:
    run = open_run(run_dir)
    road_map = run.road_map()
    assert road_map is not None
    ego = run.ego()
    states = [ego[k] for k in sorted(ego)]
    xy = np.array([s.position[:2] for s in states])
    yaw = np.array([s.heading_rad for s in states])
    return RoadMapIndex(road_map, lane_kinds={"vehicle"}).lane_of_pose(xy, yaw)


def test_a_drive_through_the_lanelet2_map_finds_its_lane_on_every_frame(
    osm: Path, road: RoadMap, tmp_path: Path
) -> None:
    """The must-show: a bag whose ego drives along a lanelet chain of the Karlsruhe map (poses in
    `map`), run with --map: the map is stored, the manifest names it, every frame's pose finds
    its lane (in the chain, in order) and the map metrics are computed, not skipped."""
    poses = drive_poses(road, seconds=12.0)
    bag = write_drive_bag(tmp_path / "drive.bag", poses, frame="map")
    out = tmp_path / "run"
    assert _run(bag, out, "--map", str(osm), "--map-origin", "49.0,8.4") == 0
    manifest = json.loads((out / "manifest.json").read_text())
    entry = manifest["map"]
    assert entry["from"] == "--map"
    assert entry["path"] == str(osm.resolve())
    assert entry["format"] == "lanelet2"
    assert entry["sha256"] == hashlib.sha256(osm.read_bytes()).hexdigest()
    assert entry["origin_lat_lon"] == [49.0, 8.4]
    assert entry["alignment"]["method"] == "log map frame"
    stored = open_run(out).road_map()
    assert stored is not None
    assert len(stored.lanes) == len(road.lanes) == 416
    lanes = _lanes_driven(out)
    assert len(lanes) == len(poses) == 120
    assert all(lane in DRIVE_LANES for lane in lanes), lanes
    order = [DRIVE_LANES.index(lane) for lane in lanes if lane is not None]
    assert order == sorted(order)  # along the chain, never back
    assert order[0] == 0
    assert order[-1] >= 2
    # the map metrics, evaluated later with no flag: computed on the stored map
    assert main(["evaluate", str(out), "--metric", "drivable_area", "--metric",
                 "driving_direction", "--metric", "speed_limit"]) == 0  # fmt: skip
    from redrive.results.evaluation import read_evaluation

    values = {
        (r["metric"], r["key"]): r["value"]
        for r in read_evaluation(out).values.to_pylist()
        if not r["algorithm"]
    }
    assert {m for m, _ in values} >= {"drivable_area", "driving_direction", "speed_limit"}
    assert values[("drivable_area", "drivable_area_compliance")] == 1.0
    assert values[("drivable_area", "off_road_frames")] == 0.0
    assert values[("driving_direction", "driving_direction_compliance")] == 1.0
    assert values[("speed_limit", "speed_limit_compliance")] == 1.0  # 8 m/s on 50 km/h lanes


def test_a_log_whose_ego_is_in_odom_is_placed_through_its_tf(
    osm: Path, road: RoadMap, tmp_path: Path
) -> None:
    """Poses in `odom`, a /tf_static map → odom (shift and 30° turn): the map is moved into
    `odom` by it, and the drive still finds its lanes."""
    x0, y0, yaw0 = 2000.0, 600.0, math.radians(30.0)  # odom's origin and heading in map
    poses = drive_poses(road, seconds=4.0)
    c, s = math.cos(yaw0), math.sin(yaw0)
    dx, dy = poses[:, 0] - x0, poses[:, 1] - y0
    in_odom = np.column_stack([c * dx + s * dy, -s * dx + c * dy, poses[:, 2] - yaw0])
    bag = write_drive_bag(tmp_path / "odom.bag", in_odom, frame="odom", map_to_frame=(x0, y0, yaw0))
    out = tmp_path / "run"
    assert _run(bag, out, "--map", str(osm), "--map-origin", "49.0,8.4") == 0
    alignment = json.loads((out / "manifest.json").read_text())["map"]["alignment"]
    assert alignment["method"] == "tf"
    assert alignment["frame"] == "odom"
    assert alignment["yaw_rad"] == pytest.approx(-yaw0)
    stored = open_run(out).road_map()
    assert stored is not None
    assert stored.frame_id == "odom"
    lanes = _lanes_driven(out)
    assert len(lanes) == 40
    assert all(lane in DRIVE_LANES[:2] for lane in lanes), lanes


def test_no_map_frame_and_no_origin_says_what_to_pass(
    road: RoadMap, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A map in metres (a run's map.json) and a log whose ego is in `odom` with no tf: the
    error says to pass --map-origin (or record the map → odom tf, or --no-map)."""
    poses = drive_poses(road, seconds=1.0)
    bag = write_drive_bag(tmp_path / "odom.bag", poses, frame="odom")
    out = tmp_path / "first"
    assert _run(bag, out, "--map", str(_projected_map(road, tmp_path)), "--map-origin",
                "49.0,8.4") == 0  # fmt: skip
    capsys.readouterr()
    assert _run(bag, tmp_path / "second", "--map", str(out / "map.json")) == 1
    err = capsys.readouterr()
    text = err.out + err.err
    assert "has no `map` frame" in text
    assert "Pass --map-origin LAT,LON" in text
    assert "--no-map" in text


def _projected_map(road: RoadMap, tmp_path: Path) -> Path:
    """The map as a redrive map.json (metres), to be given to --map."""
    from redrive.maps.document import road_map_to_json

    path = tmp_path / "karlsruhe.json"
    path.write_text(json.dumps(road_map_to_json(road)), encoding="utf-8")
    return path


def test_a_damaged_map_is_refused_by_name_and_no_map_runs_without_it(
    osm: Path, road: RoadMap, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = osm.read_text(encoding="utf-8")
    start = text.index("<relation id='42440'")
    relation = text[start : text.index("</relation>", start)]
    bad = tmp_path / "nobound.osm"
    bad.write_text(
        text.replace(
            relation, relation.replace("<member type='way' ref='44574' role='left' />", "")
        ),
        encoding="utf-8",
    )
    cut = tmp_path / "cut.osm"
    cut.write_text(text[: len(text) // 2], encoding="utf-8")
    bag = write_drive_bag(tmp_path / "drive.bag", drive_poses(road, seconds=1.0), frame="map")
    for damaged, named in ((bad, "primitive 42440: Lanelet has not exactly one left border"),
                           (cut, "is the file complete")):  # fmt: skip
        capsys.readouterr()
        assert _run(bag, tmp_path / damaged.stem, "--map", str(damaged), "--map-origin",
                    "49.0,8.4") == 1  # fmt: skip
        said = capsys.readouterr()
        assert named in said.out + said.err
        assert "--no-map" in said.out + said.err
        assert not (tmp_path / damaged.stem / "manifest.json").exists()
    out = tmp_path / "without"
    assert _run(bag, out, "--no-map") == 0
    assert json.loads((out / "manifest.json").read_text())["map"] == {
        "disabled": True,
        "from": "--no-map",
    }
    assert not (out / "map.json").exists()
    capsys.readouterr()
    assert main(["evaluate", str(out), "--metric", "drivable_area"]) == 0
    assert "no road map" in capsys.readouterr().out


def test_a_map_the_log_carries_is_replaced_by_the_users_with_a_warning(
    shared_data: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A CommonRoad scenario (its own lanelet network) run with --map another scenario's network
    (a CommonRoad XML as the map): the user's map wins and a warning says so."""
    pytest.importorskip("commonroad")
    log = shared_data / "commonroad" / "USA_US101-3_3_T-1.xml"
    other = shared_data / "commonroad" / "DEU_A9-3_1_T-1.xml"
    out = tmp_path / "run"
    with caplog.at_level(logging.WARNING):
        code = main(["run", str(log), "--out", str(out), "--no-progress", "--frames", "0:5",
                     "--map", str(other)])  # fmt: skip
    assert code == 0
    assert "carries its own road map" in caplog.text
    entry = json.loads((out / "manifest.json").read_text())["map"]
    assert entry["format"] == "commonroad"
    assert entry["replaced"].startswith("commonroad")
    stored = open_run(out).road_map()
    assert stored is not None
    assert len(stored.lanes) == entry["lanes"]
    assert stored.source is not None
    assert "DEU_A9" in stored.source


def test_the_logs_own_map_file_given_as_map_replaces_nothing(
    shared_data: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A CommonRoad scenario run with --map itself (its own lanelet network, h-tour's finding:
    it warned that the map replaced itself): no warning, nothing replaced, the manifest says so;
    `evaluate --map` with the same file again on that run says nothing either."""
    pytest.importorskip("commonroad")
    log = shared_data / "commonroad" / "USA_US101-3_3_T-1.xml"
    out = tmp_path / "run"
    with caplog.at_level(logging.WARNING):
        code = main(["run", str(log), "--out", str(out), "--no-progress", "--frames", "0:5",
                     "--map", str(log)])  # fmt: skip
        assert code == 0
        entry = json.loads((out / "manifest.json").read_text())["map"]
        assert main(["evaluate", str(out), "--metric", "drivable_area", "--map", str(log)]) == 0
    assert "road map" not in caplog.text, caplog.text
    assert entry["same_as_log"] is True
    assert "replaced" not in entry
    again = json.loads((out / "manifest.json").read_text())["map"]
    assert "replaced" not in again
    assert again["same_as_log"] is True


def test_a_lanelet2_map_far_from_the_logs_gnss_is_said(
    shared_data: Path,
    osm: Path,
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The Husky bag (REAL; /fix in Massachusetts) with the Karlsruhe map: 5,936 km apart, said in
    a warning and the manifest's map.gnss (h-tour: it went unnoticed); a fix inside the map's
    extent is not far."""
    from redrive.engine import user_map
    from redrive.types import GnssFix

    bag = shared_data / "rosbag1_real" / "robot_localization_test1_husky.bag"
    argv = ["--map", str(osm), "--map-origin", "49.0,8.4", "--frames", "0:5"]
    with caplog.at_level(logging.WARNING):
        assert _run(bag, tmp_path / "far", *argv) == 0
    gnss = json.loads((tmp_path / "far" / "manifest.json").read_text())["map"]["gnss"]
    assert gnss["topic"] == "/fix"
    assert gnss["far"] is True
    assert 5_850 < gnss["distance_km"] < 6_050  # Boston to Karlsruhe
    assert "km from the Lanelet2 map" in caplog.text
    caplog.clear()
    near = GnssFix(latitude_deg=49.005, longitude_deg=8.42, altitude_m=110.0)
    monkeypatch.setattr(user_map, "_first_fix", lambda log, topic: near)
    with caplog.at_level(logging.WARNING):
        assert _run(bag, tmp_path / "near", *argv) == 0
    gnss = json.loads((tmp_path / "near" / "manifest.json").read_text())["map"]["gnss"]
    assert gnss["far"] is False
    assert gnss["distance_km"] < 1.0
    assert "km from the Lanelet2 map" not in caplog.text


def test_map_and_no_map_exclude_each_other() -> None:
    from redrive.engine.user_map import MapOption

    with pytest.raises(MapError, match="exclude each other"):
        MapOption(path=Path("m.osm"), disabled=True)


def test_a_real_ros_bag_run_with_the_map_stores_it_and_says_what_is_missing(
    shared_data: Path, osm: Path, road: RoadMap, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The Embark truck bag (REAL LiDAR; its odometry in `odom`, no tf): without an origin the
    run is refused with what to pass; with --map-origin it runs, stores the map and the manifest
    names the file, the origin and the alignment."""
    bag = shared_data / "rosbag1_real" / "embag_luminar_test.bag"
    for given in (osm, _projected_map(road, tmp_path)):  # a Lanelet2 map, a map in metres
        capsys.readouterr()
        assert _run(bag, tmp_path / f"refused-{given.suffix[1:]}", "--map", str(given)) == 1
        said = capsys.readouterr()
        assert "--map-origin" in said.out + said.err, said
    out = tmp_path / "run"
    origin = ("--map-origin", "49.0,8.4")
    assert (
        _run(bag, out, "--map", str(osm), *origin, role="perception", alg="cluster-detector") == 0
    )
    entry = json.loads((out / "manifest.json").read_text())["map"]
    assert entry["path"] == str(osm.resolve())
    assert entry["sha256"] == hashlib.sha256(osm.read_bytes()).hexdigest()
    assert entry["origin_lat_lon"] == [49.0, 8.4]
    assert entry["alignment"]["method"] == "origin"
    assert entry["alignment"]["frame"] == "odom"
    stored = open_run(out).road_map()
    assert stored is not None
    assert stored.frame_id == "odom"
    assert len(stored.lanes) == 416


def test_evaluate_map_gives_an_existing_run_its_map(
    osm: Path, road: RoadMap, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A run made without a map: `evaluate --map` places the map through the run's log, stores
    it (map.json, manifest `map`) and the map metrics are computed; `--no-map` leaves them out."""
    bag = write_drive_bag(tmp_path / "drive.bag", drive_poses(road, seconds=3.0), frame="map")
    out = tmp_path / "run"
    assert _run(bag, out) == 0
    assert not (out / "map.json").exists()
    assert json.loads((out / "manifest.json").read_text())["map"] == {}
    capsys.readouterr()
    assert main(["evaluate", str(out), "--metric", "drivable_area", "--no-map"]) == 0
    assert "skipped drivable_area: --no-map" in capsys.readouterr().out
    assert main(["evaluate", str(out), "--metric", "drivable_area", "--metric",
                 "driving_direction", "--map", str(osm), "--map-origin", "49.0,8.4"]) == 0  # fmt: skip
    said = capsys.readouterr().out
    assert "drivable_area_compliance" in said
    assert "driving_direction_compliance" in said
    entry = json.loads((out / "manifest.json").read_text())["map"]
    assert entry["from"] == "--map"
    assert entry["alignment"]["method"] == "log map frame"
    assert open_run(out).road_map() is not None
    assert all(lane in DRIVE_LANES[:1] for lane in _lanes_driven(out))


def test_a_batch_spec_map_reaches_every_recorded_log(
    osm: Path, road: RoadMap, tmp_path: Path
) -> None:
    bag = write_drive_bag(tmp_path / "drive.bag", drive_poses(road, seconds=2.0), frame="map")
    spec = tmp_path / "batch.toml"
    spec.write_text(
        f'logs = ["{bag}"]\nmap = "{osm}"\nmap_origin = "49.0,8.4"\nout = "b"\nworkers = 1\n'
        '[[pipeline]]\nplanning = ["idm-planner"]\n',
        encoding="utf-8",
    )
    assert main(["batch", "--spec", str(spec), "--no-progress"]) == 0
    (manifest,) = (tmp_path / "b" / "runs").glob("*/*/*/manifest.json")
    entry = json.loads(manifest.read_text())["map"]
    assert entry["path"] == str(osm.resolve())
    assert entry["origin_lat_lon"] == [49.0, 8.4]
    assert (manifest.parent / "map.json").is_file()


def test_a_closed_loop_with_the_users_map_follows_the_route_on_it(
    osm: Path, road: RoadMap, tmp_path: Path
) -> None:
    """--map in closed loop: the map placed for the metrics is the one the route is found on
    (the logged ego's lanes of the Karlsruhe chain), and idm-planner drives along it, on the
    road the whole way."""
    poses = drive_poses(road, seconds=12.0)
    bag = write_drive_bag(tmp_path / "drive.bag", poses, frame="map")
    out = tmp_path / "loop"
    extra = ("--closed-loop", "--map", str(osm), "--map-origin", "49.0,8.4")
    assert _run(bag, out, *extra) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["map"]["from"] == "--map"
    assert manifest["closed_loop"]["route"]["lanes"] == list(DRIVE_LANES)
    lanes = _lanes_driven(out)
    assert all(lane in DRIVE_LANES for lane in lanes), lanes
    assert main(["evaluate", str(out), "--metric", "drivable_area"]) == 0
    from redrive.results.evaluation import read_evaluation

    values = {
        (r["metric"], r["key"]): r["value"]
        for r in read_evaluation(out).values.to_pylist()
        if not r["algorithm"]
    }
    assert values[("drivable_area", "drivable_area_compliance")] == 1.0
