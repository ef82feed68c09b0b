"""The local executor's forkserver preload (:mod:`redrive.batch.preload`): what it imports and
warms, that it leaves the server without threads, and that a cell forked from a server whose
preload was partial (an optional module missing) runs and gives the same outputs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

from redrive.batch import preload

from .outputs import batch, batch_outputs


def test_missing_modules_kernels_and_caches_are_skipped() -> None:
    assert preload.preload(("redrive.engine.run", "redrive_no_such_module")) == [
        "redrive.engine.run"
    ]
    warmed = preload.warm(
        (
            ("redrive_no_such_module", "Anything"),
            ("redrive.algorithms.reference.planner", "NoSuchClass"),
            ("redrive.algorithms.reference.planner", "IdmPlanner"),
        )
    )
    assert warmed == ["IdmPlanner"]
    assert preload.fill((("redrive_no_such_module", "f", ()), ("json", "dumps", (1,)))) == 1


def test_the_server_has_one_thread_and_its_kernels_loaded_after_the_preload() -> None:
    """What the forkserver holds when it forks: only its main thread (numba's threading layer
    not started), the reference algorithms warmed and the kernels in their dispatchers."""
    code = textwrap.dedent(
        """
        import json, threading
        import redrive.batch.preload as p
        from numba.np.ufunc import parallel
        from redrive.algorithms.reference._plan_kernels import leaders_on_path
        print(json.dumps({
            "threads": [t.name for t in threading.enumerate()],
            "numba_threads": parallel._is_initialized,
            "warm": p.warm(()),
            "overloads": len(leaders_on_path.overloads),
        }))
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300
    )
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["threads"] == ["MainThread"]
    assert seen["numba_threads"] is False
    assert seen["overloads"] >= 1


def test_a_cell_runs_the_same_from_a_partly_preloaded_server(
    logs: list[Path], pipelines: list[Path], tmp_path: Path
) -> None:
    """pandas (in the preload, not a dependency of redrive) hidden from the whole batch: the
    server's import of it fails, it goes on, and the cells run as from a full preload."""
    shim = tmp_path / "shim"
    (shim / "pandas").mkdir(parents=True)
    marker = tmp_path / "pandas-imports"
    (shim / "pandas" / "__init__.py").write_text(
        "import os\n"
        f"with open({str(marker)!r}, 'a') as f:\n"
        "    f.write(f'{os.getpid()}\\n')\n"
        "raise ImportError('pandas hidden by the test')\n",
        encoding="utf-8",
    )
    args = [str(logs[0]), "--pipeline", str(pipelines[1]), "--workers", "1", "--no-progress"]
    partial = tmp_path / "partial"
    code = (
        "from redrive.cli.main import main; "
        f"raise SystemExit(main(['batch', *{args!r}, '--out', {str(partial)!r}]))"
    )
    # PYTHONPATH, not sys.path: the forkserver of Python 3.11 does not take its parent's sys.path
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, (str(shim), env.get("PYTHONPATH"))))
    subprocess.run([sys.executable, "-c", code], check=True, timeout=600, env=env)
    assert marker.is_file()  # the server (at least) tried pandas and went on without it
    full = tmp_path / "full"
    assert batch(full, *args[:-1]) == 0
    got = batch_outputs(partial)
    assert len(got) == 1
    assert got == batch_outputs(full)
