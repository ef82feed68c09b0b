"""The two ways :func:`~redrive.io.rosbag1.index.chunk_spans` checks a chunk's messages against
the index — as one array (many messages) and one ``bytes`` at a time (few) — accept and refuse
the same chunks and give the same spans, on intact and on damaged record headers, and what they
accept is what the reader's walk of each header finds."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from redrive.io import open_log
from redrive.io.rosbag1 import index as ros1bag_index
from redrive.io.rosbag1.index import chunk_spans, merged_index
from redrive.io.rosbag1.reader import Ros1BagReader
from redrive.io.rosbag1.records import DamageError
from tests.io.test_ros1bag_batches import _write


def _chunks(path: Path) -> list[tuple[memoryview, np.ndarray, np.ndarray, np.ndarray]]:
    """Every chunk's bytes and the index's (offsets, times, connections) of its messages."""
    with open_log(path) as log:
        assert isinstance(log, Ros1BagReader)
        times, chunk_pos, offsets, conns = merged_index(
            log._index_arrays(), sorted(log._selected_ids(None)), None
        )
        out = []
        for pos in np.unique(chunk_pos).tolist():
            chunk, _ = log._chunk_bytes(log._rosbags.chunks[pos])  # type: ignore[union-attr]
            at = chunk_pos == pos
            out.append((memoryview(bytes(chunk)), offsets[at], times[at], conns[at]))
            del chunk
    return out


def _both(chunk: memoryview, offsets: np.ndarray, times: np.ndarray, conns: np.ndarray) -> tuple:
    saved = ros1bag_index.ARRAYS_FROM
    try:
        ros1bag_index.ARRAYS_FROM = 0
        arrays = chunk_spans(chunk, offsets, times, conns)
        ros1bag_index.ARRAYS_FROM = 1 << 30
        one_by_one = chunk_spans(chunk, offsets, times, conns)
    finally:
        ros1bag_index.ARRAYS_FROM = saved
    return arrays, one_by_one


def _walk(
    chunk: memoryview, offsets: np.ndarray, times: np.ndarray, conns: np.ndarray
) -> list[tuple[int, int]] | None:
    try:
        return [
            Ros1BagReader._message_span(chunk, o, t, c)
            for o, t, c in zip(offsets.tolist(), times.tolist(), conns.tolist(), strict=True)
        ]
    except DamageError:
        return None


def _damaged(chunk: Any, offsets: Any, rng: np.random.Generator) -> memoryview:
    """``chunk`` with one byte of a header or of its data length changed, in a message at
    random."""
    k = int(rng.integers(len(offsets)))
    head = int.from_bytes(chunk[int(offsets[k]) : int(offsets[k]) + 4], "little")
    at = int(offsets[k]) + int(rng.integers(head + 8))
    broken = bytearray(chunk)
    broken[at] ^= int(rng.integers(1, 256))
    return memoryview(bytes(broken))


def test_both_checks_agree_with_the_walk_on_every_chunk_and_every_damaged_byte(
    tmp_path: Path,
) -> None:
    """Chunks of clouds of several topics between other messages, damaged at random bytes."""
    path = tmp_path / "clouds.bag"
    _write(path, count=24)
    rng = np.random.default_rng(7)
    checked = damaged_refused = 0
    for chunk, offsets, times, conns in _chunks(path):
        arrays, one_by_one = _both(chunk, offsets, times, conns)
        assert arrays is not None
        assert one_by_one is not None
        walked = _walk(chunk, offsets, times, conns)
        assert walked is not None
        for spans in (arrays, one_by_one):
            assert list(zip(spans[0], spans[1], strict=True)) == walked
        for _ in range(60):
            view = _damaged(chunk, offsets, rng)
            arrays, one_by_one = _both(view, offsets, times, conns)
            if arrays is None:
                assert one_by_one is None
                damaged_refused += 1
                continue
            assert one_by_one is not None
            assert list(arrays[0]) == list(one_by_one[0])
            assert list(arrays[1]) == list(one_by_one[1])
            walked = _walk(view, offsets, times, conns)
            assert walked == list(zip(arrays[0], arrays[1], strict=True))
            checked += 1
    # Most damage is refused; a changed low byte of a data length can still be in bounds.
    assert damaged_refused > 60
    assert checked >= 1


def test_the_strided_check_of_a_chunk_of_one_sensor_agrees_with_the_others(
    tmp_path: Path,
) -> None:
    """Chunks of one topic's equal clouds at a fixed distance are checked as one strided view
    (:func:`~redrive.io.rosbag1.index._regular_spans`): intact, it finds the walk's spans and
    their distance; damaged at random bytes, it accepts and refuses what the other checks do."""
    path = tmp_path / "regular.bag"
    _write(path, count=40, mixed=False)
    rng = np.random.default_rng(11)
    strided = refused = 0
    for chunk, offsets, times, conns in _chunks(path):
        if len(offsets) < 2:
            continue
        spans = chunk_spans(chunk, offsets, times, conns)
        assert spans is not None
        assert spans[2] == int(offsets[1] - offsets[0])
        walked = _walk(chunk, offsets, times, conns)
        assert list(zip(spans[0], spans[1], strict=True)) == walked
        strided += 1
        for _ in range(40):
            view = _damaged(chunk, offsets, rng)
            found = chunk_spans(view, offsets, times, conns)
            saved = ros1bag_index.REGULAR_FROM
            try:
                ros1bag_index.REGULAR_FROM = 1 << 30
                others = _both(view, offsets, times, conns)
            finally:
                ros1bag_index.REGULAR_FROM = saved
            for other in others:
                if found is None:
                    assert other is None
                else:
                    assert other is not None
                    assert list(found[0]) == list(other[0])
                    assert list(found[1]) == list(other[1])
            refused += found is None
    assert strided >= 2
    assert refused > 20
