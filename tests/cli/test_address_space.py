"""Under an address-space limit the command line trims what its libraries reserve (issue 37):
pyarrow's 1 GiB mimalloc arena, a malloc arena per thread, an OpenBLAS thread per core — so
``redrive run`` works under 1 GiB instead of ending in ArrowMemoryError or a crash."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from redrive.cli._address_space import fit_to_address_space

_SRC = Path(__file__).resolve().parents[2] / "src"
_GIB = 1 << 30


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (_GIB, _GIB))


def _python(code: str, *, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        preexec_fn=_limited,
        env={**os.environ, "PYTHONPATH": str(_SRC), **(env or {})},
    )


def test_nothing_changes_without_a_limit() -> None:
    if resource.getrlimit(resource.RLIMIT_AS)[0] != resource.RLIM_INFINITY:
        pytest.skip("this test process itself runs under an address-space limit")
    assert fit_to_address_space() == {}


def test_under_a_limit_arrow_uses_the_system_pool() -> None:
    code = (
        "import os\n"
        "from redrive.cli._address_space import fit_to_address_space\n"
        "print(sorted(fit_to_address_space()))\n"
        "import pyarrow as pa\n"
        "pa.array(list(range(1000)))\n"
        "print(pa.default_memory_pool().backend_name)\n"
    )
    clean = {k: v for k, v in os.environ.items() if k not in ("ARROW_DEFAULT_MEMORY_POOL",)}
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        preexec_fn=_limited,
        env={**clean, "PYTHONPATH": str(_SRC)},
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.split("\n")
    assert "ARROW_DEFAULT_MEMORY_POOL" in lines[0]
    assert lines[1] == "system"


def test_a_variable_the_user_set_is_kept() -> None:
    code = (
        "from redrive.cli._address_space import fit_to_address_space\n"
        "print(sorted(fit_to_address_space()))\n"
    )
    done = _python(code, env={"OPENBLAS_NUM_THREADS": "4"})
    assert done.returncode == 0, done.stderr
    assert "OPENBLAS_NUM_THREADS" not in done.stdout


def test_redrive_run_under_1_gib(tmp_path: Path) -> None:
    """Without the trimming this ended in `ArrowMemoryError: malloc of size 64 failed` (exit 1)
    every time on the development machine, or a SIGSEGV."""
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize

    log = tmp_path / "urban.mcap"
    synthesize(load_scenario("urban"), log, duration_s=0.3, seed=7)
    code = (
        "import sys\nfrom redrive.cli.main import main\n"
        f"sys.exit(main(['run', {str(log)!r}, '--frames', '0:3', '--out', "
        f"{str(tmp_path / 'run')!r}, '--no-progress']))\n"
    )
    done = _python(code)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "results:" in done.stdout
