"""The peers of ``redrive bench transport`` (``python -m benchmarks transport``): tiny runs of every
installed peer side deliver exactly what was sent (every byte compared), and the command runs.
No timing is asserted."""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from benchmarks.cli import main
from benchmarks.transport_peers import CATALOGUE, PACKAGE_SIDES, SIDES
from redrive.benchmarks.transport import run_cell, side_available

SIZE = 64 << 10
IOX2_ROOT = Path("/tmp/iceoryx2")  # iceoryx2's default root for node and service files
PEERS = [s for s in SIDES if s not in PACKAGE_SIDES]


@pytest.fixture(scope="module", autouse=True)
def _no_iceoryx2_leftovers() -> Iterator[None]:
    """iceoryx2 keeps a global management segment in /dev/shm (and /tmp/iceoryx2) after its last
    node is gone; remove what these tests created when no iceoryx2 node is alive any more."""
    shm = Path("/dev/shm")
    before = set(shm.glob("iox2_*"))
    root_existed = IOX2_ROOT.exists()
    yield
    if any((IOX2_ROOT / "nodes").glob("*")):
        return  # someone's iceoryx2 node is alive: leave its files alone
    for path in set(shm.glob("iox2_*")) - before:
        path.unlink(missing_ok=True)
    if not root_existed:
        shutil.rmtree(IOX2_ROOT, ignore_errors=True)


def _needs(side: str) -> None:
    if not side_available(side, CATALOGUE):
        pytest.skip(f"{SIDES[side].module} is not installed ({SIDES[side].package})")


@pytest.mark.parametrize("side", PEERS)
def test_every_byte_arrives(side: str) -> None:
    _needs(side)
    r = run_cell(side, SIZE, seconds=0.15, verify=True, catalogue=CATALOGUE)
    assert r.mode == "flat"
    assert r.sent > 0
    assert r.corrupt == 0  # every received payload equals the one sent, byte for byte
    assert 0 < r.received <= r.sent
    if not SIDES[side].lossy:
        assert r.received == r.sent
        assert r.out_of_order == 0
    if r.received >= 2:
        assert r.msgs_per_s > 0
        assert r.gb_per_s == pytest.approx(r.msgs_per_s * SIZE / 1e9)
    else:  # a loaded machine got one message through the 0.15 s window: a rate needs two
        assert math.isnan(r.msgs_per_s)
    assert 0 < r.latency_p50_ms <= r.latency_p99_ms <= r.latency_max_ms


def test_the_command_runs_a_peer(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["transport", "--sizes", "16K", "--seconds", "0.1", "--sides", "mp-queue,pipe-pickle"]
    assert main([*argv, "--no-paced", "--no-memcpy", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [c["status"] for c in out["cells"]] == ["ok", "ok"]
    assert [c["flat"]["corrupt"] for c in out["cells"]] == [0, 0]
