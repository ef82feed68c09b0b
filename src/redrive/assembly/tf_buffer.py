"""A tf buffer: static and dynamic transforms in, ``dst_from_src`` 4×4 matrices out.

Frames form a tree (each child has one parent, as in tf2).  ``lookup(dst, src, stamp_ns)`` walks
from both frames to their common ancestor and composes the edges.  A dynamic edge is interpolated
between the two samples around ``stamp_ns`` — translation linearly, rotation by slerp; a stamp
up to ``tolerance_ns`` before the first / after the last sample uses that sample, anything
further raises :class:`TransformLookupError`.  Memory is bounded: each dynamic edge keeps the
samples of the last ``window_ns`` (default 10 s) before its newest one.  Leading slashes of frame
names (ROS 1 ``/base_link``) are ignored.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from redrive.errors import LogError
from redrive.geometry.quaternion import quaternion_slerp, rotation_matrix_from_quaternion
from redrive.types import Transform

__all__ = ["TransformBuffer", "TransformLookupError"]

Matrix = npt.NDArray[np.float64]


class TransformLookupError(LogError, LookupError):
    """No transform between two frames at the asked time (no path, or stamp out of range)."""


def _frame(name: str) -> str:
    return name.lstrip("/")


def _matrix(translation: npt.NDArray[np.float64], rotation_xyzw: npt.ArrayLike) -> Matrix:
    out = np.eye(4)
    out[:3, :3] = rotation_matrix_from_quaternion(rotation_xyzw)
    out[:3, 3] = translation
    return out


@dataclass(slots=True)
class _Edge:
    """``parent_from_child`` of one child frame: a static transform or time-sorted samples."""

    parent: str
    static: Transform | None = None
    stamps_ns: list[int] = field(default_factory=list)
    samples: list[Transform] = field(default_factory=list)


class TransformBuffer:
    """Answers ``dst_from_src`` queries through the frame tree.

    Args:
        window_ns: how much history each dynamic edge keeps before its newest sample.
        tolerance_ns: how far a lookup may lie outside an edge's samples (the nearest is used).
    """

    def __init__(self, *, window_ns: int = 10_000_000_000, tolerance_ns: int = 50_000_000) -> None:
        if window_ns <= 0 or tolerance_ns < 0:
            msg = f"window_ns must be > 0 and tolerance_ns >= 0, got {window_ns}, {tolerance_ns}"
            raise ValueError(msg)
        self.window_ns = window_ns
        self.tolerance_ns = tolerance_ns
        self._edges: dict[str, _Edge] = {}
        # Lookups along static edges only, by (dst, src): they hold until the tree or a static
        # transform changes, which bumps the version (a dynamic sample does not).
        self._version = 0
        self._static_paths: dict[tuple[str, str], tuple[int, Matrix]] = {}

    @property
    def frames(self) -> frozenset[str]:
        """Every frame named so far (parents and children)."""
        return frozenset(self._edges) | {e.parent for e in self._edges.values()}

    def add(self, transform: Transform, *, static: bool | None = None) -> None:
        """Add one transform; ``static`` defaults to ``transform.stamp_ns == 0``.

        A child given a new parent is re-attached (its old samples are dropped).
        """
        is_static = transform.stamp_ns == 0 if static is None else static
        child, parent = _frame(transform.child_frame), _frame(transform.parent_frame)
        if child == parent:
            msg = f"transform from frame {child!r} to itself"
            raise ValueError(msg)
        edge = self._edges.get(child)
        if edge is None or edge.parent != parent:
            edge = _Edge(parent=parent)
            self._edges[child] = edge
            self._version += 1
        if is_static:
            edge.static = transform
            edge.stamps_ns.clear()
            edge.samples.clear()
            self._version += 1
            return
        if edge.static is not None:
            edge.static = None
            self._version += 1
        stamp = transform.stamp_ns
        if edge.stamps_ns and stamp <= edge.stamps_ns[-1]:
            i = bisect.bisect_left(edge.stamps_ns, stamp)
            if i < len(edge.stamps_ns) and edge.stamps_ns[i] == stamp:
                edge.samples[i] = transform
                return
            edge.stamps_ns.insert(i, stamp)
            edge.samples.insert(i, transform)
        else:
            edge.stamps_ns.append(stamp)
            edge.samples.append(transform)
        cut = bisect.bisect_left(edge.stamps_ns, edge.stamps_ns[-1] - self.window_ns)
        if cut:
            del edge.stamps_ns[:cut]
            del edge.samples[:cut]

    def add_all(self, transforms: Iterable[Transform], *, static: bool | None = None) -> None:
        """Add many transforms (a decoded tf message)."""
        for transform in transforms:
            self.add(transform, static=static)

    def _chain(self, frame: str) -> list[str]:
        """``frame`` and its ancestors up to the root."""
        chain = [frame]
        while frame in self._edges:
            frame = self._edges[frame].parent
            if frame in chain:
                msg = f"the frame tree has a loop through {frame!r}"
                raise TransformLookupError(msg)
            chain.append(frame)
        return chain

    def _parent_from_child(self, child: str, stamp_ns: int) -> Matrix:
        edge = self._edges[child]
        if edge.static is not None:
            return _matrix(edge.static.translation, edge.static.rotation)
        stamps = edge.stamps_ns
        i = bisect.bisect_left(stamps, stamp_ns)
        if i < len(stamps) and stamps[i] == stamp_ns:
            s = edge.samples[i]
            return _matrix(s.translation, s.rotation)
        if i == 0 or i == len(stamps):
            nearest = 0 if i == 0 else len(stamps) - 1
            if abs(stamps[nearest] - stamp_ns) > self.tolerance_ns:
                msg = (
                    f"{edge.parent!r} → {child!r} is known from {stamps[0]} to {stamps[-1]} ns; "
                    f"{stamp_ns} ns lies outside by more than {self.tolerance_ns} ns "
                    "(look up a time inside the log's tf range, or raise tolerance_ns)"
                )
                raise TransformLookupError(msg)
            s = edge.samples[nearest]
            return _matrix(s.translation, s.rotation)
        before, after = edge.samples[i - 1], edge.samples[i]
        fraction = (stamp_ns - stamps[i - 1]) / (stamps[i] - stamps[i - 1])
        translation = before.translation + fraction * (after.translation - before.translation)
        rotation = quaternion_slerp(before.rotation, after.rotation, fraction)
        return _matrix(translation, rotation)

    def lookup(self, dst: str, src: str, stamp_ns: int) -> Matrix:
        """The 4×4 ``dst_from_src`` at ``stamp_ns``: maps points in ``src`` into ``dst``.

        Raises:
            TransformLookupError: the frames are not connected, or a dynamic edge on the path has
                no sample within ``tolerance_ns`` of ``stamp_ns``.
        """
        dst, src = _frame(dst), _frame(src)
        if dst == src:
            return np.eye(4)
        cached = self._static_paths.get((dst, src))
        if cached is not None and cached[0] == self._version:
            return cached[1].copy()
        src_chain, dst_chain = self._chain(src), self._chain(dst)
        common = next((f for f in src_chain if f in set(dst_chain)), None)
        if common is None:
            known = ", ".join(sorted(self.frames)) or "none"
            msg = (
                f"no transform path between {dst!r} and {src!r} (known frames: {known}); "
                "check the tf / tf_static topics are read"
            )
            raise TransformLookupError(msg)
        common_from_src = np.eye(4)
        for child in src_chain[: src_chain.index(common)]:
            common_from_src = self._parent_from_child(child, stamp_ns) @ common_from_src
        common_from_dst = np.eye(4)
        for child in dst_chain[: dst_chain.index(common)]:
            common_from_dst = self._parent_from_child(child, stamp_ns) @ common_from_dst
        dst_from_common = np.eye(4)
        rotation_t = common_from_dst[:3, :3].T
        dst_from_common[:3, :3] = rotation_t
        dst_from_common[:3, 3] = -rotation_t @ common_from_dst[:3, 3]
        dst_from_src = dst_from_common @ common_from_src
        path = src_chain[: src_chain.index(common)] + dst_chain[: dst_chain.index(common)]
        if all(self._edges[child].static is not None for child in path):
            self._static_paths[(dst, src)] = (self._version, dst_from_src.copy())
        return dst_from_src
