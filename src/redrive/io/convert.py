"""Convert any log redrive reads into MCAP (ROS 2 CDR) or a ROS 1 bag.

The output format follows the suffix of ``out_path``: ``.mcap`` → MCAP with profile ``ros2``,
CDR messages and ``ros2msg`` schemas (see :class:`~redrive.io.mcap.writer.McapWriter`); ``.bag`` → a
ROS 1 bag written with ``rosbags.rosbag1.Writer``.

Serialised ROS messages are **re-encoded, not decoded** to the data model, so no field is lost:
bytes whose wire format is the same in both stores are copied (same encoding) or converted with
rosbags' ``cdr_to_ros1`` / ``ros1_to_cdr`` (which add or drop ROS 1 ``Header.seq``); other types
are migrated field by field with rosbags' ``migrate_message``.  Message types keep the log's own
definitions (only ``std_msgs/Header`` follows the output's ROS version), and ``tf/tfMessage``
becomes ``tf2_msgs/msg/TFMessage``.  Native messages (KITTI) are serialised from their decoded
values as standard messages (:mod:`redrive.io.ros.encode`).

Topics whose type has no definition are skipped (they are named in the stats); a message that
does not deserialise is skipped and counted.  The output is written atomically.
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import tempfile
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

from rosbags.convert.converter import is_same_wireformat, migrate_message
from rosbags.rosbag1 import Writer as Bag1Writer
from rosbags.rosbag1 import WriterError as Bag1WriterError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from redrive.errors import LogError, RedriveError
from redrive.io.base import DecodedKind, LogMessage, LogReader
from redrive.io.damage import damage_report, refused
from redrive.io.mcap.writer import McapWriter
from redrive.io.readers import open_log
from redrive.io.ros.decoders.base import Decoded
from redrive.io.ros.encode import encode_value
from redrive.io.ros.typestore import typestore_for

__all__ = ["ConvertStats", "Progress", "convert_log"]

logger = logging.getLogger(__name__)

#: ``progress(messages_done, messages_total)``; total counts the selected topics' messages over
#: the whole log (an upper bound when a time range is given).
Progress = Callable[[int, int], None]

_RENAMES: Mapping[str, str] = {"tf/msg/tfMessage": "tf2_msgs/msg/TFMessage"}
_PROGRESS_EVERY = 100


@dataclass(frozen=True, slots=True, kw_only=True)
class ConvertStats:
    """What :func:`convert_log` wrote.

    Attributes:
        output_path: the file written.
        output_format: ``mcap`` or ``ros1``.
        messages_written: messages in the output.
        messages_skipped: messages that did not deserialise (logged at WARNING).
        topics: topic → msgtype of every topic written.
        skipped_topics: topic → why it was left out (no definition of its type).
    """

    output_path: Path
    output_format: Literal["mcap", "ros1"]
    messages_written: int = 0
    messages_skipped: int = 0
    topics: Mapping[str, str] = field(default_factory=dict)
    skipped_topics: Mapping[str, str] = field(default_factory=dict)


def _source_stores(reader: LogReader) -> dict[str, Typestore]:
    """encoding (``ros1`` / ``cdr``) → the typestore the reader deserialises with."""
    stores = getattr(reader, "typestores", None)
    if isinstance(stores, Mapping):
        return {k: v for k, v in stores.items() if isinstance(v, Typestore)}
    # The redrive readers keep theirs on their Deserializer.
    deserializer = getattr(reader, "_deserializer", None)
    out: dict[str, Typestore] = {}
    for encoding in ("ros1", "cdr"):
        store = getattr(deserializer, encoding, None)
        if isinstance(store, Typestore):
            out[encoding] = store
    return out


def _destination_store(
    sources: Mapping[str, Typestore], *, ros_version: Literal[1, 2]
) -> Typestore:
    """The output store: standard + shipped types, overlaid with the log's own definitions.

    ``std_msgs/msg/Header`` always keeps the output version's layout.
    """
    base, _ = typestore_for(ros_version)
    typs: dict[str, Any] = dict(base.fielddefs)
    same = "cdr" if ros_version == 2 else "ros1"
    for encoding in sorted(sources, key=lambda e: e == same):  # the same-version store wins
        typs.update(sources[encoding].fielddefs)
    typs["std_msgs/msg/Header"] = base.fielddefs["std_msgs/msg/Header"]
    store = get_typestore(Stores.EMPTY)
    store.register(typs)
    return store


Converter = Callable[[bytes | memoryview], bytes | memoryview]


class _Recoder:
    """Serialised messages of the source → bytes in the output encoding (per type, cached)."""

    def __init__(self, sources: Mapping[str, Typestore], dst: Typestore, *, dst_is2: bool) -> None:
        self.sources = sources
        self.dst = dst
        self.dst_is2 = dst_is2
        self._cache: dict[str, object] = {}
        self._converters: dict[tuple[str, str], Converter] = {}

    def converter(self, encoding: str, msgtype: str) -> Converter:
        key = (encoding, msgtype)
        conv = self._converters.get(key)
        if conv is None:
            conv = self._make(encoding, msgtype)
            self._converters[key] = conv
        return conv

    def _make(self, encoding: str, msgtype: str) -> Converter:
        src = self.sources[encoding]
        dst_type = _RENAMES.get(msgtype, msgtype)
        src_is2 = encoding == "cdr"
        dst = self.dst
        if is_same_wireformat(src, dst, msgtype, dst_type):
            if src_is2 == self.dst_is2:
                return lambda data: data
            if src_is2:
                return lambda data: src.cdr_to_ros1(data, msgtype)
            return lambda data: dst.ros1_to_cdr(data, dst_type)
        logger.debug("%s is migrated field by field to %s", msgtype, dst_type)

        def migrate(data: bytes | memoryview) -> bytes | memoryview:
            msg = (
                src.deserialize_cdr(data, msgtype)
                if src_is2
                else src.deserialize_ros1(data, msgtype)
            )
            out = migrate_message(src, dst, msgtype, dst_type, self._cache, msg)
            return (
                dst.serialize_cdr(out, dst_type)
                if self.dst_is2
                else dst.serialize_ros1(out, dst_type)
            )

        return migrate


class _Sink:
    """One output file: MCAP through McapWriter, or a ROS 1 bag (written to a temp dir)."""

    def __init__(self, out_path: Path, store: Typestore, *, compression: str | None) -> None:
        self.path = out_path
        self.store = store
        self.is2 = out_path.suffix == ".mcap"
        self._mcap: McapWriter | None = None
        self._bag: Bag1Writer | None = None
        self._tmpdir: Path | None = None
        self._conns: dict[str, Any] = {}
        if self.is2:
            comp = compression or "zstd"
            self._mcap = McapWriter(out_path, compression=comp, typestore=store)  # type: ignore[arg-type]
            return
        try:
            self._tmpdir = Path(tempfile.mkdtemp(dir=out_path.parent, prefix=f".{out_path.name}."))
        except OSError as err:
            msg = f"{out_path}: cannot write in {out_path.parent} ({err.strerror}); check the directory"
            raise LogError(msg) from err
        self._bag = Bag1Writer(self._tmpdir / out_path.name)
        comp = compression or "lz4"
        if comp != "none":
            self._bag.set_compression(Bag1Writer.CompressionFormat[comp.upper()])
        self._bag.open()

    def write(self, topic: str, msgtype: str, log_time_ns: int, data: bytes | memoryview) -> None:
        if self._mcap is not None:
            self._mcap.write_raw(topic, msgtype, log_time_ns, data)
            return
        assert self._bag is not None
        conn = self._conns.get(topic)
        if conn is None:
            latching = 1 if topic.endswith("tf_static") else 0
            conn = self._bag.add_connection(topic, msgtype, typestore=self.store, latching=latching)
            self._conns[topic] = conn
        self._bag.write(conn, log_time_ns, data)

    def close(self) -> None:
        if self._mcap is not None:
            self._mcap.close()
            return
        assert self._bag is not None
        assert self._tmpdir is not None
        try:
            self._bag.close()
            (self._tmpdir / self.path.name).replace(self.path)
        finally:
            shutil.rmtree(self._tmpdir, ignore_errors=True)

    def abort(self) -> None:
        if self._mcap is not None:
            self._mcap.abort()
            return
        if self._bag is not None:
            with contextlib.suppress(Bag1WriterError, OSError, ValueError):
                self._bag.close()
        if self._tmpdir is not None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)


def convert_log(
    in_path: str | Path,
    out_path: str | Path,
    *,
    topics: Collection[str] | None = None,
    start_ns: int | None = None,
    stop_ns: int | None = None,
    progress: Progress | None = None,
    compression: str | None = None,
    strict: bool = True,
) -> ConvertStats:
    """Convert a log (anything :func:`~redrive.io.open_log` opens) to ``.mcap`` or ``.bag``.

    Args:
        in_path: the source log.
        out_path: the output file; its suffix picks the format.  Replaced if it exists.
        topics: only these topics (all when None).
        start_ns, stop_ns: only messages with ``start_ns <= log_time < stop_ns``.
        progress: called every 100 messages and at the end (see :data:`Progress`).
        compression: MCAP ``zstd`` (default) / ``lz4`` / ``none``; bag ``lz4`` (default) /
            ``bz2`` / ``none``.
        strict: passed to :func:`~redrive.io.open_log`: when True, damage in the source stops
            the conversion (no output is left behind) — any damage the reader reports, also
            what loses no message (a missing summary or index, a chunk header whose size
            lies), as ``redrive info --strict`` refuses it; when False what is readable is
            converted.

    Raises:
        LogError: the source cannot be read, or the output cannot be written.
    """
    out = Path(out_path)
    if out.suffix not in (".mcap", ".bag"):
        msg = f"{out}: the output must end in .mcap (MCAP, ROS 2) or .bag (ROS 1 bag)"
        raise LogError(msg)
    with open_log(in_path, strict=strict, packets="raw") as reader:
        if strict and (found := damage_report(reader)):
            raise refused(reader.path, found[0], messages_read=0)
        sources = _source_stores(reader)
        is2 = out.suffix == ".mcap"
        store = _destination_store(sources, ros_version=2 if is2 else 1)
        recoder = _Recoder(sources, store, dst_is2=is2)
        native_store = store if is2 else typestore_for(2)[0]
        asked = None if topics is None else set(topics)  # sets: 50k topics made lists quadratic
        selected = [t for t in reader.topics.values() if asked is None or t.topic in asked]
        skipped_topics = {
            t.topic: f"no definition of {t.msgtype}"
            for t in selected
            if t.encoding != "native" and (not t.has_definition or t.encoding not in sources)
        }
        for topic, why in skipped_topics.items():
            logger.warning("%s: topic %s is left out: %s", reader.path, topic, why)
        wanted = [t.topic for t in selected if t.topic not in skipped_topics]
        total = sum(t.count for t in selected if t.topic not in skipped_topics)
        written: dict[str, str] = {}
        done = skipped = 0
        failed_topics: set[str] = set()
        sink = _Sink(out, store, compression=compression)
        try:
            for message in reader.messages(topics=wanted, start_ns=start_ns, stop_ns=stop_ns):
                objects_as = None
                if reader.topics[message.topic].kind is DecodedKind.OBJECTS:
                    # an empty tuple of objects keeps its topic's type (else it reads as tf)
                    objects_as = written.get(message.topic, "vision_msgs/msg/Detection3DArray")
                try:
                    msgtype, data = _recode(
                        message, recoder, native_store, store, is2=is2, objects_as=objects_as
                    )
                except RedriveError:
                    raise
                except Exception as err:  # rosbags raises plain errors on bad bytes
                    skipped += 1
                    first = message.topic not in failed_topics
                    failed_topics.add(message.topic)
                    logger.log(
                        logging.WARNING if first else logging.DEBUG,
                        "%s: topic %s at %d ns: message skipped, it does not convert (%s: %s)%s",
                        reader.path,
                        message.topic,
                        message.log_time_ns,
                        type(err).__name__,
                        err,
                        " (further failures on this topic are counted, not logged)"
                        if first
                        else "",
                    )
                    continue
                sink.write(message.topic, msgtype, message.log_time_ns, data)
                written.setdefault(message.topic, msgtype)
                done += 1
                if progress is not None and done % _PROGRESS_EVERY == 0:
                    progress(done, total)
            if strict and (found := damage_report(reader)):  # recorded while reading
                raise refused(reader.path, found[0], messages_read=done + skipped)
        except BaseException:
            sink.abort()
            raise
        try:
            sink.close()
        except (Bag1WriterError, OSError) as err:
            msg = f"{out}: cannot finish the output ({err})"
            raise LogError(msg) from err
    if progress is not None:
        progress(done, total)
    return ConvertStats(
        output_path=out,
        output_format="mcap" if is2 else "ros1",
        messages_written=done,
        messages_skipped=skipped,
        topics=MappingProxyType(written),
        skipped_topics=MappingProxyType(skipped_topics),
    )


def _recode(
    message: LogMessage,
    recoder: _Recoder,
    native_store: Typestore,
    store: Typestore,
    *,
    is2: bool,
    objects_as: str | None = None,
) -> tuple[str, bytes | memoryview]:
    if message.encoding != "native":
        conv = recoder.converter(message.encoding, message.msgtype)
        return _RENAMES.get(message.msgtype, message.msgtype), conv(message.raw)
    payload = message.payload
    if not isinstance(payload, Decoded):
        msg = f"topic {message.topic}: a native message without a Decoded payload cannot be written"
        raise LogError(msg)
    msgtype, ros_msg = encode_value(
        payload.value,
        native_store,
        frame_id=payload.frame_id,
        stamp_ns=payload.stamp_ns,
        empty_objects_as=objects_as,
    )
    cdr = native_store.serialize_cdr(ros_msg, msgtype)
    if is2:
        return msgtype, cdr
    return msgtype, _cdr_to_ros1(cdr, msgtype, native_store, store)


def _cdr_to_ros1(
    cdr: bytes | memoryview, msgtype: str, src: Typestore, dst: Typestore
) -> bytes | memoryview:
    """ROS 2 CDR bytes of a standard type → ROS 1 bytes of ``dst`` (``Header.seq`` = 0).

    A type ``dst`` lacks (``tf2_msgs/msg/TFMessage`` is not in the Noetic store) is copied over
    from ``src`` first, keeping ``dst``'s Header.
    """
    if msgtype not in dst.fielddefs:
        text, _ = src.generate_msgdef(msgtype, ros_version=1)
        typs = get_types_from_msg(text, msgtype)
        dst.register({k: v for k, v in typs.items() if k not in dst.fielddefs})
    if is_same_wireformat(src, dst, msgtype, msgtype):
        return src.cdr_to_ros1(cdr, msgtype)
    msg = migrate_message(src, dst, msgtype, msgtype, {}, src.deserialize_cdr(cdr, msgtype))
    return dst.serialize_ros1(msg, msgtype)
