"""TFRecord files read without TensorFlow: the framing of every record checked.

A TFRecord file is a sequence of records, each (TensorFlow ``core/lib/io/record_writer.cc``,
``RecordWriter::WriteRecord``)::

    uint64 length        little-endian
    uint32 masked_crc32c(length bytes)
    byte   data[length]
    uint32 masked_crc32c(data)

with ``masked(crc) = ((crc >> 15) | (crc << 17)) + 0xa282ead8`` (mod 2³², ``crc32c.h``, ``Mask``)
over CRC-32C (Castagnoli).  A record whose length CRC or data CRC does not match, or that the
file ends inside, is damage: :class:`~redrive.errors.LogError` names the file, the record's
index and its byte offset.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import google_crc32c

from redrive.errors import LogError

__all__ = ["TfRecord", "looks_like_tfrecord", "masked_crc32c", "read_tfrecords", "write_tfrecord"]

_HEADER = struct.Struct("<QI")
_FOOTER = struct.Struct("<I")
_MASK_DELTA = 0xA282EAD8


def masked_crc32c(data: bytes | memoryview) -> int:
    """TFRecord's masked CRC-32C of ``data``."""
    crc = int(google_crc32c.value(bytes(data)))
    return (((crc >> 15) | (crc << 17)) + _MASK_DELTA) & 0xFFFFFFFF


@dataclass(frozen=True, slots=True, kw_only=True)
class TfRecord:
    """One record: its index in the file, its byte offset (of its length field) and its data."""

    index: int
    offset: int
    data: bytes


def read_tfrecords(path: Path, *, limit: int | None = None) -> Iterator[TfRecord]:
    """The records of the TFRecord file at ``path``, in file order, each checked (the first
    ``limit`` only, when given).

    Raises:
        LogError: unreadable; a record is cut off or its length or data CRC does not match
            (the message names the record and its byte offset).
    """
    try:
        fh = path.open("rb")
        size = path.stat().st_size
    except OSError as err:
        msg = f"{path}: cannot read ({err.strerror}); restore the file"
        raise LogError(msg) from err
    with fh:
        offset = 0
        index = 0
        while offset < size and (limit is None or index < limit):
            where = f"{path}: record {index} at byte {offset}"
            head = fh.read(_HEADER.size)
            if len(head) < _HEADER.size:
                msg = (
                    f"{where}: the file ends after {len(head)} of the record's 12 header "
                    "bytes; it is cut off, restore it"
                )
                raise LogError(msg)
            length, length_crc = _HEADER.unpack(head)
            if masked_crc32c(head[:8]) != length_crc:
                msg = (
                    f"{where}: the CRC of its length field does not match (length {length} "
                    "read); the file is damaged here, restore it"
                )
                raise LogError(msg)
            start = offset + _HEADER.size
            if start + length + _FOOTER.size > size:
                msg = (
                    f"{where}: it holds {length} bytes but the file ends {size - start} bytes "
                    "after its header; it is cut off, restore it"
                )
                raise LogError(msg)
            body = fh.read(length + _FOOTER.size)
            data = body[:length]
            (data_crc,) = _FOOTER.unpack_from(body, length)
            if masked_crc32c(data) != data_crc:
                msg = (
                    f"{where}: the CRC of its {length} data bytes (from byte {start}) does "
                    "not match; the record is damaged, restore the file"
                )
                raise LogError(msg)
            yield TfRecord(index=index, offset=offset, data=data)
            offset = start + length + _FOOTER.size
            index += 1


def looks_like_tfrecord(path: Path) -> bool:
    """Whether ``path`` starts with a TFRecord header whose length CRC matches."""
    try:
        with path.open("rb") as fh:
            head = fh.read(_HEADER.size)
    except OSError:
        return False
    if len(head) < _HEADER.size:
        return False
    _, length_crc = _HEADER.unpack(head)
    return bool(masked_crc32c(head[:8]) == length_crc)


def write_tfrecord(path: Path, records: list[bytes]) -> None:
    """Write ``records`` as a TFRecord file (for tests and conversions)."""
    with path.open("wb") as fh:
        for data in records:
            length = struct.pack("<Q", len(data))
            fh.write(length + struct.pack("<I", masked_crc32c(length)))
            fh.write(data + struct.pack("<I", masked_crc32c(data)))
