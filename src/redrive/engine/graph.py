"""The stage graph: a pipeline's algorithms loaded, configured and checked against a log.

Checks made before the first frame (each a :class:`~redrive.errors.ConfigError` or
:class:`~redrive.errors.PluginError` that says what to change):

- every plugin loads and is an :class:`Algorithm` with a role;
- roles never go backwards: no planning stage before a perception stage, no control before
  planning (a stage may mix roles only if they are equal);
- every algorithm's declared ``inputs`` exist in the log (sensor ids or types, ego state,
  ground truth).  With ``skip_unfed=True`` an algorithm whose inputs the log lacks is left out
  instead, with the reason (:attr:`StageGraph.skipped`), and so is a control stage left without
  a planning stage; only a pipeline left with nothing to run is refused.
"""

from __future__ import annotations

import hashlib
import inspect
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from redrive.algorithms import GROUND_TRUTH, ROAD_MAP, VEHICLE_STATE, Algorithm, Role
from redrive.algorithms.discovery import load_algorithm_class
from redrive.config import AlgorithmSpec, PipelineConfig
from redrive.errors import ConfigError, MissingInputError, PluginError
from redrive.results import AlgorithmEntry
from redrive.types import Mission, RoadMap, SensorType, to_jsonable

__all__ = ["LogInputs", "PlannedAlgorithm", "StageGraph", "build_graph", "config_hash"]

_ROLE_ORDER = {Role.PERCEPTION: 0, Role.PLANNING: 1, Role.CONTROL: 2}


@dataclass(frozen=True, slots=True, kw_only=True)
class LogInputs:
    """What a log can feed algorithms: sensor id → type, plus ego state / ground truth, and its
    road map (handed to every algorithm before the first frame: ``Algorithm.use_road_map``)."""

    sensors: Mapping[str, SensorType] = field(default_factory=dict)
    has_vehicle_state: bool = False
    has_ground_truth: bool = False
    road_map: RoadMap | None = None
    #: the run's mission (``Algorithm.use_mission``): a closed loop on a recorded log's map
    mission: Mission | None = None
    #: ``vehicle_state`` / ``ground_truth`` → why the log's topic of it feeds no frame (its header
    #: stamps follow another clock: ``redrive.assembly.clocks``); such an input is not in
    #: :attr:`extras`, and an algorithm that needs it is told why
    unusable: Mapping[str, str] = field(default_factory=dict)

    @property
    def extras(self) -> tuple[str, ...]:
        out = []
        if self.has_vehicle_state:
            out.append(VEHICLE_STATE)
        if self.has_ground_truth:
            out.append(GROUND_TRUTH)
        if self.road_map is not None:
            out.append(ROAD_MAP)
        return tuple(out)


def config_hash(config: Mapping[str, Any]) -> str:
    """sha256 of the canonical JSON of a configuration (sorted keys)."""
    text = json.dumps(to_jsonable(config), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True, slots=True, kw_only=True)
class PlannedAlgorithm:
    """One algorithm of the graph: its spec, class, role and the config it runs with.

    ``instance`` is the configured, bound algorithm of this process (used by in-process
    execution; worker processes build their own from ``spec`` and ``config``).
    """

    spec: AlgorithmSpec
    stage: str
    cls: type[Algorithm]
    config: Mapping[str, Any]
    instance: Algorithm

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def role(self) -> Role:
        return self.cls.role

    def manifest_entry(self) -> AlgorithmEntry:
        try:
            source = inspect.getsourcefile(self.cls) or ""
        except TypeError:
            source = ""
        return AlgorithmEntry(
            name=self.name,
            stage=self.stage,
            role=self.role,
            plugin=self.spec.plugin,
            class_name=f"{self.cls.__module__}:{self.cls.__qualname__}",
            source=source,
            version=str(self.cls.version),
            inputs=tuple(self.cls.input_names()),
            config=to_jsonable(self.config),
            config_hash=config_hash(self.config),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class StageGraph:
    """Stages in execution order, each a tuple of planned algorithms; ``skipped``: the
    algorithms left out because the log cannot feed them (name → why), in pipeline order."""

    stages: tuple[tuple[str, tuple[PlannedAlgorithm, ...]], ...]
    skipped: Mapping[str, str] = field(default_factory=dict)

    @property
    def algorithms(self) -> tuple[PlannedAlgorithm, ...]:
        return tuple(a for _, algos in self.stages for a in algos)


def instantiate(
    cls: type[Algorithm], *, name: str, config: Mapping[str, Any], inputs: LogInputs
) -> Algorithm:
    """A configured algorithm bound to a log's inputs (what both the engine process and a worker
    process do with a plugin)."""
    algo = cls(name=name)
    algo.configure(config)
    algo.bind(inputs.sensors, extras=inputs.extras)
    algo.use_road_map(inputs.road_map)
    algo.use_mission(inputs.mission)
    return algo


def build_graph(
    pipeline: PipelineConfig, inputs: LogInputs, *, skip_unfed: bool = False
) -> StageGraph:
    """Load, configure and check every algorithm of ``pipeline`` against ``inputs``.

    ``skip_unfed``: leave out (and say why) the algorithms whose inputs the log lacks — and a
    control stage whose planning was left out, and an algorithm whose ``upstream`` role was left
    out (a tracker without its detector) — instead of refusing the pipeline; what is left must
    not be empty.
    """
    stages: list[tuple[str, tuple[PlannedAlgorithm, ...]]] = []
    skipped: dict[str, str] = {}
    last_role: Role | None = None
    last_stage = ""
    planning_skipped = False
    skipped_roles: set[Role] = set()  # roles some algorithm of was skipped (its inputs lacking)
    for stage in pipeline.stages:
        planned: list[PlannedAlgorithm] = []
        for spec in stage.algorithms:
            cls = load_algorithm_class(spec.plugin)
            role = getattr(cls, "role", None)
            if not isinstance(role, Role):
                msg = f"{spec.plugin}: {cls.__name__} sets no `role` (Role.PERCEPTION, …)"
                raise PluginError(msg)
            if stage.role is not None and role.value != stage.role:
                msg = (
                    f"{spec.plugin}: {cls.__name__} is a {role.value} algorithm "
                    f"(role = Role.{role.name}), given as --{stage.role}; "
                    f"pass it with --{role.value} {spec.plugin}"
                )
                raise ConfigError(msg)
            if last_role is not None and _ROLE_ORDER[role] < _ROLE_ORDER[last_role]:
                msg = (
                    f"stage {stage.name!r}: {spec.name} is a {role.name} algorithm after the "
                    f"{last_role.name} stage {last_stage!r}; order stages perception → planning → "
                    "control"
                )
                raise ConfigError(msg)
            config = dict(spec.config)
            if "seed" in cls.defaults and "seed" not in config:
                config["seed"] = pipeline.seed
            if (
                skip_unfed
                and role is Role.CONTROL
                and planning_skipped
                and not _has_planning(stages, planned)
            ):
                skipped[spec.name] = (
                    f"stage {stage.name!r} ({spec.plugin}): no planning stage runs to give it a "
                    "path (the planning stage was skipped)"
                )
                continue
            needs = getattr(cls, "upstream", None)
            if (
                skip_unfed
                and isinstance(needs, Role)
                and needs in skipped_roles
                and not _has_role(stages, planned, needs)
            ):
                skipped[spec.name] = (
                    f"stage {stage.name!r} ({spec.plugin}): no {needs.value} algorithm runs "
                    f"before it to give it its input (the {needs.value} stage was skipped)"
                )
                continue
            try:
                algo = instantiate(cls, name=spec.name, config=config, inputs=inputs)
            except MissingInputError as err:
                why = _unusable(cls, inputs)
                if not skip_unfed:
                    msg = (
                        f"stage {stage.name!r}, algorithm {spec.name!r} ({spec.plugin}): {err}{why}"
                    )
                    raise MissingInputError(msg) from err
                skipped[spec.name] = f"stage {stage.name!r} ({spec.plugin}): {_need(err)}{why}"
                planning_skipped = planning_skipped or role is Role.PLANNING
                skipped_roles.add(role)
                continue
            except ConfigError as err:
                msg = f"stage {stage.name!r}, algorithm {spec.name!r} ({spec.plugin}): {err}"
                raise ConfigError(msg) from err
            planned.append(
                PlannedAlgorithm(
                    spec=spec, stage=stage.name, cls=cls, config=dict(algo.config), instance=algo
                )
            )
        if not planned:
            continue  # every algorithm of the stage was skipped
        roles = {p.role for p in planned}
        if len(roles) > 1:
            names = ", ".join(f"{p.name} ({p.role.name})" for p in planned)
            msg = f"stage {stage.name!r} mixes roles ({names}); put each role in its own stage"
            raise ConfigError(msg)
        last_role = planned[0].role
        last_stage = stage.name
        stages.append((stage.name, tuple(planned)))
    if skipped and not stages:
        reasons = "; ".join(f"{name}: {why}" for name, why in skipped.items())
        msg = f"no stage of the pipeline can run on this log ({reasons})"
        raise MissingInputError(msg)
    return StageGraph(stages=tuple(stages), skipped=skipped)


def _has_planning(
    stages: list[tuple[str, tuple[PlannedAlgorithm, ...]]], planned: list[PlannedAlgorithm]
) -> bool:
    return _has_role(stages, planned, Role.PLANNING)


def _has_role(
    stages: list[tuple[str, tuple[PlannedAlgorithm, ...]]],
    planned: list[PlannedAlgorithm],
    role: Role,
) -> bool:
    return any(p.role is role for _, algos in stages for p in algos) or any(
        p.role is role for p in planned
    )


def _unusable(cls: type[Algorithm], inputs: LogInputs) -> str:
    """Why the inputs ``cls`` declares that the log has but cannot feed are missing ("" when
    none is)."""
    declared = set(getattr(cls, "inputs", ()))
    reasons = [why for name, why in inputs.unusable.items() if name in declared]
    return "".join(f" — {why}" for why in reasons)


def _need(err: MissingInputError) -> str:
    """The reason of a missing input without the advice that fits only a refusal."""
    text = str(err)
    cut = text.find("; map a topic with a sensor map file")
    return text if cut < 0 else text[:cut]
