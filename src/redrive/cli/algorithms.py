"""``redrive algorithms [SPEC]`` — the installed algorithms, or one algorithm and its config."""

from __future__ import annotations

import argparse
import enum
import inspect
import json
import math
import re
import sys
from collections.abc import Mapping
from typing import Any

from redrive.algorithms.discovery import (
    ENTRY_POINT_GROUP,
    AlgorithmInfo,
    BrokenPlugin,
    describe,
    installed_algorithms,
    load_algorithm_class,
)

__all__ = ["register", "toml_value"]

_EP_NAME = re.compile(r"^\w[\w.+-]*$")

_EPILOG = f"""\
examples:
  redrive algorithms                              every installed algorithm (and broken plugins)
  redrive algorithms --json
  redrive algorithms cluster-detector             one algorithm: inputs, version, default config
  redrive algorithms my_detector.py:MyDetector    a class in a file (relative to the cwd)
  redrive algorithms mypkg.detectors:FastDetector a class in an importable module

Installed algorithms are the entry points of the "{ENTRY_POINT_GROUP}" group, declared in a
package's pyproject.toml:

  [project.entry-points."{ENTRY_POINT_GROUP}"]
  fast-detector = "mypkg.detectors:FastDetector"

The exit status is 1 when an installed plugin cannot be loaded (it is listed as broken).
"""


def toml_value(value: Any) -> str:
    """``value`` written as a TOML value (enums as their value; None has no TOML form → ``""``)."""
    if isinstance(value, enum.Enum):
        return toml_value(value.value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, Mapping):
        inner = ", ".join(f"{_toml_key(str(k))} = {toml_value(v)}" for k, v in value.items())
        return "{ " + inner + " }" if inner else "{}"
    if hasattr(value, "tolist"):
        return toml_value(value.tolist())
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if value is None:
        return ""
    return json.dumps(repr(value))


def _toml_key(key: str) -> str:
    bare = key.replace("_", "").replace("-", "").isalnum() and key.isascii()
    return key if bare else json.dumps(key)


def _defaults_lines(defaults: Mapping[str, Any]) -> list[str]:
    lines = []
    for key, value in defaults.items():
        rendered = toml_value(value)
        if value is None:
            lines.append(f"# {_toml_key(str(key))} =   (default None: unset; give a value to set)")
        else:
            lines.append(f"{_toml_key(str(key))} = {rendered}")
    return lines


def _console() -> Any:
    from rich.console import Console

    return Console(width=None if sys.stdout.isatty() else 160, highlight=False)


def _list(as_json: bool) -> int:
    registry = installed_algorithms()
    infos = [registry.info(name) for name in registry]
    broken = [registry.broken[name] for name in sorted(registry.broken)]
    if as_json:
        payload = {
            "group": ENTRY_POINT_GROUP,
            "algorithms": [i.to_json() for i in infos],
            "broken": [b.to_json() for b in broken],
        }
        json.dump(payload, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        _print_list(infos, broken)
    return 1 if broken else 0


def _print_list(infos: list[AlgorithmInfo], broken: list[BrokenPlugin]) -> None:
    from rich.markup import escape
    from rich.table import Table

    console = _console()
    if infos:
        table = Table(title=f"installed algorithms ({ENTRY_POINT_GROUP})", title_justify="left")
        for col in ("name", "role", "inputs", "version", "target", "summary"):
            table.add_column(col, overflow="fold")
        for info in infos:
            table.add_row(
                escape(info.name),
                info.role.value,
                escape(", ".join(info.inputs) or "-"),
                escape(info.version),
                escape(info.target),
                escape(info.summary),
            )
        console.print(table)
    else:
        console.print(f"no algorithms are installed in the entry-point group {ENTRY_POINT_GROUP}")
    if broken:
        table = Table(title="[bold red]broken plugins[/] (cannot be loaded)", title_justify="left")
        for col in ("name", "target", "error"):
            table.add_column(col, overflow="fold")
        for b in broken:
            table.add_row(escape(b.name), escape(b.target), escape(b.error))
        console.print(table)
    console.print(
        "run one with: redrive run LOG --perception NAME (or path/to/file.py:ClassName); "
        "details: redrive algorithms NAME"
    )


def _show(spec: str, as_json: bool) -> int:
    cls = load_algorithm_class(spec)
    by_name = _EP_NAME.match(spec.strip()) is not None and not spec.strip().endswith(".py")
    registry_name = spec.strip() if by_name else None
    info = describe(cls, name=registry_name)
    doc = inspect.cleandoc(cls.__doc__ or "")
    if as_json:
        payload = info.to_json()
        payload["doc"] = doc
        json.dump(payload, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    from rich.markup import escape

    console = _console()
    for label, value in (
        ("name", info.name),
        ("target", info.target),
        ("role", f"{info.role.value} (returns {info.role.output_name})"),
        ("inputs", ", ".join(info.inputs) or "-"),
        ("version", info.version),
    ):
        console.print(f"[bold]{label}[/]:{' ' * (9 - len(label))}{escape(value)}")
    if doc:
        console.print()
        console.print(escape(doc))
    console.print()
    if info.defaults:
        console.print("[bold]config[/] (keys and defaults, TOML; a run's config overrides them):")
        for line in _defaults_lines(info.defaults):
            console.print("  " + escape(line))
    else:
        console.print("[bold]config[/]: none (no defaults; any config key is accepted)")
    return 0


def _run(args: argparse.Namespace) -> int:
    if args.spec is None:
        return _list(args.json)
    return _show(args.spec, args.json)


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "algorithms",
        help="list installed algorithms, or show one with its default config",
        description=(
            "Without SPEC: every algorithm installed through the entry-point group "
            f"{ENTRY_POINT_GROUP} — name, role, inputs, version, where it lives, summary — and "
            "the plugins that fail to load, with their error. With SPEC (an installed name, "
            "package.module:Class or path/to/file.py:Class): that algorithm, its docstring and "
            "its default configuration."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "spec",
        nargs="?",
        metavar="SPEC",
        help="an installed name, package.module:Class or path/to/file.py[:Class]",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=_run)
