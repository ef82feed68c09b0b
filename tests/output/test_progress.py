"""The one progress display: counts, rate and ETA on a terminal; nothing when piped or quiet."""

from __future__ import annotations

import io

import pytest
from rich.console import Console

from redrive.output import progress as progress_mod
from redrive.output.progress import ProgressBar, fmt_s


def test_counts_rate_and_eta_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    clock = [100.0]
    monkeypatch.setattr(progress_mod.time, "perf_counter", lambda: clock[0])
    out = io.StringIO()
    console = Console(file=out, force_terminal=True, width=120, color_system=None)
    with ProgressBar("converting", total=100, unit="messages", console=console) as bar:
        clock[0] += 2.0
        bar.update(50)
        fields = bar.progress.tasks[0].fields
        assert fields["count"] == "50/100 messages"
        assert fields["rate"] == "25.0 messages/s"
        assert fields["eta"] == "2s"
        bar.print("a note above the bar")
        bar.progress.refresh()
    text = out.getvalue()
    assert "converting" in text
    assert "50/100 messages" in text
    assert "a note above the bar" in text


def test_silent_when_not_a_terminal_or_quiet() -> None:
    out = io.StringIO()
    piped = Console(file=out)  # a StringIO is no terminal
    with ProgressBar("run", unit="frames", console=piped) as bar:
        assert not bar.enabled
        bar.update(10, total=20)
        bar.print("never shown")
    assert out.getvalue() == ""
    forced = Console(file=out, force_terminal=True)
    with ProgressBar("run", console=forced, quiet=True) as bar:
        assert not bar.enabled
    assert out.getvalue() == ""


def test_fmt_s() -> None:
    assert (fmt_s(None), fmt_s(42.4), fmt_s(185)) == ("?", "42s", "3m05s")
