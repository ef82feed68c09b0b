"""The pipeline a run executes (L1), as frozen dataclasses loaded from TOML.

A pipeline file (every key but the stages is optional; the CLI's flags override the file)::

    mode = "pipelined"        # "sequential" (each frame through all stages) or "pipelined"
    executor = "threads"      # how algorithms run: "threads" (in this process) or "processes"
    seed = 0                  # handed to every algorithm whose defaults have a "seed"
    step_timeout_s = 2.0      # a step running longer is recorded as timed out (worker process)
    max_rss_mb = 2048         # a worker process resident past this is killed (worker process)
    fail_fast = false         # stop at the first failed step instead of recording it

    [[stage]]
    name = "detection"

    [[stage.algorithm]]
    name = "clusters"                 # unique in the pipeline; default: the plugin's name
    plugin = "cluster-detector"       # entry-point name, package.module:Class or file.py:Class
    config = { voxel_m = 0.15 }

    [[stage]]
    name = "planning"
    max_rss_mb = 512          # this stage's own bound (else the pipeline's, or --max-rss)
    [[stage.algorithm]]
    plugin = "idm-planner"

Stages run in file order; the algorithms of one stage run side by side on the same frame and see
the outputs of every earlier stage.

``max_rss_mb`` bounds the resident memory of each algorithm's worker process (the interpreter and
its libraries included, ≈ 60-100 MB before the plugin allocates anything); a stage's own value
wins over the pipeline's, which ``--max-rss`` replaces.  Like ``step_timeout_s`` it runs the
algorithms in worker processes (an algorithm in the engine's process cannot be bounded without
bounding the engine): a step whose worker goes past it is killed, recorded as an error
``MemoryLimit`` on that frame, and a fresh worker takes the next frame
(:class:`redrive.engine.worker.ProcessRunner`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

from redrive.config.validate import Table, read_toml
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
        max_rss_mb: the memory bound of each of its algorithms' worker processes (MiB); None:
            the pipeline's.
    """

    name: str
    algorithms: tuple[AlgorithmSpec, ...]
    role: str | None = None
    max_rss_mb: float | None = None


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
        max_rss_mb: the memory bound (MiB, resident set) of every algorithm's worker process
            whose stage sets none (forces worker processes); None for none.
    """

    stages: tuple[StageSpec, ...]
    mode: RunMode = "sequential"
    executor: Executor = "threads"
    seed: int = 0
    step_timeout_s: float | None = None
    fail_fast: bool = False
    max_rss_mb: float | None = None

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
        for where, bound in (
            ("max_rss_mb", self.max_rss_mb),
            *((f"stage {s.name!r}: max_rss_mb", s.max_rss_mb) for s in self.stages),
        ):
            if bound is not None and not bound > 0:
                msg = f"{where} must be > 0 MiB, got {bound}"
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

    def max_rss_mb_of(self, stage: str) -> float | None:
        """The memory bound (MiB) of the algorithms of the stage named ``stage``: its own, else
        the pipeline's (None: unbounded)."""
        own = next((s.max_rss_mb for s in self.stages if s.name == stage), None)
        return own if own is not None else self.max_rss_mb

    @property
    def max_rss_by_stage(self) -> dict[str, float]:
        """Stage name → its memory bound (MiB), for the bounded stages."""
        out = {s.name: self.max_rss_mb_of(s.name) for s in self.stages}
        return {name: bound for name, bound in out.items() if bound is not None}

    @property
    def isolated(self) -> bool:
        """Whether the algorithms run in worker processes: asked for, or needed by a step
        timeout or a memory bound."""
        return (
            self.executor == "processes"
            or self.step_timeout_s is not None
            or bool(self.max_rss_by_stage)
        )

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


def object_level_pipeline(*, planning: bool = True) -> PipelineConfig:
    """The baseline for a log of recorded traffic without a LiDAR (Waymo Open Motion,
    CommonRoad): ground truth through the noisy oracle → Kalman tracker → IDM planner → pure
    pursuit; without ``planning`` the perception stages only (a log that records no ego
    motion to plan from)."""
    reference = reference_pipeline()
    rest = reference.stages[1:] if planning else reference.stages[1:2]
    return PipelineConfig(
        stages=(
            StageSpec(
                name="detection",
                algorithms=(AlgorithmSpec(name="oracle", plugin="noisy-oracle"),),
            ),
            *rest,
        )
    )


def _algorithm(t: Table, base: Path) -> AlgorithmSpec:
    t.check_keys({"name", "plugin", "config"})
    if not isinstance(t.data.get("plugin"), str):
        raise t.fail(
            "plugin",
            f"`plugin` must be a string, got {t.data.get('plugin')!r}",
            'add plugin = "entry-point-name", "package.module:Class" or "file.py:Class"',
        )
    plugin: str = t.data["plugin"]
    # file.py:Class paths are relative to the pipeline file
    path_part, sep, cls = plugin.rpartition(":")
    if sep and path_part.endswith(".py") and not Path(path_part).is_absolute():
        plugin = f"{(base / path_part).as_posix()}:{cls}"
    name = t.text("name", _default_name(plugin))
    if not _NAME.match(name):
        raise t.fail("name", f"{name!r} is not a name", "use letters, digits, '_', '-' or '.'")
    return AlgorithmSpec(name=name, plugin=plugin, config=dict(t.mapping("config", {})))


def load_pipeline(path: str | Path) -> PipelineConfig:
    """Read a pipeline TOML file (format in this module's docstring).

    Raises:
        ConfigError: the file is missing, not TOML, or says something invalid (the message names
            the file and the key).
    """
    path = Path(path)
    top = Table(read_toml(path, what="pipeline file"), source=str(path))
    top.check_keys(
        {"mode", "executor", "seed", "step_timeout_s", "fail_fast", "max_rss_mb", "stage"}
    )
    stages: list[StageSpec] = []
    for i, stage in enumerate(top.tables("stage", [], fix="write each stage as [[stage]]")):
        stage.check_keys({"name", "algorithm", "max_rss_mb"})
        name = stage.text("name", f"stage_{i + 1}")
        algos = stage.tables("algorithm", [], fix="write each as [[stage.algorithm]]")
        specs = tuple(_algorithm(a, path.parent) for a in algos)
        bound = stage.number("max_rss_mb", None, positive=True)
        stages.append(StageSpec(name=name, algorithms=specs, max_rss_mb=bound))
    try:
        return PipelineConfig(
            stages=tuple(stages),
            mode=top.text("mode", "sequential"),
            executor=top.text("executor", "threads"),
            seed=top.integer("seed", 0),
            step_timeout_s=top.number("step_timeout_s", None),
            fail_fast=top.flag("fail_fast", False),
            max_rss_mb=top.number("max_rss_mb", None, positive=True),
        )
    except ConfigError as err:
        if str(err).startswith(str(path)):
            raise
        msg = f"{path}: {err}"
        raise ConfigError(msg) from err
