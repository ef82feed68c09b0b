"""The sides: one sender and one receiver class per transport (redrive copy-out and in place, pipe
+ pickle) and :data:`SIDES`, the catalogue :func:`~redrive.benchmarks.transport.run_cell` runs them
from.  Peers (ZeroMQ, eCAL, iceoryx2, ``multiprocessing.Queue``) are sides of a catalogue of the
repository's ``benchmarks/transport_peers.py``, which adds them to these."""

from __future__ import annotations

import contextlib
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from redrive.benchmarks.transport.payload import CellConfig, _Payload, _Tally

__all__ = ["CATALOGUE", "DEFAULT_SIDES", "SIDES", "SideSpec", "catalogue_sides"]

_CONNECT_TIMEOUT_S = 20.0


class _Sender(Protocol):
    def wait_connected(self, timeout_s: float) -> None: ...

    def send(self, seq: int, stamp_ns: int) -> None: ...

    def close(self) -> None: ...


class _Receiver(Protocol):
    def recv(self, timeout_s: float) -> bool:
        """Deliver what arrived to the tally's ``consume``; False when nothing came in time."""
        ...

    def close(self) -> None: ...


@dataclass(frozen=True, slots=True, kw_only=True)
class SideSpec:
    """One transport: ``module`` must import for it to run (``package`` is what to install)."""

    name: str
    label: str
    module: str
    package: str
    publisher_first: bool  # the subscriber cannot attach before the publisher exists
    lossy: bool
    in_place: bool
    make_sender: Callable[[CellConfig, Any], _Sender]
    make_receiver: Callable[[CellConfig, Any, _Tally], _Receiver]
    make_shared: Callable[[Any, CellConfig], Any] | None = None  # objects both children inherit
    cleanup: Callable[[CellConfig], None] | None = None  # parent side, after the run


class _NoWait:
    def wait_connected(self, timeout_s: float) -> None:
        return None


# -- redrive ---------------------------------------------------------------------------------------


def _segment_name(cfg: CellConfig) -> str:
    return f"bench.{cfg.endpoint}"


class _RedriveSender(_NoWait):
    def __init__(self, cfg: CellConfig, *, in_place: bool) -> None:
        from redrive.transport import Policy, Writer

        self.payload = _Payload(cfg)
        self.in_place = in_place
        self.size = cfg.size_bytes
        self.src = self.payload.new_source()
        self.writer = Writer(
            _segment_name(cfg),
            capacity_bytes=cfg.size_bytes,
            slots=cfg.slots,
            policy=Policy.LOSSLESS,
        )

    def send(self, seq: int, stamp_ns: int) -> None:
        if self.in_place:
            with self.writer.loan(self.size, stamp_ns=stamp_ns) as out:
                self.payload.fill(out, seq, stamp_ns)
        else:
            self.payload.stamp(self.src, seq, stamp_ns)
            self.writer.publish(self.src, stamp_ns=stamp_ns)

    def close(self) -> None:
        self.writer.close()


class _RedriveReceiver:
    def __init__(self, cfg: CellConfig, tally: _Tally, *, in_place: bool) -> None:
        from redrive.transport import Reader

        self.tally = tally
        self.in_place = in_place
        self.reader = Reader(_segment_name(cfg), timeout_s=_CONNECT_TIMEOUT_S)
        # copy-out into one reused buffer, as a consumer that keeps the data would do: a fresh
        # array per message pays its page faults (p99 ≈ 6.5 ms for 4 MiB here) in the copy
        self.out = np.empty(max(cfg.size_bytes, 1), np.uint8)

    def recv(self, timeout_s: float) -> bool:
        if self.in_place:
            with self.reader.view(timeout_s=timeout_s) as msg:
                if msg is None:
                    return False
                self.tally.consume(msg.payload)
                return True
        got = self.reader.read(timeout_s=timeout_s, out=self.out)
        if got is None:
            return False
        self.tally.consume(got.payload)
        return True

    def close(self) -> None:
        self.reader.close()


def _redrive_cleanup(cfg: CellConfig) -> None:
    # the writer unlinks its segment on close; this is for a writer that died
    from redrive.transport import segment_path

    with contextlib.suppress(FileNotFoundError):
        segment_path(_segment_name(cfg)).unlink()


# -- pipe + pickle: the legacy path of the paper ---------------------------------------------------


class _PipeSender(_NoWait):
    def __init__(self, cfg: CellConfig, shared: Any) -> None:
        self.payload = _Payload(cfg)
        self.src = self.payload.new_source()
        _, self.conn = shared

    def send(self, seq: int, stamp_ns: int) -> None:
        self.payload.stamp(self.src, seq, stamp_ns)
        self.conn.send(self.src)  # pickled and written synchronously

    def close(self) -> None:
        self.conn.close()


class _PipeReceiver:
    def __init__(self, cfg: CellConfig, shared: Any, tally: _Tally) -> None:
        self.conn, _ = shared
        self.tally = tally

    def recv(self, timeout_s: float) -> bool:
        if not self.conn.poll(timeout_s):
            return False
        self.tally.consume(self.conn.recv())
        return True

    def close(self) -> None:
        self.conn.close()


def _pipe_shared(ctx: Any, cfg: CellConfig) -> Any:
    return ctx.Pipe(duplex=False)  # (receiving end, sending end)


SIDES: Mapping[str, SideSpec] = {
    s.name: s
    for s in (
        SideSpec(
            name="redrive-copy", label="redrive copy-out", module="redrive.transport",
            package="redrive", publisher_first=True, lossy=False, in_place=False,
            make_sender=lambda cfg, _sh: _RedriveSender(cfg, in_place=False),
            make_receiver=lambda cfg, _sh, t: _RedriveReceiver(cfg, t, in_place=False),
            cleanup=_redrive_cleanup,
        ),
        SideSpec(
            name="redrive-inplace", label="redrive in place", module="redrive.transport",
            package="redrive", publisher_first=True, lossy=False, in_place=True,
            make_sender=lambda cfg, _sh: _RedriveSender(cfg, in_place=True),
            make_receiver=lambda cfg, _sh, t: _RedriveReceiver(cfg, t, in_place=True),
            cleanup=_redrive_cleanup,
        ),
        SideSpec(
            name="pipe-pickle", label="pipe + pickle", module="multiprocessing",
            package="(standard library)", publisher_first=False, lossy=False, in_place=False,
            make_sender=_PipeSender, make_receiver=_PipeReceiver, make_shared=_pipe_shared,
        ),
    )
}  # fmt: skip
DEFAULT_SIDES = tuple(SIDES)
#: the module whose SIDES the spawned children look a side up in (``python -m benchmarks
#: transport`` passes its own, with the peers added)
CATALOGUE = __name__


def catalogue_sides(catalogue: str = CATALOGUE) -> Mapping[str, SideSpec]:
    """The sides of ``catalogue``, a module with a ``SIDES`` mapping."""
    sides: Mapping[str, SideSpec] = importlib.import_module(catalogue).SIDES
    return sides
