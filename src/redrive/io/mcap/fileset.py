"""Several MCAP files of one recording — ``redrive live --split-size``'s numbered files, or
``rosbag record --split``-like sets converted to MCAP — read as one log.

Give a folder holding them (and no ``metadata.yaml``: that is a ROS 2 bag) or a glob
(``'drive_*.mcap'``, quoted for the shell). Each file is opened with
:class:`~redrive.io.mcap.reader.McapFileReader`; messages come in log-time order across files (a merge:
files may overlap in time at their edges), the topics' counts and sizes are summed.
"""

from __future__ import annotations

import glob
import heapq
from collections.abc import Collection, Iterator, Mapping
from dataclasses import replace
from pathlib import Path

from redrive.errors import LogError
from redrive.io.base import LogMessage, TopicInfo
from redrive.io.mcap.reader import McapFileReader
from redrive.io.recognise import starts_with

__all__ = ["McapSetReader", "expand_log_set", "is_glob"]

_MAGIC = b"\x89MCAP"


def is_glob(path: Path | str) -> bool:
    """True when ``path`` holds glob characters (``*``, ``?``, ``[``)."""
    return glob.has_magic(str(path))


def expand_log_set(path: Path) -> list[Path]:
    """The MCAP files a folder or a glob names, sorted by name (empty when it names none)."""
    if is_glob(path) and not path.exists():
        found = [Path(p) for p in glob.glob(str(path))]
    elif path.is_dir():
        if (path / "metadata.yaml").exists():
            return []
        found = list(path.glob("*.mcap"))
    else:
        return []
    return sorted(p for p in found if p.is_file() and starts_with(p, _MAGIC))


class McapSetReader:
    """The MCAP files of a folder or a glob, as one log (see the module text)."""

    format = "mcap-set"
    description = "several MCAP files of one recording (a folder of them, or a quoted glob)"
    #: each of its files is a log too: `redrive batch DIR` takes them one by one
    reads_a_set = True

    @classmethod
    def recognises(cls, path: Path) -> bool:
        return bool(expand_log_set(path))

    def __init__(self, path: Path, *, strict: bool = True) -> None:
        self.path = Path(path)
        files = expand_log_set(self.path)
        if not files:
            msg = f"{self.path}: names no MCAP file; give a folder of .mcap files or a glob"
            raise LogError(msg)
        self.parts: list[McapFileReader] = []
        try:
            for file in files:
                self.parts.append(McapFileReader(file, strict=strict))
        except BaseException:
            self.close()
            raise
        self.parts.sort(key=lambda r: (r.start_ns, str(r.path)))
        topics: dict[str, TopicInfo] = {}
        self._owner: dict[str, McapFileReader] = {}
        for part in self.parts:
            for name, info in part.topics.items():
                prev = topics.get(name)
                if prev is None:
                    topics[name] = info
                    self._owner[name] = part
                    continue
                if prev.msgtype != info.msgtype:
                    msg = (
                        f"{part.path}: topic {name} is {info.msgtype} there but {prev.msgtype} in "
                        f"{self._owner[name].path}; these files are not one recording"
                    )
                    raise LogError(msg)
                size = (
                    prev.size_bytes + info.size_bytes
                    if prev.size_bytes >= 0 and info.size_bytes >= 0
                    else -1
                )
                topics[name] = replace(prev, count=prev.count + info.count, size_bytes=size)
        self._topics = dict(sorted(topics.items()))

    @property
    def topics(self) -> Mapping[str, TopicInfo]:
        return self._topics

    @property
    def capabilities(self):  # type: ignore[no-untyped-def]  # same as one file's
        from redrive.io.ros.decoders import capabilities_of

        return capabilities_of(self._topics.values(), message_typed=True)

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    @property
    def start_ns(self) -> int:
        starts = [p.start_ns for p in self.parts if p.message_count]
        return min(starts) if starts else 0

    @property
    def end_ns(self) -> int:
        return max((p.end_ns for p in self.parts if p.message_count), default=0)

    @property
    def typestores(self) -> Mapping[str, object]:
        return self.parts[0].typestores

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        streams = [
            p.messages(topics=topics, start_ns=start_ns, stop_ns=stop_ns)
            for p in self.parts
            if (stop_ns is None or p.start_ns < stop_ns)
            and (start_ns is None or p.end_ns >= start_ns)
        ]
        yield from heapq.merge(*streams, key=lambda m: m.log_time_ns)

    def deserialize(self, message: LogMessage) -> object:
        owner = self._owner.get(message.topic)
        if owner is None:
            msg = f"{self.path}: no file of this set holds topic {message.topic}"
            raise LogError(msg)
        return owner.deserialize(message)

    def close(self) -> None:
        for part in self.parts:
            part.close()

    def __enter__(self) -> McapSetReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
