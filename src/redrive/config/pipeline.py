"""Run configuration (L4): the pipeline a run executes, as frozen dataclasses loaded from TOML.

A pipeline file (every key but the stages is optional; the CLI's flags override the file)::

    mode = "pipelined"        # "sequential" (each frame through all stages) or "pipelined"
    executor = "threads"      # how algorithms run: "threads" (in this process) or "processes"
    seed = 0                  # handed to every algorithm whose defaults have a "seed"
    step_timeout_s = 2.0      # a step running longer is recorded as timed out (worker process)
    fail_fast = false         # stop at the first failed step instead of recording it

    [[stage]]
    name = "detection"

    [[stage.algorithm]]
    name = "clusters"                 # unique in the pipeline; default: the plugin's name
    plugin = "cluster-detector"       # entry-point name, package.module:Class or file.py:Class
    config = { voxel_m = 0.15 }

    [[stage]]
    name = "planning"
    [[stage.algorithm]]
    plugin = "idm-planner"

Stages run in file order; the algorithms of one stage run side by side on the same frame and see
the outputs of every earlier stage.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

from redrive.errors import ConfigError

__all__ = [
    "AlgorithmSpec",
    "Executor",
    "PipelineConfig",
    "RunMode",
    "StageSpec",
    "load_pipeline",
    "pipeline_from_plugins",
    "reference_pipeline",
]

RunMode = Literal["sequential", "pipelined"]
Executor = Literal["threads", "processes"]

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")


@dataclass(frozen=True, slots=True, kw_only=True)
class AlgorithmSpec:
    """One algorithm of a pipeline.

    Attributes:
        name: unique name in the run (rows of the results carry it).
        plugin: entry-point name, ``package.module:Class`` or ``path/file.py:Class``.
        config: laid over the algorithm's ``defaults`` and handed to its ``setup``.
    """

    name: str
    plugin: str
    config: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "config", MappingProxyType(dict(self.config)))


@dataclass(frozen=True, slots=True, kw_only=True)
class StageSpec:
    """A stage: algorithms that run side by side on the same frame.

    Attributes:
        name: the stage's name.
        algorithms: what runs in it.
        role: the role the user gave its algorithms (``--perception`` … sets it: "perception",
            "planning" or "control"); an algorithm of another role is refused. None: any.
    """

    name: str
    algorithms: tuple[AlgorithmSpec, ...]
    role: str | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class PipelineConfig:
    """What a run executes and how.

    Attributes:
        stages: in execution order.
        mode: ``sequential`` or ``pipelined`` (stage k on frame t while stage k-1 on frame t+1).
        executor: ``threads`` or ``processes`` (each algorithm in its own worker process).
        seed: handed to algorithms that take a ``seed``; recorded in the manifest.
        step_timeout_s: per-step limit (forces worker processes); None for none.
        fail_fast: stop at the first failed step.
    """

    stages: tuple[StageSpec, ...]
    mode: RunMode = "sequential"
    executor: Executor = "threads"
    seed: int = 0
    step_timeout_s: float | None = None
    fail_fast: bool = False

    def __post_init__(self) -> None:
        if not self.stages:
            raise ConfigError("a pipeline needs at least one stage with an algorithm")
        if self.mode not in ("sequential", "pipelined"):
            msg = f"mode must be 'sequential' or 'pipelined', got {self.mode!r}"
            raise ConfigError(msg)
        if self.executor not in ("threads", "processes"):
            msg = f"executor must be 'threads' or 'processes', got {self.executor!r}"
            raise ConfigError(msg)
        if self.step_timeout_s is not None and not self.step_timeout_s > 0:
            msg = f"step_timeout_s must be > 0 seconds, got {self.step_timeout_s}"
            raise ConfigError(msg)
        seen: set[str] = set()
        for stage in self.stages:
            if not stage.algorithms:
                msg = f"stage {stage.name!r} has no algorithm"
                raise ConfigError(msg)
            for algo in stage.algorithms:
                if algo.name in seen:
                    msg = (
                        f"two algorithms are named {algo.name!r}; give each a unique `name` "
                        "in the pipeline file"
                    )
                    raise ConfigError(msg)
                seen.add(algo.name)

    @property
    def algorithms(self) -> tuple[AlgorithmSpec, ...]:
        return tuple(a for s in self.stages for a in s.algorithms)

    def with_options(self, **changes: Any) -> PipelineConfig:
        """A copy with the given fields changed (None values are ignored)."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})


def _default_name(plugin: str) -> str:
    tail = plugin.rsplit(":", 1)[-1]
    tail = tail.rsplit("/", 1)[-1].removesuffix(".py")
    return tail or plugin


def pipeline_from_plugins(
    *,
    perception: Sequence[str] = (),
    planning: Sequence[str] = (),
    control: Sequence[str] = (),
) -> PipelineConfig:
    """One stage per given role, in perception → planning → control order.

    Several plugins for one role make consecutive stages (``--perception det --perception
    tracker`` runs the tracker on the detector's output).
    """
    stages: list[StageSpec] = []
    for role, plugins in (("perception", perception), ("planning", planning), ("control", control)):
        for i, plugin in enumerate(plugins):
            name = f"{role}" if len(plugins) == 1 else f"{role}_{i + 1}"
            spec = AlgorithmSpec(name=_default_name(plugin), plugin=plugin)
            stages.append(StageSpec(name=name, algorithms=(spec,), role=role))
    if not stages:
        raise ConfigError("give at least one of --perception, --planning, --control")
    return PipelineConfig(stages=tuple(stages))


def reference_pipeline() -> PipelineConfig:
    """The built-in baseline: LiDAR clusters → Kalman tracker → IDM planner → pure pursuit."""
    return PipelineConfig(
        stages=(
            StageSpec(
                name="detection",
                algorithms=(AlgorithmSpec(name="clusters", plugin="cluster-detector"),),
            ),
            StageSpec(
                name="tracking",
                algorithms=(AlgorithmSpec(name="tracker", plugin="kalman-tracker"),),
            ),
            StageSpec(
                name="planning", algorithms=(AlgorithmSpec(name="planner", plugin="idm-planner"),)
            ),
            StageSpec(
                name="control",
                algorithms=(AlgorithmSpec(name="controller", plugin="pure-pursuit-pid"),),
            ),
        )
    )


def _expect(value: Any, kind: type | tuple[type, ...], where: str, what: str) -> Any:
    if not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
        msg = f"{where}: {what}, got {value!r}"
        raise ConfigError(msg)
    return value


def _algorithm(raw: Any, where: str, base: Path) -> AlgorithmSpec:
    _expect(raw, dict, where, "expected a table with `plugin`")
    unknown = sorted(set(raw) - {"name", "plugin", "config"})
    if unknown:
        msg = f"{where}: unknown key(s) {', '.join(unknown)} (known: name, plugin, config)"
        raise ConfigError(msg)
    plugin = _expect(raw.get("plugin"), str, where, "`plugin` must be a string")
    # file.py:Class paths are relative to the pipeline file
    path_part, sep, cls = plugin.rpartition(":")
    if sep and path_part.endswith(".py") and not Path(path_part).is_absolute():
        plugin = f"{(base / path_part).as_posix()}:{cls}"
    name = _expect(raw.get("name", _default_name(plugin)), str, where, "`name` must be a string")
    if not _NAME.match(name):
        msg = f"{where}: name {name!r} must be letters, digits, '_', '-' or '.'"
        raise ConfigError(msg)
    config = _expect(raw.get("config", {}), dict, where, "`config` must be a table")
    return AlgorithmSpec(name=name, plugin=plugin, config=config)


def load_pipeline(path: str | Path) -> PipelineConfig:
    """Read a pipeline TOML file (format in this module's docstring).

    Raises:
        ConfigError: the file is missing, not TOML, or says something invalid (the message names
            the file and the key).
    """
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as err:
        msg = f"{path}: pipeline file not found"
        raise ConfigError(msg) from err
    except tomllib.TOMLDecodeError as err:
        msg = f"{path}: not valid TOML: {err}"
        raise ConfigError(msg) from err
    known = {"mode", "executor", "seed", "step_timeout_s", "fail_fast", "stage"}
    unknown = sorted(set(raw) - known)
    if unknown:
        msg = f"{path}: unknown key(s) {', '.join(unknown)} (known: {', '.join(sorted(known))})"
        raise ConfigError(msg)
    stages_raw = _expect(raw.get("stage", []), list, str(path), "`stage` must be [[stage]] tables")
    stages: list[StageSpec] = []
    for i, stage in enumerate(stages_raw):
        where = f"{path}: stage {i + 1}"
        _expect(stage, dict, where, "expected a table")
        name = _expect(stage.get("name", f"stage_{i + 1}"), str, where, "`name` must be a string")
        algos_raw = _expect(
            stage.get("algorithm", []), list, where, "`algorithm` must be [[stage.algorithm]]"
        )
        algos = tuple(
            _algorithm(a, f"{where} ({name}), algorithm {j + 1}", path.parent)
            for j, a in enumerate(algos_raw)
        )
        stages.append(StageSpec(name=name, algorithms=algos))
    timeout = raw.get("step_timeout_s")
    if timeout is not None:
        timeout = float(_expect(timeout, (int, float), str(path), "`step_timeout_s` is seconds"))
    try:
        return PipelineConfig(
            stages=tuple(stages),
            mode=raw.get("mode", "sequential"),
            executor=raw.get("executor", "threads"),
            seed=int(_expect(raw.get("seed", 0), int, str(path), "`seed` must be an integer")),
            step_timeout_s=timeout,
            fail_fast=bool(
                _expect(raw.get("fail_fast", False), bool, str(path), "`fail_fast` is true/false")
            ),
        )
    except ConfigError as err:
        msg = f"{path}: {err}"
        raise ConfigError(msg) from err
