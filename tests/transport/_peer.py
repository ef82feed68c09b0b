"""A peer process for the transport tests: ``python _peer.py ROLE NAME [ARGS]``.

Runs under the venv's Python or under /usr/bin/python3 (with ``PYTHONPATH`` = redrive's src):
it imports only redrive.transport (numpy + stdlib). Prints ``READY`` when set up, then one line
per event, and exits 0 when done.

Roles:
    write NAME COUNT SEED POLICY [PERIOD_S]   publish COUNT messages of random size, content a
                                              function of (SEED, seq); prints a final ``DONE``
    hang NAME                                 create the stream, publish one message, then open
                                              a loan, half fill it and sleep (to be killed)
    read NAME COUNT POLICY                    read COUNT messages; print ``seq crc`` per message
"""

from __future__ import annotations

import sys
import time
import zlib

import numpy as np

from redrive.transport import Policy, Reader, Writer


def payload(seed: int, seq: int) -> np.ndarray:
    rng = np.random.default_rng([seed, seq])
    size = int(rng.integers(0, 200_000))
    return rng.integers(0, 256, size, dtype=np.uint8)


def main(argv: list[str]) -> int:
    role, name = argv[0], argv[1]
    if role == "write":
        count, seed, policy = int(argv[2]), int(argv[3]), Policy[argv[4]]
        period = float(argv[5]) if len(argv) > 5 else 0.0
        with Writer(name, capacity_bytes=200_000, slots=6, policy=policy) as w:
            print("READY", flush=True)
            sys.stdin.readline()  # go
            for seq in range(1, count + 1):
                w.publish(payload(seed, seq), stamp_ns=seq, timeout_s=30.0)
                if period:
                    time.sleep(period)
            print("DONE", flush=True)
            sys.stdin.readline()  # stay until told (readers may still read)
        return 0
    if role == "hang":
        w = Writer(name, capacity_bytes=1 << 20, slots=4, policy=Policy.KEEP_LATEST)
        w.publish(np.full(1000, 1, np.uint8), stamp_ns=1)
        with w.loan(1 << 20, stamp_ns=2) as buf:
            buf[: 1 << 19] = 2
            print("READY", flush=True)
            time.sleep(600)
        return 1
    if role == "read":
        count, policy = int(argv[2]), Policy[argv[3]]
        with Reader(name, timeout_s=10.0, policy=policy) as r:
            print("READY", flush=True)
            for _ in range(count):
                msg = r.read(timeout_s=10.0)
                if msg is None:
                    print("TIMEOUT", flush=True)
                    return 1
                print(msg.seq, zlib.crc32(msg.payload), flush=True)
        return 0
    print(f"unknown role {role}", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
