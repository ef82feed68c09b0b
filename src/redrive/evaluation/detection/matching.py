"""Greedy matching of detections to ground truth inside frames, vectorised across frames.

Both benchmarks match greedily inside each frame (nuScenes: detections in order of confidence take
their nearest free ground truth; KITTI: ground truths in label order take their best free
detection).  A frame's outcome depends on no other frame, so the k-th step of every frame is done at
once: objects are laid out in padded (frames, slots) tables and a Python loop runs over the slot k
only (≤ the most objects in one frame), each step vectorised over all frames.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["PaddedFrames", "pad_by_frame"]

I64 = npt.NDArray[np.int64]


class PaddedFrames:
    """Rows of one table grouped by frame into a (frames, slots) table of row indices.

    Attributes:
        frames: (F,) the frames, increasing.
        index: (F, K) row index of the k-th object of each frame in the wanted order; −1 = empty.
        valid: (F, K) ``index >= 0``.
    """

    __slots__ = ("frames", "index", "valid")

    def __init__(self, frames: I64, index: I64) -> None:
        self.frames = frames
        self.index = index
        self.valid = index >= 0


def pad_by_frame(frame_of_row: I64, frames: I64, *, order_key: I64 | None = None) -> PaddedFrames:
    """Group the rows whose frame is in ``frames`` (increasing, unique) by frame.

    Args:
        frame_of_row: (N,) frame of each row.
        frames: the frames to lay out, increasing; rows of other frames are left out.
        order_key: (N,) order of rows inside a frame (smaller first); default: row order.
    """
    n = frame_of_row.shape[0]
    rows = np.flatnonzero(np.isin(frame_of_row, frames))
    key = np.arange(n, dtype=np.int64) if order_key is None else order_key
    rows = rows[np.lexsort((key[rows], frame_of_row[rows]))]
    slot_frame = np.searchsorted(frames, frame_of_row[rows])
    starts = np.searchsorted(frame_of_row[rows], frames, side="left")
    pos = np.arange(rows.shape[0]) - starts[slot_frame]
    width = int(pos.max()) + 1 if rows.size else 0
    index = np.full((frames.shape[0], width), -1, dtype=np.int64)
    index[slot_frame, pos] = rows
    return PaddedFrames(frames, index)
