"""Scenarios: what the synthetic world contains, loaded from small commented TOML files.

The catalogue lives in ``redrive/sim/scenarios/*.toml`` (:func:`list_scenarios`); copy one and edit
it, then pass its path to :func:`load_scenario`.  Unknown keys and invalid values raise
:class:`~redrive.errors.ConfigError` naming the file, the key and what to do.  The ``[rig]`` table
is kept raw (:mod:`redrive.sim.rig` parses it); each sensor's ``rate_hz`` is also exposed as
:attr:`Scenario.sensor_rates_hz`.
"""

from __future__ import annotations

import dataclasses
import difflib
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

from redrive.errors import ConfigError
from redrive.sim.lights import LightTiming
from redrive.sim.roads import HighwayLayout, UrbanLayout, build_network

__all__ = ["AgentSpec", "EgoSpec", "Scenario", "list_scenarios", "load_scenario", "parse_scenario"]

AGENT_KINDS = ("vehicle", "truck", "cyclist", "pedestrian", "parked", "parked_van")
_LAYOUTS: Mapping[str, type[UrbanLayout] | type[HighwayLayout]] = {
    "urban": UrbanLayout,
    "highway": HighwayLayout,
}


@dataclass(frozen=True, slots=True, kw_only=True)
class EgoSpec:
    """The ego: its route, start arclength (m), set speed (m/s) and IDM behaviour."""

    route: str
    start_s_m: float = 10.0
    set_speed_mps: float = 12.0
    initial_speed_mps: float | None = None  # None: start at the set speed
    time_headway_s: float = 1.5
    min_gap_m: float = 2.0
    max_accel_mps2: float = 1.5
    comfort_decel_mps2: float = 2.5


@dataclass(frozen=True, slots=True, kw_only=True)
class AgentSpec:
    """One agent entry (``count > 1`` makes a platoon ``spacing_m`` apart, going backwards).

    Kinds: ``vehicle``, ``truck``, ``cyclist`` follow ``route`` with IDM; ``parked`` and
    ``parked_van`` stand at ``start_s_m`` on the shoulder; ``pedestrian`` walks across the route at
    ``start_s_m`` from ``lateral_offset_m`` to ``to_offset_m`` (metres, left > 0) starting at
    ``start_time_s`` or when the ego's front is ``trigger_ego_distance_m`` before the crossing.
    """

    kind: str
    route: str
    start_s_m: float = 0.0
    lateral_offset_m: float | None = None
    speed_mps: float = 10.0
    desired_speed_mps: float | None = None
    count: int = 1
    spacing_m: float = 20.0
    size_m: tuple[float, float, float] | None = None
    color: tuple[int, int, int] | None = None
    to_offset_m: float | None = None
    start_time_s: float | None = None
    trigger_ego_distance_m: float | None = None
    brake_time_s: float | None = None
    brake_decel_mps2: float = 6.0
    lane_change_route: str | None = None
    lane_change_time_s: float | None = None
    lane_change_duration_s: float = 3.0


@dataclass(frozen=True, slots=True, kw_only=True)
class Scenario:
    """A whole scenario.  Times in seconds, ``start_stamp_ns`` in int ns since the epoch."""

    name: str
    ego: EgoSpec
    road: UrbanLayout | HighwayLayout = field(default_factory=UrbanLayout)
    description: str = ""
    source: str = "<memory>"
    duration_s: float = 20.0
    seed: int = 0
    physics_dt_s: float = 0.01
    start_stamp_ns: int = 1_700_000_000_000_000_000
    speed_jitter_mps: float = 0.0
    scenery: bool = True
    lights: LightTiming = field(default_factory=LightTiming)
    agents: tuple[AgentSpec, ...] = ()
    rig: Mapping[str, Any] = field(default_factory=dict)

    @property
    def sensor_rates_hz(self) -> Mapping[str, float]:
        """``rate_hz`` of every ``[rig.<sensor>]`` table that has one."""
        return {
            name: float(table["rate_hz"])
            for name, table in self.rig.items()
            if isinstance(table, Mapping) and "rate_hz" in table
        }


def _fail(source: str, key: str, problem: str, advice: str) -> ConfigError:
    return ConfigError(f"{source}: key '{key}': {problem}; {advice}")


def _is_num(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _convert(value: Any, annotation: str, *, source: str, key: str) -> Any:
    optional = annotation.endswith(" | None")
    base = annotation.removesuffix(" | None")
    ok = True
    if base == "float":
        ok, value = _is_num(value), float(value) if _is_num(value) else value
    elif base == "int":
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif base == "bool":
        ok = isinstance(value, bool)
    elif base == "str":
        ok = isinstance(value, str)
    elif base.startswith("tuple["):
        kind = base[6:-1].split(",")[0]
        ok = isinstance(value, list) and len(value) == 3 and all(_is_num(v) for v in value)
        if ok and kind == "int":
            ok = all(isinstance(v, int) and 0 <= v <= 255 for v in value)
        value = tuple(value) if ok else value
    if not ok:
        want = base + (" (or leave it out)" if optional else "")
        raise _fail(source, key, f"expected {want}, got {value!r}", f"write a {base} value")
    return value


def _build(
    cls: Any, table: Mapping[str, Any], *, source: str, prefix: str, skip: tuple[str, ...] = ()
) -> Any:
    """Instantiate dataclass ``cls`` from ``table``: unknown keys and wrong types are ConfigErrors."""
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name not in skip}
    kwargs: dict[str, Any] = {}
    for key, value in table.items():
        if key in skip:
            continue
        if key not in fields:
            close = difflib.get_close_matches(key, list(fields), n=1)
            hint = f"did you mean '{close[0]}'?" if close else f"valid keys: {', '.join(fields)}"
            raise _fail(source, prefix + key, "unknown key", f"remove it ({hint})")
        kwargs[key] = _convert(value, str(fields[key].type), source=source, key=prefix + key)
    missing = [
        name
        for name, f in fields.items()
        if f.default is dataclasses.MISSING
        and f.default_factory is dataclasses.MISSING
        and name not in kwargs
    ]
    if missing:
        raise _fail(source, prefix + missing[0], "missing", "add it")
    try:
        return cls(**kwargs)
    except ValueError as err:
        raise _fail(source, prefix.rstrip("."), str(err), "fix the values") from err


def _table(data: Mapping[str, Any], key: str, *, source: str) -> Mapping[str, Any]:
    value = data.get(key, {})
    if not isinstance(value, Mapping):
        raise _fail(source, key, "expected a table", f"write it as [{key}]")
    return value


def _positive(source: str, key: str, value: float | int | None) -> None:
    if value is not None and not value > 0:
        raise _fail(source, key, f"must be > 0, got {value}", "use a positive value")


def parse_scenario(data: Mapping[str, Any], *, source: str = "<memory>") -> Scenario:
    """A :class:`Scenario` from a parsed TOML document (``source`` names it in errors)."""
    top = {"name", "description", "duration_s", "seed", "physics_dt_s", "start_stamp_ns"}
    top |= {"speed_jitter_mps", "scenery", "road", "lights", "ego", "agents", "rig"}
    road_t = dict(_table(data, "road", source=source))
    layout_name = road_t.pop("layout", "urban")
    if layout_name not in _LAYOUTS:
        raise _fail(
            source,
            "road.layout",
            f"unknown layout {layout_name!r}",
            f"use one of {', '.join(_LAYOUTS)}",
        )
    road = _build(_LAYOUTS[layout_name], road_t, source=source, prefix="road.")
    lights = _build(
        LightTiming, _table(data, "lights", source=source), source=source, prefix="lights."
    )
    if "ego" not in data:
        raise _fail(source, "ego", "missing", "add an [ego] table with at least route = '...'")
    ego = _build(EgoSpec, _table(data, "ego", source=source), source=source, prefix="ego.")
    raw_agents = data.get("agents", [])
    if not isinstance(raw_agents, list):
        raise _fail(source, "agents", "expected an array of tables", "write each one as [[agents]]")
    agents = []
    for i, entry in enumerate(raw_agents):
        if not isinstance(entry, Mapping):
            raise _fail(source, f"agents[{i}]", "expected a table", "write it as [[agents]]")
        agents.append(_build(AgentSpec, entry, source=source, prefix=f"agents[{i}]."))
    rig = _table(data, "rig", source=source)
    top_kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key in {"road", "lights", "ego", "agents", "rig"}:
            continue
        if key not in top:
            close = difflib.get_close_matches(key, sorted(top), n=1)
            hint = f"did you mean '{close[0]}'?" if close else "see the catalogue scenarios"
            raise _fail(source, key, "unknown key", f"remove it ({hint})")
        top_kwargs[key] = value
    fields = {f.name: str(f.type) for f in dataclasses.fields(Scenario)}
    for key in list(top_kwargs):
        top_kwargs[key] = _convert(top_kwargs[key], fields[key], source=source, key=key)
    if "name" not in top_kwargs:
        top_kwargs["name"] = Path(source).stem
    scenario = Scenario(
        road=road,
        lights=lights,
        ego=ego,
        agents=tuple(agents),
        rig=MappingProxyType(dict(rig)),
        source=source,
        **top_kwargs,
    )
    _validate(scenario)
    return scenario


def _validate(sc: Scenario) -> None:
    src = sc.source
    _positive(src, "duration_s", sc.duration_s)
    _positive(src, "physics_dt_s", sc.physics_dt_s)
    if sc.physics_dt_s > 0.05:
        raise _fail(
            src, "physics_dt_s", f"{sc.physics_dt_s} s is too coarse", "use ≤ 0.05 (default 0.01)"
        )
    if sc.speed_jitter_mps < 0:
        raise _fail(src, "speed_jitter_mps", "must be ≥ 0", "use 0 for none")
    _positive(src, "ego.set_speed_mps", sc.ego.set_speed_mps)
    routes = build_network(sc.road).routes
    valid = ", ".join(routes)
    if sc.ego.route not in routes:
        raise _fail(
            src,
            "ego.route",
            f"no route {sc.ego.route!r} in this road layout",
            f"use one of {valid}",
        )
    for i, agent in enumerate(sc.agents):
        pre = f"agents[{i}]."
        if agent.kind not in AGENT_KINDS:
            raise _fail(
                src,
                pre + "kind",
                f"unknown kind {agent.kind!r}",
                f"use one of {', '.join(AGENT_KINDS)}",
            )
        for key in ("route", "lane_change_route"):
            name = getattr(agent, key)
            if name is not None and name not in routes:
                raise _fail(
                    src, pre + key, f"no route {name!r} in this road layout", f"use one of {valid}"
                )
        _positive(src, pre + "count", agent.count)
        _positive(src, pre + "spacing_m", agent.spacing_m)
        if agent.size_m is not None and min(agent.size_m) <= 0:
            raise _fail(
                src, pre + "size_m", "sizes must be > 0", "give [length, width, height] in metres"
            )
        if agent.kind == "pedestrian":
            if agent.to_offset_m is None:
                raise _fail(
                    src,
                    pre + "to_offset_m",
                    "missing for a pedestrian",
                    "give the lateral offset (m) where the walk ends",
                )
            if agent.start_time_s is None and agent.trigger_ego_distance_m is None:
                raise _fail(
                    src,
                    pre + "start_time_s",
                    "a pedestrian needs a start",
                    "give start_time_s or trigger_ego_distance_m",
                )
        if (agent.lane_change_route is None) != (agent.lane_change_time_s is None):
            raise _fail(
                src,
                pre + "lane_change_time_s",
                "lane change half specified",
                "give both lane_change_route and lane_change_time_s",
            )
    for name, table in sc.rig.items():
        if not isinstance(table, Mapping):
            raise _fail(src, f"rig.{name}", "expected a table", f"write it as [rig.{name}]")
        if "rate_hz" in table and not (_is_num(table["rate_hz"]) and table["rate_hz"] > 0):
            raise _fail(
                src,
                f"rig.{name}.rate_hz",
                f"must be a number > 0, got {table['rate_hz']!r}",
                "give the sensor rate in Hz",
            )


def _catalogue() -> dict[str, Any]:
    folder = resources.files("redrive.sim").joinpath("scenarios")
    return {p.name.removesuffix(".toml"): p for p in folder.iterdir() if p.name.endswith(".toml")}


def list_scenarios() -> tuple[str, ...]:
    """Names of the catalogue scenarios, sorted."""
    return tuple(sorted(_catalogue()))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A catalogue scenario by name (``"urban"``) or a scenario TOML file by path."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            msg = f"{path}: no such scenario file; check the path (catalogue: {', '.join(list_scenarios())})"
            raise ConfigError(msg)
        text, source = path.read_text(encoding="utf-8"), str(path)
    else:
        entry = _catalogue().get(str(name_or_path))
        if entry is None:
            msg = f"unknown scenario {str(name_or_path)!r}; use one of {', '.join(list_scenarios())} or a path to a .toml file"
            raise ConfigError(msg)
        text, source = entry.read_text(encoding="utf-8"), f"{name_or_path}.toml (catalogue)"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        msg = f"{source}: not valid TOML ({err}); fix the syntax at that line"
        raise ConfigError(msg) from err
    return parse_scenario(data, source=source)
