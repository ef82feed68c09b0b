"""What the map readers share when they build a :class:`~redrive.types.RoadMap`: references
into a cropped map dropped (:func:`drop_dangling`), roadblocks from the lane neighbours for a
format that has none (:func:`group_roadblocks`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from redrive.types import MapLane, Roadblock

__all__ = ["drop_dangling", "group_roadblocks", "roadblock_rows"]


def drop_dangling(lanes: Mapping[str, MapLane]) -> tuple[dict[str, MapLane], int]:
    """``lanes`` with every successor, predecessor and neighbour that is not among them left
    out (a map cropped around a log names lanes beyond its edge), and how many were dropped."""
    out: dict[str, MapLane] = {}
    dropped = 0
    for lane_id, lane in lanes.items():
        succ = tuple(i for i in lane.successors if i in lanes)
        pred = tuple(i for i in lane.predecessors if i in lanes)
        left = lane.left_neighbor if lane.left_neighbor in lanes else None
        right = lane.right_neighbor if lane.right_neighbor in lanes else None
        dropped += len(lane.successors) - len(succ) + len(lane.predecessors) - len(pred)
        dropped += (lane.left_neighbor is not None and left is None) + (
            lane.right_neighbor is not None and right is None
        )
        out[lane_id] = dataclasses.replace(
            lane, successors=succ, predecessors=pred, left_neighbor=left, right_neighbor=right
        )
    return out, dropped


def group_roadblocks(
    lanes: Mapping[str, MapLane], *, prefix: str = "rb:"
) -> tuple[dict[str, MapLane], tuple[Roadblock, ...]]:
    """Roadblocks (nuPlan's lane groups) for a map that has none: each row of lanes joined by
    mutual left/right neighbours, left to right, id ``prefix + <its leftmost lane id>``; a lane
    whose neighbours do not name it back is a roadblock of its own.  Returns the lanes with their
    ``roadblock_id`` set, and the roadblocks (successors / predecessors: those of their lanes)."""
    block_of, blocks = roadblock_rows(lanes, prefix=prefix)
    out = {i: dataclasses.replace(lane, roadblock_id=block_of[i]) for i, lane in lanes.items()}
    return out, blocks


def roadblock_rows(
    lanes: Mapping[str, Any], *, prefix: str = "rb:"
) -> tuple[dict[str, str], tuple[Roadblock, ...]]:
    """:func:`group_roadblocks`' lane id → roadblock id, and its roadblocks, of lanes given as
    anything with a :class:`MapLane`'s ``lane_id``, ``left_neighbor``, ``right_neighbor``,
    ``successors`` and ``predecessors`` (a reader that builds its lanes once, roadblock set)."""
    block_of: dict[str, str] = {}
    members: dict[str, list[str]] = {}
    for lane_id, lane in lanes.items():
        if lane_id in block_of:
            continue
        leftmost = lane
        seen = {lane_id}
        while (
            leftmost.left_neighbor is not None
            and leftmost.left_neighbor not in seen
            and lanes[leftmost.left_neighbor].right_neighbor == leftmost.lane_id
        ):
            seen.add(leftmost.left_neighbor)
            leftmost = lanes[leftmost.left_neighbor]
        row = [leftmost.lane_id]
        here = leftmost
        while (
            here.right_neighbor is not None
            and here.right_neighbor not in row
            and lanes[here.right_neighbor].left_neighbor == here.lane_id
        ):
            row.append(here.right_neighbor)
            here = lanes[here.right_neighbor]
        row = [i for i in row if i not in block_of]
        if lane_id not in row:
            row = [lane_id]
        block_id = prefix + row[0]
        members[block_id] = row
        for i in row:
            block_of[i] = block_id
    blocks = []
    for block_id, row in members.items():
        succ = [block_of[s] for i in row for s in lanes[i].successors if s in block_of]
        pred = [block_of[p] for i in row for p in lanes[i].predecessors if p in block_of]
        blocks.append(
            Roadblock(
                roadblock_id=block_id,
                lane_ids=tuple(row),
                successors=tuple(dict.fromkeys(b for b in succ if b != block_id)),
                predecessors=tuple(dict.fromkeys(b for b in pred if b != block_id)),
            )
        )
    return block_of, tuple(blocks)
