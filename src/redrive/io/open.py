"""``open_log``: recognise a log by its content and open the right reader."""

from __future__ import annotations

from pathlib import Path

from redrive.errors import LogError
from redrive.io.base import LogReader

__all__ = ["detect_format", "open_log"]

_ROS1_MAGIC = b"#ROSBAG V"
_MCAP_MAGIC = b"\x89MCAP"
_SQLITE_MAGIC = b"SQLite format 3\x00"


def _is_kitti_dir(path: Path) -> bool:
    roots = [path, path / "training", path / "testing"]
    return any((r / "velodyne").is_dir() and (r / "calib").is_dir() for r in roots)


def detect_format(path: Path) -> str:
    """``ros1``, ``ros2``, ``mcap`` or ``kitti``, from the content, not the file name.

    Raises:
        LogError: the path is missing, empty or not a log redrive reads.
    """
    if not path.exists():
        msg = f"{path}: no such file or directory"
        raise LogError(msg)
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return "ros2"
        if _is_kitti_dir(path):
            return "kitti"
        storage = sorted(p.name for p in path.glob("*") if p.suffix in {".db3", ".mcap"})
        hint = (
            f" It holds {', '.join(storage[:3])} but no metadata.yaml: open the .mcap file "
            "directly, or restore metadata.yaml (`ros2 bag reindex`)."
            if storage
            else ""
        )
        msg = (
            f"{path}: this directory is not a log: it has no metadata.yaml (ROS 2 bag) and no "
            f"KITTI layout (velodyne/ and calib/, optionally under training/).{hint}"
        )
        raise LogError(msg)
    if path.name == "metadata.yaml":
        return "ros2"
    try:
        with path.open("rb") as fh:
            head = fh.read(16)
    except OSError as err:
        msg = f"{path}: cannot read ({err.strerror})"
        raise LogError(msg) from err
    if not head:
        msg = f"{path}: the file is empty (0 bytes); it holds no log"
        raise LogError(msg)
    if head.startswith(_ROS1_MAGIC):
        return "ros1"
    if head.startswith(_MCAP_MAGIC):
        return "mcap"
    if head.startswith(_SQLITE_MAGIC) and (path.parent / "metadata.yaml").is_file():
        return "ros2"
    msg = (
        f"{path}: not a log redrive reads (starts with {head[:8]!r}); expected a ROS 1 bag, an "
        "MCAP file, a ROS 2 bag directory or a KITTI object folder"
    )
    raise LogError(msg)


def open_log(path: str | Path, *, strict: bool = True) -> LogReader:
    """Open any log redrive reads, recognised by its content.

    Args:
        path: a ROS 1 ``.bag``; a ROS 2 bag directory (sqlite3 or mcap storage), or its
            ``metadata.yaml``; a standalone ``.mcap`` (ROS 2 CDR or ROS 1 encoding); a KITTI
            3D-object folder (``training/{velodyne,image_2,calib,label_2}``).
        strict: when True, damage met while reading raises
            :class:`~redrive.errors.LogTruncatedError` after every message before it was
            yielded; when False the damage is logged and reading goes on where it can.

    Raises:
        LogError: the path is missing, empty, damaged beyond use or not a log.
    """
    path = Path(path)
    fmt = detect_format(path)
    if fmt == "ros1":
        from redrive.io.ros1bag import Ros1BagReader

        return Ros1BagReader(path, strict=strict)
    if fmt == "ros2":
        from redrive.io.ros2bag import Ros2BagReader

        return Ros2BagReader(path if path.is_dir() else path.parent, strict=strict)
    if fmt == "mcap":
        from redrive.io.mcapfile import McapFileReader

        return McapFileReader(path, strict=strict)
    from redrive.io.kitti import KittiReader

    reader: LogReader = KittiReader(path)
    return reader
