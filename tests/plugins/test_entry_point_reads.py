"""A group's entry points are read once per process, and again when what is installed changes
(a distribution added) or when a ``reload_*`` function asks (an entry_points.txt edited in
place, which changes no directory)."""

from __future__ import annotations

import os
from pathlib import Path

from redrive._entry_points import declared_entry_points
from redrive.io.readers import reload_readers
from tests.algorithms.test_discovery import site, unique, write_dist  # noqa: F401 (fixture)


def _names(group: str) -> set[str]:
    return {ep.name for ep in declared_entry_points(group)}


def test_entry_points_follow_installs_and_reloads(site: Path) -> None:  # noqa: F811
    group = unique("redrive.test_group")
    assert _names(group) == set()
    dist = unique("ep-dist")
    write_dist(site, dist, entry_points={"one": "pkg.mod:One"}, group=group)
    os.utime(site, ns=(os.stat(site).st_atime_ns, os.stat(site).st_mtime_ns + 1_000_000))
    assert _names(group) == {"one"}  # an install: the site directory changed
    info = site / f"{dist.replace('-', '_')}-1.0.dist-info" / "entry_points.txt"
    mtime = os.stat(site).st_mtime_ns
    info.write_text(f"[{group}]\none = pkg.mod:One\ntwo = pkg.mod:Two\n")
    os.utime(site, ns=(mtime, mtime))  # edited in place: no directory changed
    assert _names(group) == {"one"}  # the process's reading stands …
    reload_readers()
    assert _names(group) == {"one", "two"}  # … until a reload asks again
