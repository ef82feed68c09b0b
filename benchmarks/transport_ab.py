"""redrive in place against iceoryx2 in place, several redrive trees interleaved (issue 20 item 1).

Each cell of ``redrive bench transport`` (one side, one size, flat out, lossless, 4 slots, two
fresh processes) runs in a fresh interpreter whose ``PYTHONPATH`` is the tree's ``src``; a round
runs, for every size, iceoryx2 and then every tree in turn (the trees' order rotates from round to
round), so each redrive figure has an iceoryx2 figure taken seconds before it. Printed per round
and size: GB/s of each, each tree ÷ that round's iceoryx2, each tree ÷ the first tree; then the
medians over the rounds. ``--perf`` wraps every cell in ``perf stat`` (software events of the
cell's whole process tree, start-up included) and prints them per message sent.

    PYTHONPATH=src python benchmarks/transport_ab.py --tree main=/tmp/main/src \
        --tree noyield=/tmp/noyield/src --sizes 64K,1M,4M --rounds 5 [--perf]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

# a tree with the peers outside its package (catalogue=) runs iceoryx2 from this repository's
# benchmarks/transport_peers.py; an older tree has every side in its own package
_CELL = """
import inspect, json, sys
from redrive.benchmarks.transport.sides import run_cell
kw = {}
if "catalogue" in inspect.signature(run_cell).parameters:
    kw["catalogue"] = "benchmarks.transport_peers"
r = run_cell(sys.argv[1], int(sys.argv[2]), seconds=float(sys.argv[3]), **kw)
print(json.dumps({"gb_per_s": r.gb_per_s, "sent": r.sent, "received": r.received,
                  "lost": r.lost, "corrupt": r.corrupt}))
"""
_EVENTS = "context-switches,cpu-migrations,page-faults,task-clock"


def _size(text: str) -> int:
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}
    text = text.strip().upper()
    return int(text[:-1]) * units[text[-1]] if text[-1] in units else int(text)


def _cell(src: str, side: str, size: int, seconds: float, perf: bool) -> dict[str, float]:
    root = str(Path(__file__).resolve().parents[1])  # benchmarks/ for the peers
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, root])}
    cmd = [sys.executable, "-c", _CELL, side, str(size), str(seconds)]
    with tempfile.NamedTemporaryFile(suffix=".perf", delete=False) as tmp:
        out = tmp.name
    if perf:
        cmd = ["perf", "stat", "-x,", "-e", _EVENTS, "-o", out, "--", *cmd]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    got: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    if perf:
        for line in Path(out).read_text().splitlines():
            parts = line.split(",")
            if len(parts) > 2 and parts[2] in _EVENTS.split(","):
                value = float(parts[0]) if parts[0][:1].isdigit() else float("nan")
                got[parts[2]] = value / max(1, int(got["sent"]))
    Path(out).unlink(missing_ok=True)
    return got


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--tree", action="append", required=True, help="NAME=PATH/TO/src")
    ap.add_argument("--sizes", default="64K,1M,4M")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--perf", action="store_true", help="perf stat every cell")
    args = ap.parse_args()
    trees = [tuple(t.split("=", 1)) for t in args.tree]
    sizes = [_size(s) for s in args.sizes.split(",")]
    ratios: dict[tuple[int, str], list[float]] = {}
    vs_first: dict[tuple[int, str], list[float]] = {}
    counters: dict[tuple[int, str], list[dict[str, float]]] = {}
    for rnd in range(args.rounds):
        order = trees[rnd % len(trees) :] + trees[: rnd % len(trees)]
        load = os.getloadavg()[0]
        for size in sizes:
            ice = _cell(trees[0][1], "iceoryx2", size, args.seconds, args.perf)
            counters.setdefault((size, "iceoryx2"), []).append(ice)
            got = {
                name: _cell(src, "redrive-inplace", size, args.seconds, args.perf)
                for name, src in order
            }
            for name, _src in trees:
                r = got[name]
                if r["lost"] or r["corrupt"]:
                    print(f"  !! {name} lost {r['lost']} corrupt {r['corrupt']}")
                ratios.setdefault((size, name), []).append(r["gb_per_s"] / ice["gb_per_s"])
                vs_first.setdefault((size, name), []).append(
                    r["gb_per_s"] / got[trees[0][0]]["gb_per_s"]
                )
                counters.setdefault((size, name), []).append(r)
            cells = "  ".join(
                f"{n} {got[n]['gb_per_s']:6.2f} ({got[n]['gb_per_s'] / ice['gb_per_s']:.2f}x)"
                for n, _ in trees
            )
            print(
                f"round {rnd + 1} load {load:4.1f} {size >> 10:5d} KiB  iceoryx2 "
                f"{ice['gb_per_s']:6.2f} GB/s  {cells}",
                flush=True,
            )
    print("\nmedians over rounds (redrive in place / iceoryx2; / the first tree):")
    for size in sizes:
        for name, _src in trees:
            r, f = ratios[(size, name)], vs_first[(size, name)]
            print(
                f"{size >> 10:5d} KiB {name:>10}: {statistics.median(r):.2f}x "
                f"(min {min(r):.2f}, max {max(r):.2f}); vs {trees[0][0]} "
                f"{statistics.median(f):.2f}x  [{' '.join(f'{x:.2f}' for x in r)}]"
            )
    if args.perf:
        print("\nperf stat per message sent (medians over rounds; whole process trees):")
        for (size, name), rows in counters.items():
            keys = [k for k in _EVENTS.split(",") if k in rows[0]]
            text = "  ".join(f"{k} {statistics.median(row[k] for row in rows):.3f}" for k in keys)
            print(f"{size >> 10:5d} KiB {name:>10}: {text}")


if __name__ == "__main__":
    main()
