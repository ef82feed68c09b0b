"""``redrive algorithms [SPEC]``: the listing (table and JSON, broken plugins) and one algorithm."""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

from redrive.algorithms import Role
from redrive.cli import algorithms
from redrive.cli.algorithms import toml_value
from redrive.errors import PluginError
from tests.algorithms.test_discovery import GOOD, unique, write_dist


def run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="redrive")
    algorithms.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    status: int = args.func(args)
    return status


@pytest.fixture
def plugins(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[str, str]]:
    """A tmp distribution with one good algorithm (``fxg-…``) and one broken (``fxb-…``)."""
    site = tmp_path / "site"
    pkg, good, bad = unique("fxcli"), unique("fxg"), unique("fxb")
    write_dist(
        site,
        unique("fx-cli"),
        entry_points={good: f"{pkg}.m:GoodDetector", bad: f"{pkg}.gone:Detector"},
        modules={f"{pkg}/m.py": GOOD},
    )
    monkeypatch.syspath_prepend(str(site))
    before = set(sys.modules)
    yield good, bad
    for name in set(sys.modules) - before:
        if name.startswith(pkg):
            del sys.modules[name]


def test_list_json(plugins: tuple[str, str], capsys: pytest.CaptureFixture[str]) -> None:
    good, bad = plugins
    status = run(["algorithms", "--json"])
    payload = json.loads(capsys.readouterr().out)
    assert status == 1  # a broken plugin is installed
    assert payload["group"] == "redrive.algorithms"
    by_name = {a["name"]: a for a in payload["algorithms"]}
    entry = by_name[good]
    assert entry["role"] == "perception"
    assert entry["inputs"] == ["lidar", "vehicle_state"]
    assert entry["version"] == "2.5"
    assert entry["summary"] == "Finds nothing, for tests."
    assert entry["target"].endswith(".m:GoodDetector")
    assert entry["defaults"]["mode"] == "planning"
    broken = {b["name"]: b for b in payload["broken"]}
    assert bad in broken
    assert "not found" in broken[bad]["error"]
    assert bad not in by_name


def test_list_table(plugins: tuple[str, str], capsys: pytest.CaptureFixture[str]) -> None:
    good, bad = plugins
    assert run(["algorithms"]) == 1
    out = capsys.readouterr().out
    assert "installed algorithms" in out
    assert good in out
    assert "Finds nothing, for tests." in out
    assert "broken plugins" in out
    assert bad in out
    assert "redrive run LOG --perception NAME" in out


def test_the_installed_reference_algorithms_are_listed(capsys: pytest.CaptureFixture[str]) -> None:
    status = run(["algorithms", "--json"])
    payload = json.loads(capsys.readouterr().out)
    names = {a["name"]: a for a in payload["algorithms"]}
    broken = {b["name"]: b["error"] for b in payload["broken"]}
    assert status == (1 if broken else 0)
    for name in ("cluster-detector", "idm-planner", "pure-pursuit-pid", "noisy-oracle"):
        assert name in names, broken.get(name)
    assert names["idm-planner"]["role"] == "planning"
    assert names["pure-pursuit-pid"]["role"] == "control"


def test_show_one_by_name_module_and_file(
    plugins: tuple[str, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good, _ = plugins
    assert run(["algorithms", good]) == 0
    out = capsys.readouterr().out
    assert f"name:     {good}" in out
    assert "role:     perception (returns a list of DetectedObject)" in out
    assert "inputs:   lidar, vehicle_state" in out
    assert "A second paragraph that the summary leaves out." in out
    assert "threshold_m = 0.5" in out
    assert 'mode = "planning"' in out
    assert "sizes = [1, 2]" in out

    path = tmp_path / "mine.py"
    path.write_text(GOOD)
    assert run(["algorithms", f"{path}:HelperPlanner", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["name"] == "HelperPlanner"
    assert payload["role"] == Role.PLANNING.value
    assert payload["target"] == f"{path}:HelperPlanner"
    assert payload["doc"] == "Plans nothing."
    assert payload["defaults"] == {}

    with pytest.raises(PluginError, match="is not an Algorithm subclass"):
        run(["algorithms", "json:JSONDecoder"])


def test_show_a_missing_file_is_a_plugin_error(tmp_path: Path) -> None:
    with pytest.raises(PluginError, match="not found"):
        run(["algorithms", str(tmp_path / "nope.py:Thing")])


def test_defaults_render_as_toml_that_reads_back() -> None:
    values = {
        "f": 0.5,
        "i": 3,
        "b": True,
        "s": 'say "hi"\n',
        "lst": [1, 2.5, "x"],
        "tup": (1, 2),
        "nested": {"a-b": 1, "c": [True]},
        "role": Role.CONTROL,
        "inf": float("inf"),
    }
    text = "\n".join(f"{k} = {toml_value(v)}" for k, v in values.items())
    back = tomllib.loads(text)
    assert back["f"] == 0.5
    assert back["i"] == 3
    assert back["b"] is True
    assert back["s"] == 'say "hi"\n'
    assert back["lst"] == [1, 2.5, "x"]
    assert back["tup"] == [1, 2]
    assert back["nested"] == {"a-b": 1, "c": [True]}
    assert back["role"] == "control"
    assert back["inf"] == float("inf")


def test_help_names_the_entry_point_group(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        run(["algorithms", "--help"])
    out = capsys.readouterr().out
    assert '[project.entry-points."redrive.algorithms"]' in out
    assert "path/to/file.py" in out
