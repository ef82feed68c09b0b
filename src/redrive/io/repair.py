"""``repair_log``: what a damaged log still holds, written to a valid, indexed MCAP.

In the spirit of ``mcap recover`` and ``rosbag reindex``: the log is read past its damage
(``strict=False``) and every intact message is written, **as it is** — its bytes, channel,
schema and encodings are kept (no re-encoding, unlike :func:`~redrive.io.convert.convert_log`):

- an MCAP is copied record by record from a forward scan (:mod:`redrive.io.mcap.scan`):
  schemas, channels with their metadata, messages with their sequence and publish time, metadata
  and attachment records;
- a ROS 1 bag becomes an MCAP of profile ``ros1`` (``ros1msg`` schemas from the bag's connection
  definitions, ``ros1`` message encoding);
- a ROS 2 bag becomes an MCAP of profile ``ros2`` (``ros2msg``/``ros2idl`` schemas from the bag,
  or generated from redrive's type store when the bag holds none; ``cdr`` encoding).

The output is written to a temporary file beside it and renamed over ``out_path`` when complete.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

from redrive.errors import LogError, is_no_space
from redrive.io.base import LogReader
from redrive.io.damage import LogDamage, damage_report
from redrive.io.mcap.part import McapPart
from redrive.io.mcap.reader import McapFileReader
from redrive.io.mcap.scan import (
    McapAttachment,
    McapChannel,
    McapMetadata,
    McapSchema,
    Message,
)
from redrive.io.readers import open_log
from redrive.io.rosbag1.reader import Ros1BagReader
from redrive.io.rosbag2.reader import Ros2BagReader

__all__ = ["RepairStats", "repair_log"]

_COMPRESSION = ("zstd", "lz4", "none")


@dataclass(frozen=True, slots=True, kw_only=True)
class RepairStats:
    """What :func:`repair_log` wrote and what it could not.

    Attributes:
        output_path: the MCAP written.
        source_format: the damaged log's format.
        messages_written: messages in the output.
        topics: topic → messages written.
        damage: the damaged parts of the source that were skipped.
        messages_dropped: intact messages left out because the record that says what they are
            (their channel or schema) was in a damaged part.
    """

    output_path: Path
    source_format: str
    messages_written: int
    topics: Mapping[str, int] = field(default_factory=dict)
    damage: tuple[LogDamage, ...] = ()
    messages_dropped: int = 0

    @property
    def messages_lost(self) -> tuple[int, bool]:
        """Messages lost as far as the log says, and whether some part lost an unknown number."""
        known = sum(d.messages_lost or 0 for d in self.damage) + self.messages_dropped
        return known, any(d.messages_lost is None for d in self.damage)


class _Out:
    """The MCAP being written (:class:`~redrive.io.mcap.part.McapPart`: a part renamed over the
    target on :meth:`close`; a full disk keeps what was written) and its messages per topic."""

    def __init__(self, path: Path, *, profile: str, compression: str) -> None:
        self.part = McapPart(
            path,
            profile=profile,
            library="redrive repair",
            compression=compression,  # type: ignore[arg-type]
        )
        self.writer = self.part.stream
        self.counts: dict[str, int] = {}

    def close(self) -> None:
        self.part.close()

    def abort(self, err: BaseException) -> None:
        if is_no_space(err) and self.part.is_open:
            raise self.part.out_of_space(err) from err  # type: ignore[arg-type]
        self.part.abort()


def repair_log(
    in_path: str | Path, out_path: str | Path, *, compression: str = "zstd"
) -> RepairStats:
    """Write everything of the log at ``in_path`` that is still intact to the MCAP ``out_path``.

    Args:
        in_path: an MCAP file or a ROS 1 / ROS 2 bag (damaged or not).
        out_path: the ``.mcap`` to write (replaced if it exists; never the input).
        compression: chunk compression of the output: ``zstd``, ``lz4`` or ``none``.

    Raises:
        LogError: the input cannot be opened at all, or is not an MCAP or a bag; the output
            cannot be written.
    """
    src, out = Path(in_path), Path(out_path)
    if out.suffix != ".mcap":
        msg = f"{out}: the repaired log is an MCAP file: give an output path ending in .mcap"
        raise LogError(msg)
    if compression not in _COMPRESSION:
        msg = f"compression must be one of {sorted(_COMPRESSION)}, got {compression!r}"
        raise LogError(msg)
    if out.exists() and src.exists() and out.resolve() == src.resolve():
        msg = f"{out}: the output would replace the damaged input; write it elsewhere"
        raise LogError(msg)
    with open_log(src, strict=False, packets="raw") as reader:
        if isinstance(reader, McapFileReader):
            return _repair_mcap(reader, out, compression)
        if isinstance(reader, Ros1BagReader | Ros2BagReader):
            return _repair_bag(reader, out, compression)
        msg = (
            f"{src}: a {reader.format} log has no damage redrive can repair; "
            f"`redrive convert {src} {out}` writes it as MCAP"
        )
        raise LogError(msg)


def _repair_mcap(reader: McapFileReader, out_path: Path, compression: str) -> RepairStats:
    out = _Out(out_path, profile=_mcap_profile(reader), compression=compression)
    schemas: dict[int, int] = {}  # source id → output id
    channels: dict[int, tuple[int, str]] = {}
    pending: dict[int, McapChannel] = {}  # channels whose schema has not been seen (yet)
    damage: list[LogDamage] = []
    written = dropped = 0
    # the records of the summary or the whole file: for messages whose schema or channel record
    # before them is damaged
    summary_schemas, summary_channels = reader.known_records()
    try:
        for kind, item in reader.scan():
            if kind == "message":
                cid, seq, log_time, pub_time, data = cast("Message", item)
                known = channels.get(cid)
                if known is None and cid in summary_channels:
                    channel = pending.pop(cid, None) or summary_channels[cid]
                    sid = channel.schema_id
                    if sid != 0 and sid not in schemas and sid in summary_schemas:
                        schema = summary_schemas[sid]
                        schemas[sid] = out.writer.register_schema(
                            schema.name, schema.encoding, schema.data
                        )
                    if sid == 0 or sid in schemas:
                        _add_channel(out, channel, schemas, channels)
                        known = channels[cid]
                if known is None:
                    dropped += 1
                    continue
                out.writer.add_message(
                    known[0], log_time=log_time, publish_time=pub_time, sequence=seq, data=data
                )
                out.counts[known[1]] = out.counts.get(known[1], 0) + 1
                written += 1
            elif kind == "schema":
                schema = cast("McapSchema", item)
                if schema.id not in schemas:
                    schemas[schema.id] = out.writer.register_schema(
                        schema.name, schema.encoding, schema.data
                    )
                    for channel in [c for c in pending.values() if c.schema_id == schema.id]:
                        del pending[channel.id]
                        _add_channel(out, channel, schemas, channels)
            elif kind == "channel":
                channel = cast("McapChannel", item)
                if channel.id in channels:
                    continue
                if channel.schema_id == 0 or channel.schema_id in schemas:
                    _add_channel(out, channel, schemas, channels)
                else:
                    pending[channel.id] = channel
            elif kind == "metadata":
                meta = cast("McapMetadata", item)
                out.writer.add_metadata(meta.name, dict(meta.metadata))
            elif kind == "attachment":
                att = cast("McapAttachment", item)
                out.writer.add_attachment(
                    name=att.name,
                    media_type=att.media_type,
                    data=att.data,
                    log_time=att.log_time,
                    create_time=att.create_time,
                )
            elif kind == "damage":
                damage.append(cast("LogDamage", item))
        out.close()
    except BaseException as err:
        out.abort(err)
        raise
    return RepairStats(
        output_path=out_path,
        source_format=reader.format,
        messages_written=written,
        topics=dict(sorted(out.counts.items())),
        damage=tuple(dict.fromkeys([*damage, *_summary_damage(reader)])),
        messages_dropped=dropped,
    )


def _summary_damage(reader: McapFileReader) -> list[LogDamage]:
    return [d for d in reader.damage_report if d.start_byte is None]


def _mcap_profile(reader: McapFileReader) -> str:
    encodings = {t.encoding for t in reader.topics.values()}
    return "ros1" if encodings == {"ros1"} else "ros2"


def _add_channel(
    out: _Out,
    channel: McapChannel,
    schemas: Mapping[int, int],
    channels: dict[int, tuple[int, str]],
) -> None:
    new_id = out.writer.register_channel(
        channel.topic,
        channel.message_encoding,
        schemas.get(channel.schema_id, 0),
        dict(channel.metadata),
    )
    channels[channel.id] = (new_id, channel.topic)


def _repair_bag(reader: LogReader, out_path: Path, compression: str) -> RepairStats:
    ros1 = isinstance(reader, Ros1BagReader)
    out = _Out(out_path, profile="ros1" if ros1 else "ros2", compression=compression)
    ids: dict[str, int] = {}
    try:
        for topic, (schema_name, encoding, text) in _bag_schemas(reader).items():
            schema_id = (
                out.writer.register_schema(schema_name, encoding, text.encode("utf-8"))
                if encoding
                else 0
            )
            ids[topic] = out.writer.register_channel(
                topic, "ros1" if ros1 else "cdr", schema_id, {}
            )
        written = 0
        sequence: dict[str, int] = {}
        for message in reader.messages():
            channel = ids.get(message.topic)
            if channel is None:
                continue
            seq = sequence[message.topic] = sequence.get(message.topic, 0) + 1
            out.writer.add_message(
                channel,
                log_time=message.log_time_ns,
                publish_time=message.log_time_ns,
                sequence=seq,
                data=message.raw,
            )
            out.counts[message.topic] = out.counts.get(message.topic, 0) + 1
            written += 1
        out.close()
    except BaseException as err:
        out.abort(err)
        raise
    return RepairStats(
        output_path=out_path,
        source_format=reader.format,
        messages_written=written,
        topics=dict(sorted(out.counts.items())),
        damage=damage_report(reader),
    )


def _bag_schemas(reader: LogReader) -> dict[str, tuple[str, str, str]]:
    """Topic → (schema name, schema encoding or "" for none, schema text)."""
    out: dict[str, tuple[str, str, str]] = {}
    if isinstance(reader, Ros1BagReader):
        for topic, (msgtype, msgdef) in reader.definitions().items():
            name = msgtype.replace("/msg/", "/")
            out[topic] = (name, "ros1msg" if msgdef else "", msgdef)
        return out
    assert isinstance(reader, Ros2BagReader)
    store = reader.typestores.get("cdr")
    for topic, (msgtype, kind, text) in reader.definitions().items():
        if kind:
            out[topic] = (msgtype, "ros2msg" if kind == "msg" else "ros2idl", text)
        elif store is not None and msgtype in store.fielddefs:
            generated, _ = store.generate_msgdef(msgtype, ros_version=2)
            out[topic] = (msgtype, "ros2msg", generated)
        else:
            out[topic] = (msgtype, "", "")
    return out
