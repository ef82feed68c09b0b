"""The temporary ``.part`` files a log is written to before it is moved into place.

A writer creates ``.<name>.<pid>-<random>.part`` beside its target and renames it when it finishes;
an error removes it — except a full disk, after which what reached the part is kept
(:func:`keep_part`). A writer killed outright (SIGKILL, power loss) cannot: its part stays. The
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

__all__ = ["create_part", "keep_part", "orphaned_parts", "part_target"]

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


def keep_part(part: Path, target: Path) -> Path:
    """Put an unfinished part that holds data someone needs (a recording cut short by a full
    disk) in view, never over an existing file: at ``target`` when nothing is there, else at
    ``NAME.incomplete.mcap`` (``NAME.incomplete-2.mcap`` …).  Returns where it is (the part
    itself when no name could be made, e.g. a folder too full for one more entry)."""
    names = [target, target.with_name(f"{target.stem}.incomplete{target.suffix}")]
    names += [
        target.with_name(f"{target.stem}.incomplete-{i}{target.suffix}") for i in range(2, 100)
    ]
    for name in names:
        try:
            os.link(part, name)  # never replaces a file, unlike a rename
        except FileExistsError:
            continue
        except OSError:
            return part
        part.unlink()
        return name
    return part


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
