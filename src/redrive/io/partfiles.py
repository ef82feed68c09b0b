"""The temporary ``.part`` files a log is written to before it is moved into place.

A writer creates ``.<name>.<pid>-<random>.part`` beside its target and renames it when it finishes;
an error removes it. A writer killed outright (SIGKILL, power loss) cannot: its part stays. The
pid in the name tells a part whose writer is gone (an *orphan*, worth recovering with ``redrive
repair PART -o FIXED.mcap``) from one another process is still writing.

>>> from redrive.io.partfiles import orphaned_parts
>>> [p.name for p in orphaned_parts(Path("recordings"))]      # doctest: +SKIP
['.husky.mcap.4242-k3j2h1ab.part']
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

__all__ = ["create_part", "orphaned_parts", "part_target"]

_PART = re.compile(r"^\.(?P<name>.+)\.(?:(?P<pid>\d+)-)?[^.]+\.part$")


def create_part(path: Path) -> tuple[int, Path]:
    """An open file descriptor and the path of a new part for ``path`` (mode 0644).

    Raises:
        OSError: the folder cannot be written.
    """
    fd, tmp = tempfile.mkstemp(
        dir=path.parent, prefix=f".{path.name}.{os.getpid()}-", suffix=".part"
    )
    os.chmod(tmp, 0o644)  # mkstemp makes it 0600; a recording is a normal file
    return fd, Path(tmp)


def part_target(part: Path) -> str | None:
    """The file name the part was to become (``husky.mcap``), or None if it is not a part."""
    found = _PART.match(part.name)
    return found["name"] if found else None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def orphaned_parts(folder: Path) -> list[Path]:
    """Parts in ``folder`` whose writer process is gone (parts of older versions without a pid
    included), oldest first."""
    if not folder.is_dir():
        return []
    out = []
    for path in folder.glob(".*.part"):
        found = _PART.match(path.name)
        if found is None or not path.is_file():
            continue
        pid = found["pid"]
        if pid is not None and _alive(int(pid)):
            continue
        out.append(path)
    return sorted(out, key=lambda p: p.stat().st_mtime)
