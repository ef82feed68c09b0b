"""A `redrive synth` killed with SIGKILL mid-write leaves a file recovery reads up to its last
complete chunk: `info` reports the cut (exit 5), `run` replays the intact part, `repair` writes
an MCAP the mcap library reads without error."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from redrive.cli.main import main
from redrive.io import open_log

_ENV = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2] / "src")}
_CHUNKS = 3


def test_synth_killed_mid_write_is_recovered(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "redrive", "synth", "urban", "--duration", "120", "-o", "out.mcap"],
        cwd=tmp_path,
        env=_ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        part: Path | None = None
        deadline = time.monotonic() + 240  # a bound against a hang, not a measurement
        while time.monotonic() < deadline and proc.poll() is None:
            parts = list(tmp_path.glob(".out.mcap.*.part"))
            # each chunk of the synth log is ~1 MB compressed: wait for a few
            if parts and parts[0].stat().st_size > _CHUNKS * 1_000_000:
                part = parts[0]
                break
            time.sleep(0.05)
        assert part is not None, "synth wrote no partial file"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
    assert not (tmp_path / "out.mcap").exists()  # the target appears only when complete
    size = part.stat().st_size

    with open_log(part, strict=False) as log:
        messages = [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages()]
        report = log.damage_report  # type: ignore[attr-defined]
    assert len(messages) > 100
    # only the end is lost: the summary, and the chunk being written if it was cut
    assert report
    assert all(d.start_byte is None or d.stop_byte == size for d in report)

    assert main(["info", str(part)]) == 5
    out = capsys.readouterr()
    assert "damaged" in out.out
    assert "Traceback" not in out.out + out.err

    fixed = tmp_path / "fixed.mcap"
    assert main(["repair", str(part), "-o", str(fixed)]) == 5
    with fixed.open("rb") as fh:
        reader = make_reader(fh)
        stats = reader.get_summary().statistics  # type: ignore[union-attr]
        assert stats is not None
        got = [(c.topic, m.log_time, bytes(m.data)) for _, c, m in reader.iter_messages()]
    assert stats.message_count == len(messages)
    assert sorted(got) == sorted(messages)
    capsys.readouterr()

    args = ["run", str(part), "--out", str(tmp_path / "run"), "--perception", "noisy-oracle"]
    assert main([*args, "--no-progress"]) == 0
    out = capsys.readouterr()
    assert "the log is damaged" in out.out
    assert "Traceback" not in out.out + out.err
