"""Plugin discovery: entry points of real (tmp) distributions, module:Class, file.py:Class, and an
error that says what, where and what to do for every way a spec can go wrong."""

from __future__ import annotations

import importlib.metadata
import json
import logging
import os
import sys
import textwrap
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from redrive.algorithms import Algorithm, Role
from redrive.algorithms.discovery import (
    ENTRY_POINT_GROUP,
    AlgorithmRegistry,
    BrokenPlugin,
    describe,
    installed_algorithms,
    load_algorithm_class,
)
from redrive.errors import PluginError

GOOD = '''
from types import MappingProxyType

import numpy as np

from redrive.algorithms import VEHICLE_STATE, Algorithm, Role
from redrive.types import SensorType


class GoodDetector(Algorithm):
    """Finds nothing, for tests.

    A second paragraph that the summary leaves out.
    """

    role = Role.PERCEPTION
    inputs = (SensorType.LIDAR, VEHICLE_STATE)
    version = "2.5"
    defaults = MappingProxyType(
        {"threshold_m": 0.5, "mode": Role.PLANNING, "sizes": (1, 2), "gain": np.float64(3.0)}
    )

    def step(self, frame, upstream):
        return []


class HelperPlanner(Algorithm):
    """Plans nothing."""

    role = Role.PLANNING

    def step(self, frame, upstream):
        raise NotImplementedError
'''

EXPECTED_REFERENCE = {
    "cluster-detector": "redrive.algorithms.reference.detector:ClusterDetector",
    "kalman-tracker": "redrive.algorithms.reference.tracker:KalmanTracker",
    "noisy-oracle": "redrive.algorithms.reference.oracle:NoisyOracle",
    "idm-planner": "redrive.algorithms.reference.planner:IdmPlanner",
    "pure-pursuit-pid": "redrive.algorithms.reference.controller:PurePursuitPid",
    "log-future-planner": "redrive.algorithms.reference.log_future:LogFuturePlanner",
}


def write_dist(
    site: Path,
    dist: str,
    *,
    entry_points: dict[str, str],
    modules: dict[str, str] | None = None,
    group: str = ENTRY_POINT_GROUP,
) -> None:
    """An installed distribution as pip leaves it: ``NAME-1.0.dist-info`` with METADATA and
    entry_points.txt, plus its modules (``{"pkg/mod.py": source}``) in ``site``."""
    info = site / f"{dist.replace('-', '_')}-1.0.dist-info"  # escaped like pip does
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 1.0\n")
    lines = [f"[{group}]"] + [f"{k} = {v}" for k, v in entry_points.items()]
    (info / "entry_points.txt").write_text("\n".join(lines) + "\n")
    for rel, source in (modules or {}).items():
        path = site / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        (path.parent / "__init__.py").touch()
        path.write_text(textwrap.dedent(source))


@pytest.fixture
def site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A fresh site directory on sys.path; the modules imported from it are forgotten after."""
    root = tmp_path / "site"
    root.mkdir()
    monkeypatch.syspath_prepend(str(root))
    before = set(sys.modules)
    yield root
    for name in set(sys.modules) - before:
        module = sys.modules.get(name)
        where = getattr(module, "__file__", None) or ""
        if where.startswith(str(tmp_path)) or name.startswith("redrive_user_"):
            del sys.modules[name]


def unique(prefix: str) -> str:
    return f"{prefix}_{uuid.uuid4().hex[:8]}"


# -- entry points ---------------------------------------------------------------------------------


def test_entry_point_by_name_and_in_the_registry(site: Path) -> None:
    pkg, dist = unique("fxpkg"), unique("fx-dist")
    write_dist(
        site,
        dist,
        entry_points={"fx-good": f"{pkg}.algos:GoodDetector"},
        modules={f"{pkg}/algos.py": GOOD},
    )
    cls = load_algorithm_class("fx-good")
    assert cls.__name__ == "GoodDetector"
    assert cls.__module__ == f"{pkg}.algos"

    registry = installed_algorithms()
    assert registry["fx-good"] is cls
    assert "fx-good" in list(registry)
    assert registry.target("fx-good") == f"{pkg}.algos:GoodDetector"
    info = registry.info("fx-good")
    assert info.name == "fx-good"
    assert info.role is Role.PERCEPTION
    assert info.inputs == ("lidar", "vehicle_state")
    assert info.version == "2.5"
    assert info.summary == "Finds nothing, for tests."
    assert info.distribution == f"{dist} 1.0"
    assert info.defaults["threshold_m"] == 0.5
    as_json = json.loads(json.dumps(info.to_json()))
    assert as_json["defaults"] == {
        "threshold_m": 0.5,
        "mode": "planning",
        "sizes": [1, 2],
        "gain": 3.0,
    }
    assert as_json["role"] == "perception"


def test_duplicate_names_are_refused_naming_both_targets(site: Path) -> None:
    pkg = unique("fxdup")
    one, two = unique("fx-one"), unique("fx-two")
    write_dist(site, one, entry_points={"fx-same": f"{pkg}.a:GoodDetector"})
    write_dist(
        site,
        two,
        entry_points={"fx-same": f"{pkg}.b:HelperPlanner"},
        modules={f"{pkg}/a.py": GOOD, f"{pkg}/b.py": GOOD},
    )
    for attempt in (installed_algorithms, lambda: load_algorithm_class("fx-same")):
        with pytest.raises(PluginError) as err:
            attempt()
        msg = str(err.value)
        assert "'fx-same'" in msg
        assert f"{pkg}.a:GoodDetector" in msg
        assert f"{pkg}.b:HelperPlanner" in msg
        assert one in msg
        assert two in msg
        assert "uninstall one" in msg


def test_duplicates_through_the_entry_points_hook(monkeypatch: pytest.MonkeyPatch) -> None:
    eps = importlib.metadata.EntryPoints(
        [
            importlib.metadata.EntryPoint("twin", "json:JSONDecoder", ENTRY_POINT_GROUP),
            importlib.metadata.EntryPoint("twin", "json:JSONEncoder", ENTRY_POINT_GROUP),
        ]
    )

    def fake(**params: str) -> importlib.metadata.EntryPoints:
        assert params == {"group": ENTRY_POINT_GROUP}
        return eps

    monkeypatch.setattr(importlib.metadata, "entry_points", fake)
    with pytest.raises(PluginError, match=r"json:JSONDecoder.*json:JSONEncoder"):
        installed_algorithms()


def test_registry_refuses_a_taken_name() -> None:
    good = _good_class()
    registry = AlgorithmRegistry()
    registry.register("x", good, target="a.b:Good")
    with pytest.raises(PluginError, match=r"'x'.*'a\.b:Good'.*'c\.d:Other'"):
        registry.register("x", good, target="c.d:Other")
    with pytest.raises(PluginError, match="'x'"):
        registry.add_broken(BrokenPlugin(name="x", target="e:F", distribution=None, error="e"))
    assert len(registry) == 1


def test_a_broken_entry_point_is_reported_not_fatal(
    site: Path, caplog: pytest.LogCaptureFixture
) -> None:
    pkg, dist = unique("fxbroken"), unique("fx-broken")
    write_dist(
        site,
        dist,
        entry_points={
            "fx-ok": f"{pkg}.good:GoodDetector",
            "fx-raises": f"{pkg}.bad:Anything",
            "fx-missing": f"{pkg}.nowhere:Anything",
            "fx-not-algo": f"{pkg}.good:np",
        },
        modules={f"{pkg}/good.py": GOOD, f"{pkg}/bad.py": "raise RuntimeError('no GPU here')\n"},
    )
    with caplog.at_level(logging.WARNING, logger="redrive.algorithms.discovery"):
        registry = installed_algorithms()
    assert "fx-ok" in registry
    broken = registry.broken
    assert {"fx-raises", "fx-missing", "fx-not-algo"} <= set(broken)
    assert "RuntimeError: no GPU here" in broken["fx-raises"].error
    assert f"{pkg}/bad.py" in broken["fx-raises"].error
    assert "not found" in broken["fx-missing"].error
    assert "reinstall" in broken["fx-missing"].error
    assert "not a class" in broken["fx-not-algo"].error
    assert broken["fx-raises"].distribution == f"{dist} 1.0"
    assert broken["fx-raises"].target == f"{pkg}.bad:Anything"
    warned = "\n".join(r.getMessage() for r in caplog.records)
    assert "fx-raises" in warned
    assert "fx-missing" in warned
    # and by name, the same error is raised
    with pytest.raises(PluginError, match="no GPU here"):
        load_algorithm_class("fx-raises")


def test_unknown_name_lists_the_installed_ones(site: Path) -> None:
    pkg = unique("fxname")
    write_dist(
        site,
        unique("fx-names"),
        entry_points={"fx-lidar-detector": f"{pkg}.m:GoodDetector"},
        modules={f"{pkg}/m.py": GOOD},
    )
    with pytest.raises(PluginError) as err:
        load_algorithm_class("fx-lidar-detectr")
    msg = str(err.value)
    assert "no installed algorithm is named 'fx-lidar-detectr'" in msg
    assert "did you mean fx-lidar-detector" in msg
    assert "path/to/file.py:ClassName" in msg
    with pytest.raises(PluginError, match=r"give mypkg\.detectors:ClassName"):
        load_algorithm_class("mypkg.detectors")


def test_nothing_registers_itself_on_import(tmp_path: Path, site: Path) -> None:
    path = tmp_path / "lonely.py"
    path.write_text(GOOD)
    before = set(installed_algorithms()) | set(installed_algorithms().broken)
    cls = load_algorithm_class(f"{path}:GoodDetector")
    after = installed_algorithms()
    assert set(after) | set(after.broken) == before
    assert cls not in after.values()


def test_every_declared_reference_algorithm_loads() -> None:
    """Each entry point redrive's own pyproject declares loads to a usable algorithm class."""
    declared = {
        ep.name: ep.value
        for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
        if ep.dist is not None and ep.dist.name == "redrive"
    }
    assert declared == EXPECTED_REFERENCE
    registry = installed_algorithms()
    for name, target in declared.items():
        cls = load_algorithm_class(name)
        assert registry[name] is cls, registry.broken.get(name)
        info = describe(cls, name=name)
        assert info.target == target
        assert info.summary, f"{target} has no docstring"
        cls().configure({})  # its defaults are a valid configuration


# -- module:Class ---------------------------------------------------------------------------------


def test_module_colon_class(site: Path) -> None:
    pkg = unique("fxmod")
    write_dist(site, unique("fx-mod"), entry_points={}, modules={f"{pkg}/algos.py": GOOD})
    cls = load_algorithm_class(f"{pkg}.algos:GoodDetector")
    assert cls.role is Role.PERCEPTION
    assert describe(cls).target == f"{pkg}.algos:GoodDetector"
    assert describe(cls).name == "GoodDetector"
    assert load_algorithm_class(f"  {pkg}.algos:HelperPlanner ").role is Role.PLANNING


def test_module_not_found(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(PluginError) as err:
        load_algorithm_class("fx_no_such_module.sub:Thing")
    msg = str(err.value)
    assert "'fx_no_such_module.sub:Thing'" in msg
    assert "module fx_no_such_module not found" in msg
    assert "pip install" in msg
    # a file of that name in the cwd: the message says to give its path
    monkeypatch.chdir(tmp_path)
    (tmp_path / "fx_here.py").write_text(GOOD)
    with pytest.raises(PluginError, match=r"\./fx_here\.py:ClassName"):
        load_algorithm_class("fx_here:GoodDetector")


def test_module_whose_own_import_fails(site: Path) -> None:
    pkg = unique("fxdep")
    write_dist(
        site,
        unique("fx-dep"),
        entry_points={},
        modules={f"{pkg}/algos.py": "import fx_missing_dependency\n" + GOOD},
    )
    with pytest.raises(PluginError) as err:
        load_algorithm_class(f"{pkg}.algos:GoodDetector")
    msg = str(err.value)
    assert f"importing module {pkg}.algos raised ModuleNotFoundError" in msg
    assert "fx_missing_dependency" in msg
    assert "algos.py:1" in msg


# -- file.py:Class --------------------------------------------------------------------------------


def test_file_specs_absolute_relative_and_implicit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, site: Path
) -> None:
    (tmp_path / "algos").mkdir()
    path = tmp_path / "algos" / "mine.py"
    path.write_text(GOOD)
    cls = load_algorithm_class(f"{path}:GoodDetector")
    assert cls.role is Role.PERCEPTION
    assert describe(cls).target == f"{path}:GoodDetector"
    monkeypatch.chdir(tmp_path)
    assert load_algorithm_class("algos/mine.py:GoodDetector") is cls  # same file, same class
    assert load_algorithm_class("./algos/mine.py:GoodDetector") is cls
    # without a class the file must define exactly one usable Algorithm subclass; this has two
    with pytest.raises(
        PluginError, match=r"defines 2 usable Algorithm subclasses \(GoodDetector, "
    ):
        load_algorithm_class("algos/mine.py")
    single = tmp_path / "single.py"
    single.write_text(GOOD.split("class HelperPlanner", maxsplit=1)[0])
    assert load_algorithm_class("single.py").__name__ == "GoodDetector"
    assert str(tmp_path) not in sys.path
    assert str(tmp_path / "algos") not in sys.path


def test_two_files_of_one_name_do_not_collide(tmp_path: Path, site: Path) -> None:
    sources = {}
    for side, role in (("left", "PERCEPTION"), ("right", "PLANNING")):
        folder = tmp_path / side
        folder.mkdir()
        sources[side] = folder / "detector.py"
        sources[side].write_text(
            GOOD.replace("role = Role.PERCEPTION", f"role = Role.{role}").replace(
                'version = "2.5"', f'version = "{side}"'
            )
        )
    left = load_algorithm_class(f"{sources['left']}:GoodDetector")
    right = load_algorithm_class(f"{sources['right']}:GoodDetector")
    assert left is not right
    assert left.__module__ != right.__module__
    assert (left.role, left.version) == (Role.PERCEPTION, "left")
    assert (right.role, right.version) == (Role.PLANNING, "right")
    assert sys.modules[left.__module__].__file__ == str(sources["left"])


def test_an_edited_file_is_loaded_again(tmp_path: Path, site: Path) -> None:
    path = tmp_path / "edited.py"
    path.write_text(GOOD)
    first = load_algorithm_class(f"{path}:GoodDetector")
    path.write_text(GOOD.replace('version = "2.5"', 'version = "2.6-edited"'))
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    second = load_algorithm_class(f"{path}:GoodDetector")
    assert second is not first
    assert second.version == "2.6-edited"


def test_file_not_found(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(PluginError) as err:
        load_algorithm_class("missing/detector.py:Det")
    msg = str(err.value)
    assert "'missing/detector.py:Det'" in msg
    assert f"file {tmp_path / 'missing' / 'detector.py'} not found" in msg
    assert f"current directory, {tmp_path}" in msg
    (tmp_path / "adir.py").mkdir()
    with pytest.raises(PluginError, match="is a directory"):
        load_algorithm_class("adir.py:Det")


def test_file_that_raises_on_import(tmp_path: Path, site: Path) -> None:
    path = tmp_path / "raiser.py"
    path.write_text(GOOD + "\n\nraise ValueError('calibration file missing')\n")
    with pytest.raises(PluginError) as err:
        load_algorithm_class(f"{path}:GoodDetector")
    msg = str(err.value)
    assert "ValueError: calibration file missing" in msg
    assert f"{path}:{GOOD.count(chr(10)) + 3}" in msg  # the line that raised
    assert "fix the file" in msg
    assert isinstance(err.value.__cause__, ValueError)
    assert not any(getattr(m, "__file__", None) == str(path) for m in list(sys.modules.values())), (
        "a failed import must not stay in sys.modules"
    )


def test_file_with_a_syntax_error_or_a_missing_sibling(tmp_path: Path, site: Path) -> None:
    bad = tmp_path / "syntax.py"
    bad.write_text("class Broken(:\n    pass\n")
    with pytest.raises(PluginError, match=rf"SyntaxError.*at {bad}:1"):
        load_algorithm_class(f"{bad}:Broken")
    (tmp_path / "helpers_fx.py").write_text("X = 1\n")
    user = tmp_path / "uses_sibling.py"
    user.write_text("import helpers_fx\n" + GOOD)
    with pytest.raises(PluginError) as err:
        load_algorithm_class(f"{user}:GoodDetector")
    assert "helpers_fx" in str(err.value)
    assert "does not put a plugin file's directory on sys.path" in str(err.value)


def test_no_such_class_lists_what_is_there(tmp_path: Path, site: Path) -> None:
    path = tmp_path / "two.py"
    path.write_text(GOOD)
    with pytest.raises(PluginError) as err:
        load_algorithm_class(f"{path}:GoodDetectr")
    msg = str(err.value)
    assert f"file {path} has no 'GoodDetectr'" in msg
    assert "defines: GoodDetector, HelperPlanner" in msg
    assert "did you mean GoodDetector?" in msg
    empty = tmp_path / "empty.py"
    empty.write_text("from redrive.algorithms import Algorithm\n")
    with pytest.raises(PluginError, match="defines: none"):
        load_algorithm_class(f"{empty}:Algo")


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        ("class NotAlgo:\n    role = Role.PERCEPTION\n", "is not an Algorithm subclass"),
        ("def NotAlgo(frame, upstream):\n    return []\n", "is a function, not a class"),
        (
            "class NotAlgo(Algorithm):\n    role = Role.CONTROL\n",
            "is abstract: it does not implement step",
        ),
        (
            "class NotAlgo(Algorithm):\n    def step(self, frame, upstream):\n        return []\n",
            "has no role (got None); set role = Role.PERCEPTION",
        ),
        (
            "class NotAlgo(Algorithm):\n    role = 'perception'\n"
            "    def step(self, frame, upstream):\n        return []\n",
            "has no role (got 'perception')",
        ),
        (
            "class NotAlgo(Algorithm):\n    role = Role.PERCEPTION\n    inputs = ('lidar_top')\n"
            "    def step(self, frame, upstream):\n        return []\n",
            "a single input needs a trailing comma",
        ),
        (
            "class NotAlgo(Algorithm):\n    role = Role.PERCEPTION\n    defaults = [1]\n"
            "    def step(self, frame, upstream):\n        return []\n",
            "defaults must be a mapping",
        ),
    ],
    ids=["plain-class", "function", "abstract", "no-role", "role-string", "inputs", "defaults"],
)
def test_unusable_classes(tmp_path: Path, site: Path, body: str, expected: str) -> None:
    path = tmp_path / "unusable.py"
    path.write_text("from redrive.algorithms import Algorithm, Role\n\n" + body)
    with pytest.raises(PluginError) as err:
        load_algorithm_class(f"{path}:NotAlgo")
    assert expected in str(err.value)
    assert f"'{path}:NotAlgo'" in str(err.value)


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("", "cannot read it"),
        ("   ", "cannot read it"),
        ("my detector", "cannot read it"),
        ("mypkg.mod:", "after the last ':' comes a class name, got ''"),
        ("mypkg.mod:1Bad", "after the last ':' comes a class name, got '1Bad'"),
        ("my-pkg.mod:Thing", "neither a module name"),
        ("a::B", "neither a module name"),
        ("bad!name", "cannot read it"),
    ],
)
def test_bad_spec_syntax(spec: str, expected: str) -> None:
    with pytest.raises(PluginError) as err:
        load_algorithm_class(spec)
    assert expected in str(err.value)
    assert "package.module:ClassName" in str(err.value)


# -- describe -------------------------------------------------------------------------------------


def _good_class() -> type[Algorithm]:
    namespace: dict[str, object] = {"__name__": "fx_inline"}
    exec(compile(GOOD, "<inline>", "exec"), namespace)
    cls = namespace["GoodDetector"]
    assert isinstance(cls, type)
    assert issubclass(cls, Algorithm)
    return cls


def test_describe_a_class_without_docstring() -> None:
    class Quiet(Algorithm):
        role = Role.CONTROL

        def step(self, frame: object, upstream: object) -> object:
            return None

    info = describe(Quiet)
    assert info.summary == ""
    assert info.name == "Quiet"
    assert info.target.endswith(
        "test_discovery:test_describe_a_class_without_docstring.<locals>.Quiet"
    )
    assert info.to_json()["defaults"] == {}
    with pytest.raises(PluginError, match="has no role"):
        describe(Algorithm)
