"""Message type definitions: rosbags' standard stores plus the few packages redrive ships.

The ROS 2 Humble and ROS 1 Noetic stores of ``rosbags`` cover ``common_interfaces``.  Types used
by driving logs that are not there (``vision_msgs``, ``derived_object_msgs``, ``velodyne_msgs``)
live as plain ``.msg`` files under ``redrive/io/ros/msgs/<package>/msg/<Type>.msg`` and are registered
on top.  Definitions embedded in a log always win over these.
"""

from __future__ import annotations

import logging
from collections.abc import Collection, Mapping
from functools import cache
from importlib import resources
from typing import Any, Literal

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.base import TypesysError
from rosbags.typesys.store import Typestore

__all__ = ["shipped_definitions", "typestore_for"]

logger = logging.getLogger(__name__)


@cache
def shipped_definitions() -> dict[str, str]:
    """``pkg/msg/Type`` → .msg text of every definition shipped in ``redrive/io/ros/msgs``."""
    out: dict[str, str] = {}
    root = resources.files("redrive.io.ros").joinpath("msgs")
    if not root.is_dir():
        return out
    for pkg in root.iterdir():
        msgdir = pkg.joinpath("msg")
        if not msgdir.is_dir():
            continue
        for item in msgdir.iterdir():
            if item.name.endswith(".msg"):
                out[f"{pkg.name}/msg/{item.name[:-4]}"] = item.read_text(encoding="utf-8")
    return out


@cache
def _default_fielddefs(ros_version: Literal[1, 2]) -> Mapping[str, Any]:
    """Noetic or Humble plus the shipped definitions, parsed once per process (never mutated)."""
    base = get_typestore(Stores.ROS1_NOETIC if ros_version == 1 else Stores.ROS2_HUMBLE)
    typs: dict[str, Any] = dict(base.fielddefs)
    for name, text in sorted(shipped_definitions().items()):
        for key, value in get_types_from_msg(text, name).items():
            typs.setdefault(key, value)
    return typs


def _closure(typs: Mapping[str, Any], roots: Collection[str]) -> dict[str, Any]:
    """``roots`` and every type their fields name, transitively (those that ``typs`` knows)."""
    out: dict[str, Any] = {}
    pending = [r for r in roots if r in typs]
    while pending:
        name = pending.pop()
        if name in out:
            continue
        out[name] = typs[name]
        for _, (kind, detail) in typs[name][1]:
            if kind == Nodetype.NAME:
                sub = detail
            elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and detail[0][0] == Nodetype.NAME:
                sub = detail[0][1]
            else:
                continue
            if sub in typs and sub not in out:
                pending.append(sub)
    return out


def typestore_for(
    ros_version: Literal[1, 2],
    log_definitions: Mapping[str, tuple[str, str]] | None = None,
    *,
    needed: Collection[str] | None = None,
) -> tuple[Typestore, set[str]]:
    """A typestore for one log.

    Starts from ROS 1 Noetic or ROS 2 Humble plus the definitions redrive ships, then lays the
    log's own definitions (``msgtype`` → (``"msg"`` or ``"idl"``, text)) on top, since a log's
    definition is what its bytes were written with.

    ``needed`` (the log's message types) registers only those and the types they contain:
    registering all ≈ 340 standard types builds as many classes and costs ≈ 0.1 s per log opened;
    a log's handful costs a few ms.  Without it the store knows every standard type (writers
    need that).

    Returns:
        the typestore, and the message types whose embedded definition did not parse (they fall
        back to the defaults when those know the type).
    """
    typs: dict[str, Any] = dict(_default_fielddefs(ros_version))
    failed: set[str] = set()
    for msgtype, (fmt, text) in sorted((log_definitions or {}).items()):
        if not text.strip():
            continue
        try:
            found = get_types_from_msg(text, msgtype) if fmt == "msg" else get_types_from_idl(text)
        except (TypesysError, ValueError, KeyError, IndexError) as err:
            logger.debug("embedded definition of %s does not parse: %s", msgtype, err)
            failed.add(msgtype)
            continue
        typs.update(found)
    if needed is not None:
        typs = _closure(typs, needed)
    store = get_typestore(Stores.EMPTY)
    store.register(typs)
    return store, failed
