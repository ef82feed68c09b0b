"""RUN/map.json and the ego_logged table: written, read back, validated; old runs still read."""

from __future__ import annotations

import json
import math
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import ConfigError
from redrive.maps.document import road_map_to_json
from redrive.results import MAP_NAME, RunWriter, open_run, write_road_map
from redrive.types import DrivableArea, MapLane, RoadMap
from tests.results._records import SETUP, frame


def _map() -> RoadMap:
    return RoadMap(
        lanes=(
            MapLane(
                lane_id="a",
                centerline=np.array([[0.0, 0.0], [50.0, 0.0], [100.0, 5.0]]),
                width_m=3.5,
                speed_limit_mps=13.89,
            ),
            MapLane(lane_id="b", centerline=np.array([[100.0, 3.5], [0.0, 3.5]]), width_m=3.25),
        ),
        areas=(
            DrivableArea(
                area_id="x", polygon=np.array([[0.0, 0.0], [5.0, 0.0], [5.0, 5.0]]), kind="carpark"
            ),
        ),
    )


def test_map_round_trip(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    with RunWriter(run_dir, setup=SETUP) as writer:
        writer.write_frame(frame(0))
        writer.write_map(_map())
    got = open_run(run_dir).road_map()
    assert got is not None
    want = _map()
    assert [lane.lane_id for lane in got.lanes] == ["a", "b"]
    for a, b in zip(got.lanes, want.lanes, strict=True):
        assert np.array_equal(a.centerline, b.centerline)
        assert (a.width_m, a.speed_limit_mps) == (b.width_m, b.speed_limit_mps)
    assert got.areas[0].kind == "carpark"
    assert np.array_equal(got.areas[0].polygon, want.areas[0].polygon)
    assert not got.lanes[0].centerline.flags.writeable
    assert not list(run_dir.glob("*.tmp"))


def test_map_written_into_a_finished_run(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    with RunWriter(run_dir, setup=SETUP) as writer:
        writer.write_frame(frame(0))
    write_road_map(run_dir, _map())
    road_map = open_run(run_dir).road_map()
    assert road_map is not None
    assert road_map.lane("b").width_m == 3.25
    with pytest.raises(ConfigError, match="not a redrive run"):
        write_road_map(tmp_path / "nothing", _map())


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.update(schema_version=7), "schema_version: 7 is not 1"),
        (lambda d: d["lanes"][1].pop("width_m"), r"lanes\[1\]: 'width_m' is missing"),
        (lambda d: d["lanes"][0].update(centerline=[[1, 2]]), "needs >= 2 finite points"),
        (lambda d: d["lanes"][0].update(width_m="wide"), r"lanes\[0\]\.width_m: expected"),
        (lambda d: d["areas"][0].update(polygon=[1, 2, 3]), r"areas\[0\]\.polygon: points must be"),
        (lambda d: d["lanes"].append(d["lanes"][0]), "lane id 'a' appears twice"),
    ],
)
def test_bad_map_is_refused_with_where(tmp_path: Path, edit: object, message: str) -> None:
    run_dir = tmp_path / "run"
    with RunWriter(run_dir, setup=SETUP) as writer:
        writer.write_map(_map())
    path = run_dir / MAP_NAME
    data = json.loads(path.read_text())
    edit(data)  # type: ignore[operator]
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=message) as info:
        open_run(run_dir).road_map()
    assert str(path) in str(info.value)
    path.write_text("{not json")
    with pytest.raises(ConfigError, match="cannot be read as JSON"):
        open_run(run_dir).road_map()


def test_run_without_ego_logged_table_still_reads(tmp_path: Path) -> None:
    """Runs written before the table existed have no ego_logged folder at all."""
    run_dir = tmp_path / "run"
    with RunWriter(run_dir, setup=SETUP) as writer:
        for i in range(3):
            writer.write_frame(frame(i))
    shutil.rmtree(run_dir / "ego_logged")
    run = open_run(run_dir)
    assert run.logged_ego() == {}
    assert sorted(run.ego()) == [0, 1, 2]
    assert "ego_logged" not in run.tables()
    assert run.table("ego_logged").num_rows == 0


def test_road_map_refuses_bad_values() -> None:
    with pytest.raises(ValueError, match="width_m must be > 0"):
        MapLane(lane_id="a", centerline=np.zeros((2, 2)), width_m=0.0)
    with pytest.raises(ValueError, match="speed_limit_mps"):
        MapLane(lane_id="a", centerline=np.zeros((2, 2)), width_m=3.0, speed_limit_mps=-1.0)
    with pytest.raises(ValueError, match="dtype"):
        MapLane(lane_id="a", centerline=np.zeros((2, 2), dtype=np.float32), width_m=3.0)
    area = DrivableArea(area_id="x", polygon=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="area id 'x' appears twice"):
        RoadMap(lanes=(), areas=(area, area))


def _bits_equal(a: object, b: object) -> bool:
    """Whether two JSON documents are the same: types, keys, every double bit for bit."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return struct.pack("<d", a) == struct.pack("<d", b)
    if isinstance(a, dict):
        assert isinstance(b, dict)
        return list(a) == list(b) and all(_bits_equal(a[k], b[k]) for k in a)
    if isinstance(a, list):
        assert isinstance(b, list)
        return len(a) == len(b) and all(_bits_equal(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def test_map_text_parses_to_the_json_module_document(tmp_path: Path) -> None:
    """orjson's text of a map reads back as exactly json.dumps's document (every double)."""
    rng = np.random.default_rng(7)
    awkward = np.array(
        [[0.1 + 0.2, -0.0], [1e16, 5e-324], [1.7976931348623157e308, -123456.789e-300]]
    )
    wide = rng.normal(0.0, 1e4, (400, 4))
    road = RoadMap(
        lanes=(
            MapLane(lane_id="é", centerline=awkward, width_m=1.0 / 3.0, speed_limit_mps=13.89),
            # a strided view: written as its values
            MapLane(lane_id="b", centerline=wide[:, ::2], width_m=3.25),
            MapLane(
                lane_id="c",
                centerline=wide[:, 1:3].copy(),
                width_m=3.0,
                left_boundary=wide[:, :2].copy(),
                right_boundary=wide[:, 2:].copy(),
            ),
        ),
        areas=(DrivableArea(area_id="x", polygon=rng.uniform(-1e3, 1e3, (50, 2))),),
    )
    run_dir = tmp_path / "run"
    with RunWriter(run_dir, setup=SETUP) as writer:
        writer.write_map(road)
    got = json.loads((run_dir / MAP_NAME).read_text(encoding="utf-8"))
    want = json.loads(json.dumps(road_map_to_json(road), separators=(",", ":"), allow_nan=False))
    assert _bits_equal(got, want)
    assert not _bits_equal(got, {**want, "frame_id": "other"})  # the check can fail


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_map_with_a_non_finite_number_is_refused(tmp_path: Path, bad: float) -> None:
    """JSON has no NaN or infinity (orjson would write null): refused as json.dumps did."""
    run_dir = tmp_path / "run"
    with RunWriter(run_dir, setup=SETUP) as writer:
        writer.write_frame(frame(0))
    road = _map()
    points = road.lanes[1].centerline.copy()
    points[1, 0] = bad
    object.__setattr__(road.lanes[1], "centerline", points)  # past MapLane's checks
    with pytest.raises(ValueError, match="not JSON compliant"):
        write_road_map(run_dir, road)
    object.__setattr__(road.lanes[1], "centerline", road.lanes[0].centerline)
    object.__setattr__(road.lanes[0], "width_m", bad)
    with pytest.raises(ValueError, match="not JSON compliant"):
        write_road_map(run_dir, road)
    assert not (run_dir / MAP_NAME).exists()


def test_check_finite_finds_a_bad_number_anywhere_and_names_it() -> None:
    """The one-pass check refuses what the value-by-value walk refuses, wherever it sits (a
    nested list, an array, a numpy float), with the walk's message; a finite document passes."""
    from redrive.results.roadmap import _check_finite

    good = {"a": [1, "x", None, 2.5, {"b": np.zeros((2, 2)), "c": [np.float64(3.0)]}]}
    _check_finite(good)
    for bad_value, shown in (
        (math.nan, "nan"),
        (np.float64(math.inf), "inf"),
        (np.array([[0.0, -math.inf]]), "-inf"),
    ):
        doc = {"a": [1, "x", {"b": np.zeros((2, 2)), "c": [0.5, bad_value]}]}
        with pytest.raises(ValueError, match=f"not JSON compliant: .*{shown}"):
            _check_finite(doc)
