"""``redrive new-algorithm NAME --role ROLE`` — a working algorithm file and its tests to start from.

The templates are the strings of :mod:`redrive.cli.templates` (plain Python with ``$module`` /
``$cls`` placeholders); what they generate runs as written, passes its own tests and the
project's ruff configuration.
"""

from __future__ import annotations

import argparse
import importlib.util
import keyword
import os
import re
import sys
from pathlib import Path
from string import Template
from typing import Any

from redrive.algorithms import Role
from redrive.cli.templates import ALGORITHM_TEMPLATES, IMPORTED_NAMES, TEST_TEMPLATES
from redrive.errors import ConfigError

__all__ = ["class_name_for", "register", "write_algorithm"]

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

_EPILOG = """\
examples:
  redrive new-algorithm my_detector --role perception
  redrive new-algorithm lane_keeper --role planning -o algorithms/
  redrive new-algorithm speed_pid --role control --force     overwrite the files

Writes DIR/NAME.py (a documented Algorithm subclass named NAME in CamelCase, e.g. my_detector →
MyDetector, that runs as written) and DIR/test_NAME.py (pytest tests on a hand-built frame).
"""


def class_name_for(name: str) -> str:
    """The CamelCase class name of a module name: ``my_detector`` → ``MyDetector``."""
    return "".join(part[:1].upper() + part[1:] for part in name.split("_") if part)


def _check_name(name: str, *, target: Path) -> str:
    """``name``'s class name, or :class:`ConfigError` saying why ``name`` cannot be used."""
    if not _NAME.match(name):
        suggestion = re.sub(r"\W+", "_", name.strip()).strip("_").lower()
        if suggestion[:1].isdigit():
            suggestion = "algo_" + suggestion
        hint = f" (e.g. {suggestion})" if suggestion else ""
        msg = (
            f"new-algorithm: {name!r} is not a usable name: it becomes a Python module, so use "
            f"letters, digits and underscores, starting with a letter{hint}"
        )
        raise ConfigError(msg)
    if keyword.iskeyword(name) or keyword.issoftkeyword(name):
        msg = f"new-algorithm: {name!r} is a Python keyword; pick another name"
        raise ConfigError(msg)
    if name.startswith("test") or name.endswith("_test"):
        msg = (
            f"new-algorithm: {name!r} looks like a test module to pytest; name the algorithm, "
            "its tests are written to test_NAME.py"
        )
        raise ConfigError(msg)
    cls = class_name_for(name)
    if cls in IMPORTED_NAMES:
        msg = (
            f"new-algorithm: the class {cls} would hide the name {cls} the template imports; "
            "pick another name"
        )
        raise ConfigError(msg)
    if name in sys.stdlib_module_names:
        msg = f"new-algorithm: {name!r} would shadow the standard-library module {name}"
        raise ConfigError(msg)
    found = importlib.util.find_spec(name)
    if found is not None and (
        found.origin is None or Path(found.origin).resolve() != target.resolve()
    ):
        msg = (
            f"new-algorithm: {name!r} would shadow the installed module {name} "
            f"({found.origin or 'a namespace package'}); pick another name"
        )
        raise ConfigError(msg)
    return cls


def write_algorithm(
    name: str, role: Role, *, directory: Path, force: bool = False
) -> tuple[Path, Path]:
    """Write ``directory/name.py`` and ``directory/test_name.py`` for an algorithm of ``role``.

    Returns:
        The paths of the algorithm file and of its test file.

    Raises:
        ConfigError: ``name`` is not usable, or a file exists and ``force`` is not set.
    """
    algo_path = directory / f"{name}.py"
    test_path = directory / f"test_{name}.py"
    cls = _check_name(name, target=algo_path)
    if not force:
        existing = [p for p in (algo_path, test_path) if p.exists()]
        if existing:
            msg = (
                f"new-algorithm: {', '.join(str(p) for p in existing)} already exist"
                f"{'s' if len(existing) == 1 else ''}; pass --force to overwrite, or pick "
                "another name or -o DIR"
            )
            raise ConfigError(msg)
    if directory.exists() and not directory.is_dir():
        msg = f"new-algorithm: {directory} is not a directory; give another -o DIR"
        raise ConfigError(msg)
    directory.mkdir(parents=True, exist_ok=True)
    values = {"module": name, "cls": cls}
    algo_path.write_text(Template(ALGORITHM_TEMPLATES[role]).substitute(values), encoding="utf-8")
    test_path.write_text(Template(TEST_TEMPLATES[role]).substitute(values), encoding="utf-8")
    return algo_path, test_path


def _shown(path: Path) -> str:
    rel = os.path.relpath(path)
    return rel if not rel.startswith("..") else str(path)


def _run(args: argparse.Namespace) -> int:
    role = Role(args.role)
    algo_path, test_path = write_algorithm(args.name, role, directory=args.output, force=args.force)
    cls = class_name_for(args.name)
    spec = f"{_shown(algo_path)}:{cls}"
    flag = {"perception": "--perception", "planning": "--planning", "control": "--control"}
    steps = [
        (f"python -m pytest {_shown(test_path)}", "run its tests"),
        (f"redrive algorithms {spec}", "check that redrive loads it"),
        (f"redrive run LOG {flag[role.value]} {spec}", "run it on a log"),
    ]
    width = max(len(cmd) for cmd, _ in steps) + 3
    print(f"wrote {_shown(algo_path)} ({cls}, a {role.value} algorithm)")
    print(f"wrote {_shown(test_path)}")
    print()
    print("next steps:")
    for cmd, what in steps:
        print(f"  {cmd:<{width}}{what}")
    print(f"then edit {cls}.step in {_shown(algo_path)}; its docstring says what comes in and out.")
    return 0


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "new-algorithm",
        help="write a working algorithm template and its tests",
        description=(
            "Write NAME.py, a documented Algorithm subclass for the given role that runs as "
            "written (perception: LiDAR points above the ground grouped into boxes; planning: a "
            "straight path ahead at the current speed; control: a P controller on the path's "
            "speed), and test_NAME.py, pytest tests that feed it a hand-built frame."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("name", metavar="NAME", help="module name, e.g. my_detector")
    parser.add_argument(
        "--role", required=True, choices=[r.value for r in Role], help="the algorithm's stage"
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        default=Path(),
        metavar="DIR",
        help="directory to write into (default: the current one; created if missing)",
    )
    parser.add_argument("--force", action="store_true", help="overwrite existing files")
    parser.set_defaults(func=_run)
