"""The matrix of a batch: logs × pipelines × loop modes, from the command line or a TOML spec.

A batch spec file (``redrive batch --spec batch.toml``; relative paths are relative to the file)::

    logs = ["drives/*.mcap", "fleet.txt", "drives/night", "urban@3", "cut_in"]
    seeds = "0-3"            # scenario names without @SEED run once per seed (default: their own)
    duration_s = 2.0         # synthetic scenarios only (default: the scenario's duration)
    loop = "open"            # "open", "closed" or "both"
    agents = "replay"        # closed loop: "replay" or "reactive"
    on_collision = "continue"  # closed loop: "continue" (count it, as nuPlan) or "stop"
    out = "batches/nightly"  # the batch directory
    executor = "local"       # "local" or "ray"
    workers = 2              # default: the number of cores
    retries = 1              # a cell whose worker died is run again up to this many times
    fail_fast = false        # a failed step fails its cell (default: recorded, the run goes on)
    map = "maps/lanelet2_map.osm"  # a road map for every recorded log (as `redrive run --map`)
    map_origin = "49.0,8.4"  # its projection origin (`--map-origin`); no_map = true: no map at all

    [[pipeline]]
    file = "pipelines/a.toml"        # a pipeline file, as `redrive run --pipeline` takes

    [[pipeline]]
    name = "idm"                     # default: the file's stem, else "flags"
    planning = ["idm-planner"]       # or plugins, as --perception/--planning/--control
    control = ["pure-pursuit-pid"]

A log entry is a log (file or ROS 2 bag directory), a glob, a directory (the logs in it: what a
registered reader recognises — ``.bag`` and ``.mcap`` files, ROS 2 bag directories, KITTI and
nuScenes folders, a reader plugin's logs), a ``.txt`` file of such entries (one a line, ``#``
comments), or a synthetic scenario: a name of ``redrive synth --list`` or a scenario
``.toml`` with an optional ``@SEED``.  No pipeline means the reference pipeline.
"""

from __future__ import annotations

import glob
import hashlib
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from redrive.config import PipelineConfig, load_pipeline, pipeline_from_plugins, reference_pipeline
from redrive.config.validate import Table, is_integer, read_toml
from redrive.errors import ConfigError
from redrive.sim.scenario import list_scenarios

__all__ = [
    "LOOP_MODES",
    "BatchSpec",
    "LogItem",
    "LoopMode",
    "PipelineItem",
    "expand_logs",
    "load_batch_spec",
    "make_pipeline_item",
    "parse_seeds",
    "pipeline_hash",
    "safe_name",
    "unique_pipelines",
]

LoopMode = Literal["open", "closed"]
#: what ``--loop`` takes: one mode or both.
LOOP_MODES: Mapping[str, tuple[LoopMode, ...]] = {
    "open": ("open",),
    "closed": ("closed",),
    "both": ("open", "closed"),
}
_LOG_SUFFIXES = (".bag", ".mcap", ".db3")
_SEEDS = re.compile(r"^(\d+)(?:-(\d+))?$")
_ID_CHARS = re.compile(r"[^A-Za-z0-9_.@+\-]")


@dataclass(frozen=True, slots=True, kw_only=True)
class LogItem:
    """One log of the matrix: a recorded log (``path``) or a synthetic scenario (``scenario``,
    ``seed`` or None for the scenario's own).  ``log_id`` names its cells' directories."""

    log_id: str
    path: str | None = None
    scenario: str | None = None
    seed: int | None = None

    def describe(self) -> str:
        return self.path if self.path is not None else self.log_id


@dataclass(frozen=True, slots=True, kw_only=True)
class PipelineItem:
    """One pipeline of the matrix: a pipeline file, or plugins per role (none at all: the
    reference pipeline).  Workers rebuild the :class:`PipelineConfig` from these strings."""

    name: str
    file: str | None = None
    perception: tuple[str, ...] = ()
    planning: tuple[str, ...] = ()
    control: tuple[str, ...] = ()

    def load(self, *, fail_fast: bool = False) -> PipelineConfig:
        """The pipeline (raises ConfigError as ``redrive run`` does for a bad file or plugin)."""
        if self.file is not None:
            config = load_pipeline(self.file)
        elif self.perception or self.planning or self.control:
            config = pipeline_from_plugins(
                perception=self.perception, planning=self.planning, control=self.control
            )
        else:
            config = reference_pipeline()
        return config.with_options(fail_fast=True if fail_fast else None)

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "file": self.file,
            "perception": list(self.perception),
            "planning": list(self.planning),
            "control": list(self.control),
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class BatchSpec:
    """The whole matrix and how to run it (the TOML keys of the module docstring)."""

    logs: tuple[LogItem, ...]
    pipelines: tuple[PipelineItem, ...]
    loops: tuple[LoopMode, ...] = ("open",)
    duration_s: float | None = None
    agents: Literal["replay", "reactive"] = "replay"
    on_collision: Literal["continue", "stop"] = "continue"
    fail_fast: bool = False
    options: Mapping[str, Any] = field(default_factory=dict)  # out, executor, workers, retries
    #: ``--map`` / ``map``: the road map of every recorded log, its origin, ``--no-map``
    map_file: str | None = None
    map_origin: tuple[float, float] | None = None
    no_map: bool = False

    def to_json(self) -> dict[str, Any]:
        return {
            "logs": [
                {"log_id": x.log_id, "path": x.path, "scenario": x.scenario, "seed": x.seed}
                for x in self.logs
            ],
            "pipelines": [p.to_json() for p in self.pipelines],
            "loops": list(self.loops),
            "duration_s": self.duration_s,
            "agents": self.agents,
            "on_collision": self.on_collision,
            "fail_fast": self.fail_fast,
            "map": self.map_file,
            "map_origin": None if self.map_origin is None else list(self.map_origin),
            "no_map": self.no_map,
        }


def parse_seeds(text: str) -> tuple[int, ...]:
    """``"0-7"`` → 0…7, ``"3"`` → (3,), ``"1,4,9"`` and mixes (``"0-2,7"``) too."""
    seeds: list[int] = []
    for part in str(text).split(","):
        match = _SEEDS.match(part.strip())
        if not match:
            msg = f"seeds {text!r}: expected N, A-B or a comma list of them (e.g. 0-7)"
            raise ConfigError(msg)
        first = int(match[1])
        last = int(match[2]) if match[2] else first
        if last < first:
            msg = f"seeds {text!r}: {part.strip()} ends before it starts"
            raise ConfigError(msg)
        seeds.extend(range(first, last + 1))
    return tuple(dict.fromkeys(seeds))


def _is_scenario(name: str) -> bool:
    return name in list_scenarios() or (name.endswith(".toml") and Path(name).is_file())


def _is_log(path: Path) -> bool:
    """Whether a registered reader (redrive's, an installed plugin, one ``REDRIVE_READERS``
    names) recognises ``path`` as one log.  A folder of split MCAP files is not one log here:
    each of its files is."""
    from redrive.io.readers import recognised_format

    return recognised_format(path, sets=False) is not None


def _logs_in_dir(path: Path) -> list[Path]:
    if _is_log(path):
        return [path]
    entries = sorted(path.iterdir())
    found = [p for p in entries if _is_log(p)]
    if not found:
        msg = (
            f"{path}: a directory with no logs in it (nothing in it is a log a reader "
            "recognises: .bag, .mcap, ROS 2 bag directories, KITTI, nuScenes, reader plugins)"
        )
        raise ConfigError(msg)
    if len(found) < len(entries):
        import logging

        left = [p.name for p in entries if p not in found]
        logging.getLogger(__name__).info(
            "%s: %d entries no reader recognises are not logs: %s", path, len(left), left[:5]
        )
    return found


def _expand_one(entry: str, base: Path, seeds: Sequence[int], depth: int) -> list[LogItem | Path]:
    name, at, seed_text = entry.rpartition("@")
    if not at:
        name, seed_text = entry, ""
    scenario = name if _is_scenario(name) else None
    if scenario is None and name.endswith(".toml") and _is_scenario(str(base / name)):
        scenario = str(base / name)
    if scenario is not None:
        stem = safe_name(Path(scenario).stem) if scenario.endswith(".toml") else scenario
        if seed_text:
            chosen: Sequence[int | None] = parse_seeds(seed_text)
        else:
            chosen = list(seeds) or [None]
        return [
            LogItem(log_id=stem if s is None else f"{stem}@{s}", scenario=scenario, seed=s)
            for s in chosen
        ]
    path = Path(entry) if Path(entry).is_absolute() else base / entry
    if glob.has_magic(entry):
        matches = sorted(Path(p) for p in glob.glob(str(path), recursive=True))
        if not matches:
            msg = f"{entry}: the pattern matches no file"
            raise ConfigError(msg)
        return [m for m in matches if _is_log(m)]
    if path.is_dir():
        return list(_logs_in_dir(path))
    if path.suffix == ".txt" and path.is_file():
        if depth > 4:
            raise ConfigError(f"{entry}: lists of logs nest more than 4 deep")
        out: list[LogItem | Path] = []
        for raw_line in path.read_text(encoding="utf-8").splitlines():
            line = raw_line.split("#", 1)[0].strip()
            if line:
                out.extend(_expand_one(line, path.parent, seeds, depth + 1))
        return out
    if not path.exists():
        msg = (
            f"{entry}: no such log, directory, list of logs (.txt) or scenario "
            "(`redrive synth --list` lists the scenarios)"
        )
        raise ConfigError(msg)
    return [path]


def expand_logs(
    entries: Sequence[str], *, base: Path = Path(), seeds: Sequence[int] = ()
) -> tuple[LogItem, ...]:
    """The logs of ``entries`` (paths, globs, directories, ``.txt`` lists, scenarios with seeds),
    each once, in the order given; each gets a unique ``log_id``: the file's stem made a safe
    directory name (:func:`safe_name`), with a short hash of its path when it equals another
    log's or scenario's id (case aside).

    Raises:
        ConfigError: an entry matches nothing, or no log at all.
    """
    items: list[LogItem | Path] = []
    for entry in entries:
        items.extend(_expand_one(str(entry), base, seeds, 0))
    seen: set[str] = set()
    unique: list[LogItem | Path] = []
    for item in items:
        key = str(item.resolve()) if isinstance(item, Path) else item.log_id
        if key not in seen:
            seen.add(key)
            unique.append(item)
    names = [_stem(x) if isinstance(x, Path) else x.log_id for x in unique]
    folded = [n.casefold() for n in names]
    logs: list[LogItem] = []
    for item, stem in zip(unique, names, strict=True):
        if isinstance(item, LogItem):
            logs.append(item)
            continue
        resolved = str(item.resolve())
        # two logs never share a cell directory: a stem that another log's (or scenario's) name
        # equals — case aside, for case-insensitive file systems — gets a hash of its path
        log_id = stem
        if folded.count(stem.casefold()) > 1:
            log_id = f"{stem}-{hashlib.sha256(resolved.encode()).hexdigest()[:8]}"
        logs.append(LogItem(log_id=log_id, path=resolved))
    if not logs:
        raise ConfigError("the batch has no logs: give paths, globs, directories or scenarios")
    ids = [x.log_id.casefold() for x in logs]
    clash = sorted({x.log_id for x in logs if ids.count(x.log_id.casefold()) > 1})
    if clash:
        msg = f"two logs are both named {clash[0]!r} in the batch (two scenarios?)"
        raise ConfigError(msg)
    return tuple(logs)


def safe_name(text: str) -> str:
    """``text`` as one directory name: a character outside ``A-Z a-z 0-9 _ . @ + -`` becomes
    ``_``, and so does every leading dot — ``.``, ``..`` and hidden names never name a cell's
    directory (a log ``..mcap`` is ``_``, ``...mcap`` is ``__``)."""
    name = _ID_CHARS.sub("_", text)
    bare = name.lstrip(".")
    return "_" * (len(name) - len(bare)) + bare if name else "log"


def _stem(path: Path) -> str:
    stem = path.name
    for suffix in _LOG_SUFFIXES:
        stem = stem.removesuffix(suffix)
    return safe_name(stem)


def pipeline_hash(config: PipelineConfig) -> str:
    """sha256 of the pipeline as run: stages, algorithms (plugin, config), mode, executor, seed,
    timeout, fail-fast, and the bytes of every ``file.py:Class`` plugin's file."""
    stages = []
    for stage in config.stages:
        algos = []
        for algo in stage.algorithms:
            entry: dict[str, Any] = {
                "name": algo.name,
                "plugin": algo.plugin,
                "config": json.loads(json.dumps(dict(algo.config), sort_keys=True, default=str)),
            }
            module = algo.plugin.rsplit(":", 1)[0]
            if module.endswith(".py") and Path(module).is_file():
                entry["file_sha256"] = hashlib.sha256(Path(module).read_bytes()).hexdigest()
            algos.append(entry)
        stages.append({"name": stage.name, "algorithms": algos})
    canonical: dict[str, Any] = {
        "stages": stages,
        "mode": config.mode,
        "executor": config.executor,
        "seed": config.seed,
        "step_timeout_s": config.step_timeout_s,
        "fail_fast": config.fail_fast,
    }
    if (
        config.max_rss_by_stage
    ):  # only when set: the hashes of unbounded pipelines stay as they were
        canonical["max_rss_mb"] = config.max_rss_by_stage
    text = json.dumps(canonical, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _pipeline_items(doc: Table, base: Path) -> tuple[PipelineItem, ...]:
    items = []
    for entry in doc.tables("pipeline", [], fix="write each pipeline as [[pipeline]]"):
        entry.check_keys({"name", "file", "perception", "planning", "control"})
        plugins = {
            role: entry.texts(role, (), one_ok=True, fix=f"give `{role}` a list of plugin names")
            for role in ("perception", "planning", "control")
        }
        file = entry.text("file", None)
        if file is not None and any(plugins.values()):
            raise entry.fail(
                "file", "given with plugins", "give either `file` or plugins, not both"
            )
        if file is not None:
            file = str(Path(file) if Path(file).is_absolute() else base / file)
        name = entry.text("name", None)
        items.append(make_pipeline_item(name=name, file=file, **plugins))
    return tuple(items)


def make_pipeline_item(
    *,
    name: str | None,
    file: str | None = None,
    perception: Sequence[str] = (),
    planning: Sequence[str] = (),
    control: Sequence[str] = (),
) -> PipelineItem:
    """A pipeline item named ``name``, else the file's stem, else ``flags`` (``reference`` for
    no plugin at all)."""
    if name is None:
        if file is not None:
            name = safe_name(Path(file).stem)
        else:
            name = "flags" if (perception or planning or control) else "reference"
    if not name or _ID_CHARS.search(name) or name.startswith("."):
        msg = (
            f"pipeline name {name!r}: use letters, digits, '.', '_', '-', not starting with '.' "
            "(it names the directory of its cells)"
        )
        raise ConfigError(msg)
    return PipelineItem(
        name=name,
        file=file,
        perception=tuple(perception),
        planning=tuple(planning),
        control=tuple(control),
    )


def unique_pipelines(items: Sequence[PipelineItem]) -> tuple[PipelineItem, ...]:
    """``items``, refusing two with one name (their run directories would collide)."""
    names = [p.name.casefold() for p in items]
    clash = sorted({p.name for p in items if names.count(p.name.casefold()) > 1})
    if clash:
        msg = (
            f"two pipelines are named {clash[0]!r}: give each a `name` (spec) or rename a file "
            "(the name is the directory of its cells)"
        )
        raise ConfigError(msg)
    return tuple(items) or (make_pipeline_item(name=None),)


_SPEC_KEYS = {
    "logs",
    "seeds",
    "duration_s",
    "loop",
    "agents",
    "on_collision",
    "out",
    "executor",
    "workers",
    "retries",
    "fail_fast",
    "address",
    "pipeline",
    "map",
    "map_origin",
    "no_map",
}


def _origin(text: str, *, where: str) -> tuple[float, float]:
    try:
        lat, lon = (float(v) for v in text.split(","))
    except ValueError as err:
        raise ConfigError(f'{where}: expected "LAT,LON" in degrees, got {text!r}') from err
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise ConfigError(f"{where}: {text!r} is no latitude, longitude")
    return lat, lon


def load_batch_spec(path: Path) -> dict[str, Any]:
    """The keys of a batch spec file, checked and with paths resolved against its directory
    (``logs`` expanded to :class:`LogItem`, ``pipeline`` to :class:`PipelineItem`); the CLI lays
    its flags over them.

    Raises:
        ConfigError: the file is missing, not TOML, or a key is unknown or of the wrong type.
    """
    doc = Table(read_toml(path, what="batch spec"), source=str(path))
    doc.check_keys(_SPEC_KEYS)
    base = path.parent
    out: dict[str, Any] = {}
    for key in ("loop", "agents", "on_collision", "out", "executor", "address"):
        if key in doc:
            out[key] = doc.text(key)
    for key in ("workers", "retries"):
        if key in doc:
            out[key] = doc.integer(key)
    if "duration_s" in doc:
        out["duration_s"] = doc.number("duration_s")
    if "fail_fast" in doc:
        out["fail_fast"] = doc.flag("fail_fast")
    if "no_map" in doc:
        out["no_map"] = doc.flag("no_map")
    if "map" in doc:
        found = Path(doc.text("map"))
        out["map"] = str(found if found.is_absolute() else base / found)
    if "map_origin" in doc:
        out["map_origin"] = _origin(doc.text("map_origin"), where=f"{path}: map_origin")
    if "seeds" in doc:
        out["seeds"] = doc.value("seeds", lambda v: isinstance(v, str) or is_integer(v), "0-3 or 3")
    if "out" in out:
        out["out"] = Path(out["out"]) if Path(out["out"]).is_absolute() else base / out["out"]
    seeds = parse_seeds(str(out.pop("seeds"))) if "seeds" in out else ()
    logs = doc.texts("logs", ())
    out["logs"] = expand_logs(logs, base=base, seeds=seeds) if logs else ()
    out["pipelines"] = _pipeline_items(doc, base)
    return out
