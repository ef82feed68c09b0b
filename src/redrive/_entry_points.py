"""The installed entry points of a plugin group, read once per process while what is installed
stays as it was (:mod:`redrive.plugins` loads the plugins they name).

A group's entry points are read again when :func:`_installed_stamp` changes: another
``importlib.metadata.entry_points`` (a test's replacement), another ``sys.path``, or a directory
of it modified (an install or an uninstall adds or removes a ``*.dist-info`` there —
importlib.metadata's own directory listings are kept by the same modification times).  An
``entry_points.txt`` edited in place, without a reinstall, is seen by the next process or after
:func:`forget_entry_points` (``reload_readers``, ``reload_decoders``).  Within
a :func:`discovered_once` block every read of a group gives the same entry points.
"""

from __future__ import annotations

import contextlib
import contextvars
import importlib.metadata
import os
import sys
from collections.abc import Iterator

__all__ = ["declared_entry_points", "discovered_once", "dist_name", "forget_entry_points"]


#: within :func:`discovered_once`: group → its entry points as read there; None outside it
_READ_ONCE: contextvars.ContextVar[dict[str, list[importlib.metadata.EntryPoint]] | None] = (
    contextvars.ContextVar("redrive_plugins_read_once", default=None)
)


@contextlib.contextmanager
def discovered_once() -> Iterator[None]:
    """Within the block (in this thread or task) each group's entry points are read from the
    installed metadata once (a run loads its algorithms twice: what they read, then the graph),
    whatever is installed meanwhile.  Nests: the outermost block's reads are kept."""
    token = None if _READ_ONCE.get() is not None else _READ_ONCE.set({})
    try:
        yield
    finally:
        if token is not None:
            _READ_ONCE.reset(token)


#: group → (:func:`_installed_stamp` when read, its entry points): each group read once per
#: process while what is installed stays as it was
_READ: dict[str, tuple[tuple[object, ...], list[importlib.metadata.EntryPoint]]] = {}


def _installed_stamp() -> tuple[object, ...]:
    """What the installed entry points depend on: the lookup (a test's replacement), ``sys.path``
    and the modification time of each of its directories (an install or an uninstall adds or
    removes a ``*.dist-info`` there; importlib.metadata's own directory listings go by them)."""
    times: list[int | None] = []
    for entry in sys.path:
        try:
            times.append(os.stat(entry or ".").st_mtime_ns)
        except OSError:
            times.append(None)
    cwd = os.getcwd() if "" in sys.path else None
    return importlib.metadata.entry_points, tuple(sys.path), tuple(times), cwd


def declared_entry_points(group: str) -> list[importlib.metadata.EntryPoint]:
    """The entry points of ``group``, read from the installed metadata once per process
    (again when :func:`_installed_stamp` changes) and the same throughout a
    :func:`discovered_once` block."""
    read = _READ_ONCE.get()
    found = None if read is None else read.get(group)
    if found is None:
        stamp = _installed_stamp()
        known = _READ.get(group)
        if known is not None and known[0] == stamp:
            found = known[1]
        else:
            found = list(importlib.metadata.entry_points(group=group))
            _READ[group] = (stamp, found)
        if read is not None:
            read[group] = found
    return list(found)


def forget_entry_points() -> None:
    """Read every group's entry points from the installed metadata again at its next lookup
    (the ``reload_*`` functions call it: an ``entry_points.txt`` edited in place is then seen)."""
    _READ.clear()
    _NAMES.clear()


#: id(distribution) → (the distribution, its "Name Version"): each METADATA parsed once
_NAMES: dict[int, tuple[object, str | None]] = {}


def dist_name(ep: importlib.metadata.EntryPoint) -> str | None:
    """ "Name Version" of the distribution that declares ``ep`` (None: unknown, or its metadata
    is broken)."""
    dist = getattr(ep, "dist", None)
    if dist is None:
        return None
    known = _NAMES.get(id(dist))
    if known is not None and known[0] is dist:
        return known[1]
    try:
        meta = dist.metadata  # read once (``dist.name`` and ``dist.version`` read it each)
        name: str | None = f"{meta['Name']} {meta['Version']}"
    except Exception:  # broken metadata: the name is only decoration here
        name = None
    _NAMES[id(dist)] = (dist, name)
    return name
