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

__all__ = ["MAX_TYPE_NESTING", "shipped_definitions", "typestore_for", "unreadable_types"]

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


#: the deepest nesting of message types deserialised (a standard type nests a handful; the
#: deserialisers recurse per level, so a 400-level definition ends in a RecursionError)
MAX_TYPE_NESTING = 64


def _members(typs: Mapping[str, Any], name: str) -> list[str]:
    """The message types the fields of ``name`` name (those that ``typs`` knows)."""
    out = []
    for _, (kind, detail) in typs[name][1]:
        if kind == Nodetype.NAME:
            sub = detail
        elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and detail[0][0] == Nodetype.NAME:
            sub = detail[0][1]
        else:
            continue
        if sub in typs:
            out.append(sub)
    return out


def _closure(typs: Mapping[str, Any], roots: Collection[str]) -> dict[str, Any]:
    """``roots`` and every type their fields name, transitively (those that ``typs`` knows)."""
    out: dict[str, Any] = {}
    pending = [r for r in roots if r in typs]
    while pending:
        name = pending.pop()
        if name in out:
            continue
        out[name] = typs[name]
        pending.extend(sub for sub in _members(typs, name) if sub not in out)
    return out


def unreadable_types(typs: Mapping[str, Any], roots: Collection[str]) -> dict[str, str]:
    """The types of ``roots``' closure that cannot be deserialised, with why: one that contains
    itself (ROS message types cannot be recursive, and rosbags' deserialisers would recurse for
    ever), one nesting more than :data:`MAX_TYPE_NESTING` levels, and every type containing one
    of those.  Walked without recursion (a definition may nest thousands of levels deep)."""
    closure = _closure(typs, roots)
    members = {name: _members(typs, name) for name in closure}
    bad: dict[str, str] = {}
    for name in closure:
        seen: set[str] = set()
        pending = list(members[name])
        while pending:
            sub = pending.pop()
            if sub == name:
                bad[name] = f"{name} contains itself"
                break
            if sub not in seen:
                seen.add(sub)
                pending.extend(members[sub])
    depth: dict[str, int] = {}  # what is left is acyclic: a post-order walk ends
    for name in closure:
        if name in bad or name in depth:
            continue
        stack = [(name, iter(members[name]))]
        while stack:
            top, subs = stack[-1]
            nxt = next(subs, None)
            if nxt is not None:
                if nxt not in bad and nxt not in depth:
                    stack.append((nxt, iter(members[nxt])))
                continue
            stack.pop()
            depth[top] = 1 + max((depth[s] for s in members[top] if s in depth), default=0)
    for name, levels in depth.items():
        if levels > MAX_TYPE_NESTING:
            bad[name] = (
                f"{name} nests {levels} message types deep, more than the {MAX_TYPE_NESTING} "
                "redrive deserialises"
            )
    cause = dict(bad)  # the types that fail by themselves
    changed = True
    while changed:  # a type holding an unreadable one cannot be read either
        changed = False
        for name in closure:
            if name in bad:
                continue
            for sub in members[name]:
                if sub in bad:
                    cause[name] = cause[sub]
                    bad[name] = f"{name} contains {sub}, which cannot be read: {cause[sub]}"
                    changed = True
                    break
    return bad


def typestore_for(
    ros_version: Literal[1, 2],
    log_definitions: Mapping[str, tuple[str, str]] | None = None,
    *,
    needed: Collection[str] | None = None,
    source: object = None,
) -> tuple[Typestore, set[str]]:
    """A typestore for one log.

    Starts from ROS 1 Noetic or ROS 2 Humble plus the definitions redrive ships, then lays the
    log's own definitions (``msgtype`` → (``"msg"`` or ``"idl"``, text)) on top, since a log's
    definition is what its bytes were written with.

    ``needed`` (the log's message types) registers only those and the types they contain:
    registering all ≈ 340 standard types builds as many classes and costs ≈ 0.1 s per log opened;
    a log's handful costs a few ms.  Without it the store knows every standard type (writers
    need that).

    A log type that cannot be deserialised (:func:`unreadable_types`: recursive, or nested
    too deep) is left out of the store — its messages stay raw, ``convert`` leaves its topics
    out — with one warning per type naming ``source`` (the log), not one per message.

    Returns:
        the typestore, and the message types whose embedded definition did not parse or cannot
        be deserialised (they fall back to the defaults when those know the type).
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
    if log_definitions:
        defaults = _default_fielddefs(ros_version)
        roots = [t for t in (needed if needed is not None else log_definitions) if t in typs]
        unreadable = unreadable_types(typs, roots)
        for msgtype in sorted(unreadable):
            failed.add(msgtype)
            if msgtype in defaults and not unreadable_types(defaults, [msgtype]):
                typs[msgtype] = defaults[msgtype]  # the standard definition of that name
            else:
                del typs[msgtype]
        for msgtype in sorted(set(unreadable) & set(roots)):  # the others: said with these
            logger.warning(
                "%s: the message type %s cannot be deserialised: %s; its messages are kept "
                "as they are (raw), and not decoded or converted",
                source or "a log",
                msgtype,
                unreadable[msgtype],
            )
    if needed is not None:
        typs = _closure(typs, needed)
    store = get_typestore(Stores.EMPTY)
    store.register(typs)
    return store, failed
