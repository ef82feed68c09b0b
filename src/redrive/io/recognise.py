"""How single-file readers recognise their files: by the bytes they start with."""

from __future__ import annotations

from pathlib import Path

__all__ = ["starts_with"]


def starts_with(path: Path, magic: bytes) -> bool:
    """Whether ``path`` is a file whose first bytes are ``magic``."""
    if not path.is_file():
        return False
    with path.open("rb") as fh:
        return fh.read(len(magic)) == magic
