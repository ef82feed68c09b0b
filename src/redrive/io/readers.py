"""The reader registry: every log format redrive opens, how it is recognised, what it can provide.

A *reader format* is a reader class that declares, as class attributes and a class method:

- ``format``: its short name (``ros1``, ``ros2``, ``mcap``, ``kitti``, ``nuscenes``,
  ``nuscenes-mmdet3d``, ``kitti-mmdet3d``, ``av2-sensor``, ``womd``, ``commonroad``), recorded in the run
  manifest and shown by ``redrive info``;
- ``description``: what it reads, for listings and error messages;
- ``recognises(path)``: whether ``path`` is a log of this format, from its content (magic bytes,
  layout), never from its file name;
- a constructor ``(path, *, strict)`` that opens it (a :class:`~redrive.io.base.LogReader`);
- optionally a class method ``recognised(path)``: what recognising ``path`` found out (a decoded
  first record …), or None when it is no log of the format.  :func:`open_log` hands that value to
  the constructor as the keyword ``recognised=``, so the work is not done twice; a reader with it
  still has ``recognises`` (``recognised(path) is not None``);
- optionally ``reads_a_set = True``: it reads several logs as one (split MCAP files), so a caller
  looking for logs in a folder takes the files one by one (:func:`recognised_format`).

An opened reader says what it can provide through ``capabilities`` (:class:`ReaderCapabilities`):
callers (the frame assembler, the GUI, the engine) ask these, never the format name.  The
formats redrive ships are tried first, in a fixed order; installed plugins of the
``redrive.readers`` entry-point group (loaded by :mod:`redrive.plugins`) after them, so a new
format (closed-loop output, another dataset …) plugs in without touching :func:`open_log`.

A reader not installed as a package is named in the environment variable ``REDRIVE_READERS``:
comma-separated specs of the plugin loader (``path/to/toy.py:ToyReader``,
``mypkg.readers:ToyReader``), tried after the entry points.  Every command that opens logs
(``redrive info``, ``run``, ``batch`` and its worker processes, which inherit the variable)
then reads that format::

    REDRIVE_READERS=./toy_reader.py:ToyReader redrive batch drives/
"""

from __future__ import annotations

import functools
import logging
import os
import stat
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Literal, Protocol, runtime_checkable

from redrive.errors import LogError, PluginError
from redrive.io.base import LogReader, ReaderCapabilities
from redrive.plugins import (
    READERS,
    class_target,
    forget_entry_points,
    installed_plugins,
    load_plugin,
)

__all__ = [
    "READERS_ENV",
    "ReaderCapabilities",
    "ReaderFormat",
    "detect_format",
    "open_log",
    "reader_format",
    "reader_formats",
    "recognised_format",
    "reload_readers",
]

logger = logging.getLogger(__name__)

#: the environment variable naming reader plugins by spec (see the module docstring)
READERS_ENV = "REDRIVE_READERS"


@runtime_checkable
class ReaderFormat(Protocol):
    """A reader class as the registry sees it (see the module docstring)."""

    format: str
    description: str

    @classmethod
    def recognises(cls, path: Path) -> bool: ...

    def __init__(self, path: Path, *, strict: bool = True) -> None: ...


def _check_reader(obj: object) -> str | None:
    """What keeps ``obj`` (a class) from being a reader plugin, or None."""
    for attr in ("recognises", "messages", "deserialize", "close", "__enter__"):
        if not callable(getattr(obj, attr, None)):
            return (
                f"is not a reader: it has no {attr}(); a reader follows redrive.io.LogReader "
                "and redrive.io.readers.ReaderFormat"
            )
    for attr in ("format", "description"):
        value = getattr(obj, attr, None)
        if not isinstance(value, str) or not value:
            return f": {attr} must be a non-empty str (class attribute), got {value!r}"
    return None


def _builtin() -> list[type[ReaderFormat]]:
    # imported here: each pulls in its own dependencies (rosbags, mcap, PIL)
    from redrive.io.datasets.av2 import Av2SensorLogReader
    from redrive.io.datasets.commonroad import CommonRoadReader
    from redrive.io.datasets.kitti import KittiReader
    from redrive.io.datasets.kitti_info import KittiInfoReader
    from redrive.io.datasets.mmdet3d_info import Mmdet3dInfoReader
    from redrive.io.datasets.nuscenes import NuScenesReader
    from redrive.io.datasets.womd import WomdReader
    from redrive.io.mcap.fileset import McapSetReader
    from redrive.io.mcap.reader import McapFileReader
    from redrive.io.rosbag1.reader import Ros1BagReader
    from redrive.io.rosbag2.reader import Ros2BagReader

    # a ROS 2 bag before MCAP: a bag directory's .mcap storage is read through its metadata.yaml;
    # a folder of .mcap files without one is a set of split files
    return [
        Ros2BagReader,
        KittiReader,
        NuScenesReader,
        Mmdet3dInfoReader,
        KittiInfoReader,
        Ros1BagReader,
        McapFileReader,
        McapSetReader,
        # recorded traffic: an AV2 log folder, a WOMD TFRecord, a CommonRoad .xml
        Av2SensorLogReader,
        WomdReader,
        CommonRoadReader,
    ]


@functools.cache
def reader_formats() -> Sequence[type[ReaderFormat]]:
    """The reader formats in the order they are tried: redrive's, then installed plugins, then
    those :data:`READERS_ENV` names.

    Raises:
        PluginError: a spec in :data:`READERS_ENV` does not load (the message says which).
    """
    out = _builtin()
    taken = {cls.format: cls for cls in out}
    registry = installed_plugins(READERS, _check_reader)
    found = [(name, registry.target(name), cls) for name, cls in registry.items()]
    found += [(spec, spec, cls) for spec, cls in _named_in_env()]
    for name, target, cls in found:
        fmt = str(cls.format)
        if fmt in taken:
            logger.warning(
                "reader plugin %s (%s) left out: format %r is already read by %s",
                name,
                target,
                fmt,
                taken[fmt].__qualname__,
            )
            continue
        taken[fmt] = cls
        out.append(cls)
    return tuple(out)


def _named_in_env() -> list[tuple[str, type[ReaderFormat]]]:
    specs = [s.strip() for s in os.environ.get(READERS_ENV, "").split(",") if s.strip()]
    out = []
    for spec in specs:
        try:
            cls = load_plugin(READERS, _check_reader, spec)
        except PluginError as err:
            msg = f"{READERS_ENV}: {err}"
            raise PluginError(msg) from err
        logger.debug("reader %s from %s=%s", class_target(cls), READERS_ENV, spec)
        out.append((spec, cls))
    return out


def reload_readers() -> None:
    """Read the ``redrive.readers`` entry points (and :data:`READERS_ENV`) again at the next
    lookup."""
    reader_formats.cache_clear()
    forget_entry_points()


def reader_format(name: str) -> type[ReaderFormat]:
    """The reader class of format ``name``.

    Raises:
        LogError: no reader reads that format (the message lists those that do).
    """
    for cls in reader_formats():
        if cls.format == name:
            return cls
    known = ", ".join(cls.format for cls in reader_formats())
    msg = f"no reader for format {name!r}; redrive reads {known}"
    raise LogError(msg)


def _recognising(path: Path) -> tuple[type[ReaderFormat], object | None]:
    found = _first_recognising(path, sets=True)
    if found is None:
        raise LogError(_not_a_log(path))
    return found


def _first_recognising(
    path: Path, *, sets: bool
) -> tuple[type[ReaderFormat], object | None] | None:
    """The first reader recognising ``path`` and what its ``recognised`` found (None for a
    reader without one)."""
    for cls in reader_formats():
        if not sets and getattr(cls, "reads_a_set", False):
            continue
        try:
            probe = getattr(cls, "recognised", None)
            if callable(probe):
                kept = probe(path)
                if kept is not None:
                    return cls, kept
            elif cls.recognises(path):
                return cls, None
        except OSError as err:
            msg = f"{path}: cannot read ({err.strerror or err})"
            raise LogError(msg) from err
    return None


def recognised_format(path: Path, *, sets: bool = True) -> str | None:
    """The format name of the first reader (redrive's, then plugins') that recognises ``path``,
    or None when none does: *the* test of "is this a log", for every caller that looks for logs
    (``redrive batch DIR``, globs) rather than guessing from names.

    Args:
        sets: when False, readers that read several logs as one (a class attribute
            ``reads_a_set = True``: a folder of split MCAP files) are left out, for callers that
            take each of those files as a log of its own.

    Raises:
        LogError: ``path`` cannot be read.
    """
    try:
        if _kind_of(Path(path).stat().st_mode) is not None:
            return None  # a pipe or a device is no log (and reading it could block)
    except OSError:
        pass
    found = _first_recognising(Path(path), sets=sets)
    return None if found is None else found[0].format


def _not_a_log(path: Path) -> str:
    described = "; ".join(f"{cls.format}: {cls.description}" for cls in reader_formats())
    if path.is_dir():
        storage = sorted(p.name for p in path.glob("*") if p.suffix in {".db3", ".mcap"})
        hint = (
            f" It holds {', '.join(storage[:3])} but no metadata.yaml: open the .mcap file "
            "directly, or restore metadata.yaml (`ros2 bag reindex`)."
            if storage
            else ""
        )
        return f"{path}: this directory is not a log redrive reads ({described}).{hint}"
    with path.open("rb") as fh:
        head = fh.read(8)
    return f"{path}: not a log redrive reads (starts with {head!r}); redrive reads {described}"


def _kind_of(mode: int) -> str | None:
    """What a path that is neither a regular file nor a directory is, in words; None for those."""
    for test, name in (
        (stat.S_ISFIFO, "a named pipe (FIFO)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return None if stat.S_ISREG(mode) or stat.S_ISDIR(mode) else "not a regular file"


def refuse_special(path: Path) -> None:
    """Refuse at once a path that is neither a regular file nor a directory (a named pipe, a
    device, a socket): reading one would block or never end.

    Raises:
        LogError: it is one, with what it is.
    """
    try:
        mode = path.stat().st_mode
    except OSError:
        return  # missing or unreadable: the caller says so
    kind = _kind_of(mode)
    if kind is not None:
        msg = (
            f"{path}: {kind}, not a log: redrive reads logs from regular files and log "
            "directories; copy the data to a file first"
        )
        raise LogError(msg)


def detect_format(path: Path) -> str:
    """The format name of the log at ``path`` (``ros1``, ``ros2``, ``mcap``, ``kitti``,
    ``nuscenes``, ``nuscenes-mmdet3d`` or a plugin's), from its content, not its name.

    Raises:
        LogError: the path is missing, empty or not a log redrive reads.
    """
    return _detect(Path(path))[0].format


def _detect(path: Path) -> tuple[type[ReaderFormat], object | None]:
    """:func:`detect_format`'s reader class, and what its ``recognised`` found."""
    path = Path(path)
    if not path.exists():
        from redrive.io.mcap.fileset import expand_log_set, is_glob

        if is_glob(path) and expand_log_set(path):
            return _recognising(path)
        msg = f"{path}: no such file or directory"
        if is_glob(path):
            msg += " (a glob names MCAP files of one recording; this one names none)"
        raise LogError(msg)
    refuse_special(path)
    if path.is_file():
        try:
            size = path.stat().st_size
            with path.open("rb"):
                pass
        except OSError as err:
            msg = f"{path}: cannot read ({err.strerror})"
            raise LogError(msg) from err
        if size == 0:
            msg = f"{path}: the file is empty (0 bytes); it holds no log"
            raise LogError(msg)
    return _recognising(path)


def open_log(
    path: str | Path, *, strict: bool = True, packets: Literal["clouds", "raw"] = "clouds"
) -> LogReader:
    """Open any log redrive reads, recognised by its content.

    Args:
        path: a ROS 1 ``.bag``; a ROS 2 bag directory (sqlite3 or mcap storage), its
            ``metadata.yaml`` or a ``.db3`` in it; a standalone ``.mcap`` (ROS 2 CDR or ROS 1
            encoding); split MCAP files of one recording, as a folder or a glob
            (``drive_*.mcap``); a KITTI 3D-object folder
            (``training/{velodyne,image_2,calib,label_2}``); a nuScenes data root (``v1.0-*/``
            tables + ``samples/``) or an mmdetection3d nuScenes info file (``.pkl`` / JSON, or its
            folder);
            or a log of an installed reader plugin.
        strict: when True, damage met while reading raises
            :class:`~redrive.errors.LogTruncatedError` after every message before it was
            yielded; when False the damage is logged and reading goes on where it can.
        packets: ``clouds`` (the default): beside each topic of Ouster lidar packets whose sensor
            metadata is in the log, a LiDAR topic ``…/points`` of one cloud per frame
            (:mod:`redrive.io.ros.decoders.ouster_log`); ``raw``: the file's own topics only
            (converting, repairing, counting what was recorded).

    Raises:
        LogError: the path is missing, empty, damaged beyond use or not a log.
    """
    path = Path(path)
    cls, kept = _detect(path)
    opener: Callable[..., LogReader] = cls  # type: ignore[assignment]
    # what recognising found goes to the reader that asked for it (see the module docstring)
    log = (
        opener(path, strict=strict)
        if kept is None
        else opener(path, strict=strict, recognised=kept)
    )
    if packets == "raw":
        return log
    from redrive.io.ros.decoders.ouster_log import with_packet_clouds  # decoders load on use

    try:
        return with_packet_clouds(log)
    except BaseException:
        log.close()
        raise
