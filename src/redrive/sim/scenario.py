"""Scenarios: what the synthetic world contains, loaded from small commented TOML files.

The catalogue lives in ``redrive/sim/scenarios/*.toml`` (:func:`list_scenarios`); copy one and edit
it, then pass its path to :func:`load_scenario`.  Unknown keys and invalid values raise
:class:`~redrive.errors.ConfigError` naming the file, the key and what to do.  The ``[rig]`` table
is kept raw (:mod:`redrive.sim.rig` parses it); each sensor's ``rate_hz`` is also exposed as
:attr:`Scenario.sensor_rates_hz`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

from redrive.config.validate import Table, is_number, parse_toml
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


def _style(source: str, path: str, problem: str, fix: str) -> str:
    return f"{source}: key '{path}': {problem}; {fix}"


def _fail(source: str, key: str, problem: str, advice: str) -> ConfigError:
    return ConfigError(_style(source, key, problem, advice))


def _read(t: Table, key: str, annotation: str) -> Any:
    """``key`` of ``t`` read as the dataclass field ``annotation`` says (``float | None``, ...)."""
    base = annotation.removesuffix(" | None")
    if base == "float":
        return t.number(key)
    if base == "int":
        return t.integer(key)
    if base == "bool":
        return t.flag(key)
    if base == "str":
        return t.text(key)
    if base.startswith("tuple["):
        colour = base[6:-1].split(",")[0] == "int"
        return t.numbers(key, length=3, integers=(0, 255) if colour else None)
    return t.raw(key)


def _build(cls: Any, t: Table, *, skip: tuple[str, ...] = ()) -> Any:
    """Instantiate dataclass ``cls`` from ``t``: unknown keys and wrong types are ConfigErrors."""
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name not in skip}
    t.check_keys(set(fields) | set(skip))
    kwargs = {key: _read(t, key, str(fields[key].type)) for key in t if key not in skip}
    for name, f in fields.items():
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        if required and name not in kwargs:
            raise t.missing(name, "a value", "add it")
    try:
        return cls(**kwargs)
    except ValueError as err:
        raise t.fail("", str(err), "fix the values") from err


def _positive(source: str, key: str, value: float | int | None) -> None:
    if value is not None and not value > 0:
        raise _fail(source, key, f"must be > 0, got {value}", "use a positive value")


def parse_scenario(data: Mapping[str, Any], *, source: str = "<memory>") -> Scenario:
    """A :class:`Scenario` from a parsed TOML document (``source`` names it in errors)."""
    doc = Table(data, source=source, style=_style)
    road_t = doc.table("road", {}, fix="write it as [road]")
    layout_name = road_t.text("layout", "urban", choices=tuple(_LAYOUTS))
    road = _build(_LAYOUTS[layout_name], road_t, skip=("layout",))
    lights = _build(LightTiming, doc.table("lights", {}, fix="write it as [lights]"))
    if "ego" not in doc:
        raise _fail(source, "ego", "missing", "add an [ego] table with at least route = '...'")
    ego = _build(EgoSpec, doc.table("ego", fix="write it as [ego]"))
    agents = [
        _build(AgentSpec, entry)
        for entry in doc.tables("agents", [], fix="write each one as [[agents]]")
    ]
    rig = doc.mapping("rig", {}, fix="write it as [rig]")
    tables = ("road", "lights", "ego", "agents", "rig")
    known = {f.name: str(f.type) for f in dataclasses.fields(Scenario)}
    known = {k: v for k, v in known.items() if k not in (*tables, "source")}
    doc.check_keys(set(known) | set(tables))
    top_kwargs = {key: _read(doc, key, known[key]) for key in doc if key in known}
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
        if "rate_hz" in table and not (is_number(table["rate_hz"]) and table["rate_hz"] > 0):
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
    return parse_scenario(parse_toml(text, source=source), source=source)
