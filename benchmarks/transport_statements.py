"""Instructions of single statements on the transport's per-message paths, under callgrind.

Each statement runs ``--count`` times in a loop; callgrind collects only between two
``CALLGRIND_TOGGLE_COLLECT`` requests around it (a tiny C library built with ``cc``), so the
count is the statement plus one toggle call; ``empty`` is that call alone — subtract it::

    for s in empty fence fence_with_order w_get w_set pack5 pack9 unpack7 time_ns message; do
      PYTHONPATH=src valgrind --tool=callgrind --instr-atstart=no --collect-atstart=no \\
        --callgrind-out-file=/tmp/st.$s python benchmarks/transport_statements.py $s
      grep -E '^(summary|totals):' /tmp/st.$s | tail -1   # ÷ --count, less empty's
    done

``fence`` is :data:`redrive.transport._fence.fence` as loaded (on x86-64 with GCC's libatomic:
the C function called without its order), ``fence_with_order`` the same function called with
``memory_order_seq_cst`` (what every CPU did before, and what any other still does).
"""

from __future__ import annotations

import argparse
import ctypes
import functools
import mmap
import struct
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from redrive.transport import _fence
from redrive.transport.stream import new_message

_C = """#include <valgrind/callgrind.h>
void start(void) { CALLGRIND_START_INSTRUMENTATION; }
void stop(void) { CALLGRIND_STOP_INSTRUMENTATION; }
void toggle(void) { CALLGRIND_TOGGLE_COLLECT; }
"""

STATEMENTS = {
    "empty": "pass",
    "fence": "fence()",
    "fence_with_order": "fence_with_order()",
    "w_get": "w[3]",
    "w_set": "w[3] = 5",
    "pack5": "S5.pack_into(mm, 8, 1, 2, 3, 4, 5)",
    "pack9": "S9.pack_into(mm, 8, 1, 2, 3, 4, 5, 6, 7, 8, 9)",
    "unpack7": "S7.unpack_from(mm, 8)",
    "time_ns": "time_ns()",
    "message": "m = new_message(1, 2, 3, 0, b'', arr, 0); del m",
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("statement", choices=tuple(STATEMENTS))
    ap.add_argument("--count", type=int, default=1000)
    args = ap.parse_args()
    where = Path(tempfile.mkdtemp(prefix="redrive-statements-"))
    (where / "t.c").write_text(_C)
    subprocess.run(
        ["cc", "-O2", "-shared", "-fPIC", "-o", str(where / "libt.so"), str(where / "t.c")],
        check=True,
    )
    lib = ctypes.CDLL(str(where / "libt.so"))
    mm = mmap.mmap(-1, mmap.PAGESIZE)
    func: Any = _fence.fence.func if isinstance(_fence.fence, functools.partial) else _fence.fence
    names = {
        "toggle": lib.toggle,
        "fence": _fence.fence,
        "fence_with_order": functools.partial(func, 5),
        "w": memoryview(mm).cast("B").cast("q"),
        "mm": mm,
        "S5": struct.Struct("5q"),
        "S9": struct.Struct("9q"),
        "S7": struct.Struct("7q"),
        "time_ns": time.time_ns,
        "new_message": new_message,
        "arr": np.zeros(4, np.uint8),
    }
    body = STATEMENTS[args.statement]
    source = f"def run(n):\n for _ in range(n):\n  toggle()\n  {body}\n  toggle()\n"
    exec(compile(source, "statement", "exec"), names)  # our own fixed statements
    run = names["run"]
    run(50)  # warm-up: specialised bytecode, allocator pools
    lib.start()
    run(args.count)
    lib.stop()
    names["w"].release()


if __name__ == "__main__":
    main()
