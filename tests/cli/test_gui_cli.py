"""``redrive gui`` without a display says so (Qt would abort the process)."""

from __future__ import annotations

import pytest

from redrive.cli.main import main


def test_gui_without_a_display_is_a_clear_error(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("PySide6")
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(name, raising=False)
    assert main(["gui"]) != 0
    err = capsys.readouterr().err
    assert "no display" in err
    assert "xvfb-run" in err


def test_gui_help_lists_it() -> None:
    with pytest.raises(SystemExit) as exc:
        main(["gui", "--help"])
    assert exc.value.code == 0
