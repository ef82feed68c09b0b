"""Shared fixtures: the real third-party data in ../shared/data (skipped cleanly when absent)."""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest

_ROOT = Path(__file__).resolve().parents[1]


def _shared_data_dir() -> Path | None:
    env = os.environ.get("REDRIVE_SHARED_DATA")
    candidates = [Path(env)] if env else []
    candidates += [_ROOT.parent / "shared" / "data", _ROOT / ".." / "shared" / "data"]
    for cand in candidates:
        if (cand / "README.md").is_file():
            return cand.resolve()
    return None


SHARED_DATA = _shared_data_dir()

# A shell starts a background job (`make test &`, nohup, a CI agent's script) with SIGINT ignored;
# Python then leaves it ignored (it puts its KeyboardInterrupt handler only over SIG_DFL) and every
# child inherits the ignored signal through exec.  The tests of Ctrl-C need it delivered: a
# `redrive run` sent SIGINT went on forever and its test timed out, and a batch that interrupts
# its own driver ran to the end.  A handler (unlike SIG_IGN) is reset to SIG_DFL in a child.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``; the test is skipped when it is not there."""
    if SHARED_DATA is None:
        pytest.skip("../shared/data is not present")
    return SHARED_DATA


@pytest.fixture(scope="session")
def demo_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """10 s of the built-in ``urban`` scenario (seed 7, as ``make demo`` but shorter), made once per
    test session with the real simulator and MCAP writer."""
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize

    out = tmp_path_factory.mktemp("demo") / "urban.mcap"
    synthesize(load_scenario("urban"), out, duration_s=10.0, seed=7)
    return out


@pytest.fixture(scope="session")
def cut_in_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """2 s of the built-in ``cut_in`` scenario (its own seed), made once per test session; the
    tests that take it only read it (the engine's reference-pipeline runs, a closed-loop metric's
    open-loop run)."""
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize

    out = tmp_path_factory.mktemp("cut_in") / "cut_in.mcap"
    synthesize(load_scenario("cut_in"), out, duration_s=2.0)
    return out


@pytest.fixture(scope="session")
def demo_run(demo_log: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference pipeline (clusters → tracker → planner → controller) over :func:`demo_log`,
    written as ``redrive run`` writes it."""
    from redrive.cli.main import main

    out = tmp_path_factory.mktemp("demo_run") / "run"
    assert main(["run", str(demo_log), "--out", str(out), "--no-progress"]) == 0
    return out


@pytest.fixture(autouse=True)
def _signal_handlers_restored() -> Iterator[None]:
    """A command run in the test process must give back the SIGINT/SIGTERM handlers it set,
    however it ends: a `redrive live` refused at start once left its Ctrl-C handler behind, and
    a later test's Ctrl-C then did nothing."""
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    yield
    changed = [sig.name for sig, handler in before.items() if signal.getsignal(sig) is not handler]
    for sig, handler in before.items():
        signal.signal(sig, handler)
    assert not changed, f"the test left its {' and '.join(changed)} handler set"
