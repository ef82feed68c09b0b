"""``python -m benchmarks transport``: ``redrive bench transport`` with the peers added (ZeroMQ,
eCAL, iceoryx2, ``multiprocessing.Queue``: :mod:`benchmarks.transport_peers`)."""

from __future__ import annotations

from typing import Any

from redrive.benchmarks.cli.transport import DESCRIPTION, add_transport_parser

__all__ = ["add_peers_parser"]

_DESCRIPTION = (
    DESCRIPTION.split("(Against ZeroMQ")[0]
    + """Here also the peers: multiprocessing.Queue, ZeroMQ ipc with copy=False, eCAL shared memory
(default settings: lossy, no back-pressure) and iceoryx2 (in place); sides whose package is missing
show "not installed". Target (issue 20), when iceoryx2 runs: redrive in place >= 1.0x iceoryx2 at
64 KiB, 1 and 4 MiB.
"""
)

_EPILOG = """\
examples:
  python -m benchmarks transport                            every side, 64K 1M 4M 16M, 2 s a run
  python -m benchmarks transport --sizes 4M --sides redrive-inplace,iceoryx2 --seconds 5
  python -m benchmarks transport --sizes 64K,1M,4M --sides redrive-inplace,iceoryx2 --repeat 3
"""


def add_peers_parser(sub: Any) -> None:
    add_transport_parser(
        sub,
        catalogue="benchmarks.transport_peers",
        help="redrive bench transport with ZeroMQ, eCAL, iceoryx2 and multiprocessing.Queue",
        description=_DESCRIPTION,
        epilog=_EPILOG,
    )
