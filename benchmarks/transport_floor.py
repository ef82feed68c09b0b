"""How far redrive's per-message Python is from the least a Python process must execute per message.

Three publish → receive paths, each in one process (publisher and subscriber alternating, so
neither ever waits and no spin or sleep is counted), with a 64-byte payload (the copy and the
subscriber's touch are the same on every path and left out):

* ``redrive``: ``Writer.loan`` + commit, ``Reader.view`` + release (lossless, one reader);
* ``iceoryx2``: what the benchmark's iceoryx2 side calls: ``loan_slice_uninit``, the payload as a
  numpy array, ``assume_init().send()``, ``notify()``; ``receive()``, the payload array,
  ``delete()`` (its protocol runs in compiled Rust);
* ``floor``: redrive's protocol stripped to what Python cannot avoid: the shared words it must
  store and load through a ``memoryview`` (slot claim, header, ``write_seq``, the reader's pin,
  the sequence checks before and after, ``read_seq``), the two fences per side its memory-ordering
  argument needs (``redrive.transport._fence``), one clock reading per side and the payload as a
  numpy view — no error checks, no policies, no counters, no wake-up bookkeeping, no objects;
* ``none``: empty steps, the cost of the measuring loop itself (to subtract).

Prints instructions per message of each side when run under callgrind (``--callgrind``: the
instrumentation is switched on around each side's calls only, through a tiny C library built
with ``cc``; run valgrind with ``--instr-atstart=no --collect-atstart=no``), else thread CPU ns
per message (noisy on a shared machine)::

    valgrind --tool=callgrind --instr-atstart=no --collect-atstart=no \\
        --callgrind-out-file=/tmp/cg.%p \\
        python benchmarks/transport_floor.py --path redrive --side pub --callgrind
    python benchmarks/transport_floor.py --path floor        # CPU ns per message, both sides

Run once per path and side under callgrind (``--side`` chooses which side is instrumented); the
instructions per message are the callgrind total / ``--count``.
"""

from __future__ import annotations

import argparse
import ctypes
import mmap
import subprocess
import tempfile
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

SIZE = 64
Step = Callable[[int], Any]

# instrumentation is switched on once (switching it discards valgrind's translations: slow);
# the events of the instrumented side are collected by toggling collection around its calls
_CALLGRIND_C = """#include <valgrind/callgrind.h>
void start(void) { CALLGRIND_START_INSTRUMENTATION; }
void stop(void) { CALLGRIND_STOP_INSTRUMENTATION; }
void toggle(void) { CALLGRIND_TOGGLE_COLLECT; }
"""


def _redrive() -> tuple[Step, Step, Callable[[], None]]:
    from redrive.transport import Policy, Reader, Writer

    name = f"floor.{uuid.uuid4().hex[:10]}"
    writer = Writer(name, capacity_bytes=SIZE, slots=4, policy=Policy.LOSSLESS, max_readers=1)
    reader = Reader(name)

    def pub(i: int) -> None:
        with writer.loan(SIZE, stamp_ns=i) as out:
            out[0] = 1

    def sub(i: int) -> None:
        with reader.view(timeout_s=1.0) as msg:
            assert msg is not None
            msg.payload[0]

    def close() -> None:
        reader.close()
        writer.close()

    return pub, sub, close


def _iceoryx2() -> tuple[Step, Step, Callable[[], None]]:
    from benchmarks.transport_peers import _as_u8, _iox2_service
    from redrive.benchmarks.transport.sides import CellConfig

    cfg = CellConfig(
        side="iceoryx2",
        size_bytes=SIZE,
        seconds=0.0,
        paced_hz=None,
        verify=False,
        endpoint=f"floor-{uuid.uuid4().hex[:10]}",
    )
    iox2, node, service, event = _iox2_service(cfg)
    publisher = (
        service.publisher_builder()
        .initial_max_slice_len(SIZE)
        .allocation_strategy(iox2.AllocationStrategy.Static)
        .create()
    )
    subscriber = service.subscriber_builder().create()
    notifier = event.notifier_builder().create()
    listener = event.listener_builder().create()
    publisher.update_connections()
    alive = [node, service]  # held until close

    def pub(i: int) -> None:
        sample = publisher.loan_slice_uninit(SIZE)
        _as_u8(sample.payload_ptr, SIZE)[0] = 1
        sample.assume_init().send()
        notifier.notify()

    def sub(i: int) -> None:
        sample = subscriber.receive()
        _as_u8(sample.payload_ptr, sample.payload().len())[0]
        sample.delete()

    def close() -> None:
        listener.try_wait()  # the notifications of the run
        for obj in (listener, notifier, subscriber, publisher):
            obj.delete()
        alive.clear()

    return pub, sub, close


def _floor() -> tuple[Step, Step, Callable[[], None]]:
    from redrive.transport._fence import fence

    n_slots, page = 4, mmap.PAGESIZE
    mm = mmap.mmap(-1, page * (1 + 2 * n_slots))
    w = memoryview(mm).cast("B").cast("q")
    write_seq, order, pin, read_seq, waiting, writer_waiting = 0, 8, 16, 17, 18, 19
    slot_word = [(page + 2 * page * s) // 8 for s in range(n_slots)]  # seq_begin, seq_end, header
    payload = [np.frombuffer(mm, np.uint8, SIZE, page * (2 + 2 * s)) for s in range(n_slots)]
    w[pin] = -1
    state = {"seq": 0, "slot": 0}

    def pub(i: int) -> None:
        seq = state["seq"] + 1
        slot = seq % n_slots  # the slot is the one after the last: no choice to make
        b = slot_word[slot]
        w[b] = seq  # seq_begin
        fence()
        if w[pin] == slot:  # the one reader pins it: not in this loop
            raise AssertionError
        out = payload[slot][:SIZE]
        out[0] = 1  # the user's fill
        w[b + 2] = i  # stamp
        w[b + 3] = time.time_ns()  # publish time
        w[b + 4] = SIZE
        w[b + 1] = seq  # seq_end
        w[order + seq % n_slots] = slot
        w[write_seq] = seq
        state["seq"] = seq
        fence()
        if w[waiting]:  # would write the reader's eventfd
            raise AssertionError

    def sub(i: int) -> None:
        want = w[read_seq] + 1
        if w[write_seq] < want:
            raise AssertionError
        slot = w[order + want % n_slots]
        w[pin] = slot
        fence()
        b = slot_word[slot]
        if w[b] != want or w[b + 1] != want:
            raise AssertionError
        view = payload[slot][: w[b + 4]]
        view[0]
        stamp, lag = w[b + 2], time.time_ns() - w[b + 3]
        if w[b] != want or w[b + 1] != want or stamp < 0 or lag < 0:  # the torn-read re-check
            raise AssertionError
        w[pin] = -1
        w[read_seq] = want
        fence()
        if w[writer_waiting]:  # would write the writer's eventfd
            raise AssertionError

    def close() -> None:
        w.release()
        payload.clear()
        mm.close()

    return pub, sub, close


def _none() -> tuple[Step, Step, Callable[[], None]]:
    """Empty steps: what the measuring loop itself costs (subtract it from the others)."""

    def step(i: int) -> None:
        return None

    return step, step, lambda: None


PATHS = {"redrive": _redrive, "iceoryx2": _iceoryx2, "floor": _floor, "none": _none}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--path", choices=tuple(PATHS), default="floor")
    ap.add_argument("--side", choices=("pub", "sub"), default="pub", help="instrumented side")
    ap.add_argument("--count", type=int, default=2000)
    ap.add_argument("--callgrind", action="store_true", help="running under callgrind")
    args = ap.parse_args()
    lib = None
    if args.callgrind:
        where = Path(tempfile.mkdtemp(prefix="redrive-floor-"))
        (where / "t.c").write_text(_CALLGRIND_C)
        so = where / "libt.so"
        subprocess.run(
            ["cc", "-O2", "-shared", "-fPIC", "-o", str(so), str(where / "t.c")], check=True
        )
        lib = ctypes.CDLL(str(so))
    pub, sub, close = PATHS[args.path]()
    for i in range(200):  # warm-up: every slot written and read, code paths taken
        pub(i)
        sub(i)
    if lib is not None:
        first, second = (pub, sub) if args.side == "pub" else (sub, pub)
        if args.side == "sub":
            pub(0)  # one message in flight
        lib.start()
        for i in range(args.count):
            lib.toggle()
            first(i)
            lib.toggle()
            second(i)
        lib.stop()
        if args.side == "sub":
            sub(-1)
        close()
        return
    cpu = {"pub": 0, "sub": 0}
    clock = time.thread_time_ns
    for i in range(args.count):
        t0 = clock()
        pub(i)
        t1 = clock()
        sub(i)
        cpu["pub"] += t1 - t0
        cpu["sub"] += clock() - t1
    close()
    per = {k: v / args.count for k, v in cpu.items()}
    print(f"{args.path}\tpub_cpu_ns\t{per['pub']:.0f}\tsub_cpu_ns\t{per['sub']:.0f}")


if __name__ == "__main__":
    main()
