"""The one validator: typed reads, unknown keys, ranges, and messages that say where and what to do."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from redrive.config.validate import REQUIRED, Table, read_toml
from redrive.errors import ConfigError


def table(data: Any) -> Table:
    return Table(data, source="spec.toml", where="run")


def test_reads_typed_values_and_defaults() -> None:
    t = table({"n": 3, "x": 2, "ok": True, "s": "a", "xs": ["a", "b"], "v": [1, 2.5, 3]})
    assert t.integer("n", minimum=0) == 3
    assert isinstance(t.number("x"), float)
    assert t.flag("ok") is True
    assert t.text("s", choices=("a", "b")) == "a"
    assert t.texts("xs") == ("a", "b")
    assert t.numbers("v", length=3) == (1.0, 2.5, 3.0)
    assert t.number("absent", None) is None
    assert t.text("absent", "dflt") == "dflt"
    assert Table({"p": "one"}, source="f").texts("p", one_ok=True) == ("one",)


@pytest.mark.parametrize(
    ("data", "read", "words"),
    [
        ({"n": True}, lambda t: t.integer("n"), ["spec.toml: run.n", "a boolean (True)", "an integer"]),
        ({"n": -1}, lambda t: t.integer("n", minimum=0), ["run.n", "≥ 0"]),
        ({"x": "1"}, lambda t: t.number("x"), ["run.x", "a string ('1')", "give x a finite number"]),
        ({"x": 0}, lambda t: t.number("x", positive=True), ["> 0"]),
        ({"x": float("nan")}, lambda t: t.number("x"), ["finite"]),
        ({"p": 2}, lambda t: t.number("p", maximum=1), ["≤ 1"]),
        ({"s": "c"}, lambda t: t.text("s", choices=("a", "b")), ["one of a, b"]),
        ({"v": [1, 2]}, lambda t: t.numbers("v", length=3), ["a list of 3 numbers"]),
        ({"c": [1, 2, 256]}, lambda t: t.numbers("c", length=3, integers=(0, 255)), ["0..255"]),
        ({}, lambda t: t.text("name"), ["run.name: missing", "add name"]),
        ({"sub": 3}, lambda t: t.table("sub"), ["run.sub", "expected a table"]),
    ],
)  # fmt: skip
def test_failures_name_file_key_and_fix(data: Any, read: Any, words: list[str]) -> None:
    with pytest.raises(ConfigError) as err:
        read(table(data))
    for word in words:
        assert word in str(err.value)


def test_unknown_keys_suggest_the_closest() -> None:
    with pytest.raises(ConfigError, match=r"run.sed: unknown key; remove it \(did you mean 'seed'"):
        table({"sed": 1}).check_keys({"seed", "mode"})
    table({"seed": 1}).check_keys({"seed", "mode"})


def test_nested_tables_carry_their_path_and_style() -> None:
    def style(source: str, path: str, problem: str, fix: str) -> str:
        return f"{source} <{path}> {problem} / {fix}"

    doc = Table({"agents": [{"speed": 1}, {"speed": "x"}]}, source="s.toml", style=style)
    first, second = doc.tables("agents")
    assert first.number("speed") == 1.0
    with pytest.raises(ConfigError, match=r"^s.toml <agents\[1\].speed> a string"):
        second.number("speed")
    assert doc.tables("none", []) == []
    with pytest.raises(ConfigError, match="agents"):
        doc.table("agents")


def test_not_a_mapping_is_refused() -> None:
    with pytest.raises(ConfigError, match="expected a table"):
        Table([1], source="f.toml")
    assert REQUIRED is not None


def test_toml_files_missing_unreadable_or_broken(tmp_path: Path) -> None:
    good = tmp_path / "good.toml"
    good.write_text("a = 1\n", encoding="utf-8")
    assert read_toml(good, what="spec") == {"a": 1}
    with pytest.raises(ConfigError, match=r"nope.toml: spec not found; check the path"):
        read_toml(tmp_path / "nope.toml", what="spec")
    bad = tmp_path / "bad.toml"
    bad.write_text("a = = 1\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"bad.toml: not valid TOML \(.*\); fix the syntax"):
        read_toml(bad, what="spec")
    with pytest.raises(ConfigError, match="cannot read the spec"):
        read_toml(tmp_path, what="spec")  # a folder
