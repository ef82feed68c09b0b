"""``scripts/gui_screenshots.py`` (the README's images) runs and writes every panel's image."""

from __future__ import annotations

import importlib.util
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyqtgraph")

from PIL import Image

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "gui_screenshots.py"


def test_screenshot_script(demo_log: Path, demo_run: Path, tmp_path: Path) -> None:
    from redrive.cli.main import main as redrive_main

    run = tmp_path / "run"
    shutil.copytree(demo_run, run)
    assert redrive_main(["evaluate", str(run), "--metric", "clear_mot"]) == 0
    spec = importlib.util.spec_from_file_location("gui_screenshots", SCRIPT)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["gui_screenshots"] = module
    spec.loader.exec_module(module)
    out = tmp_path / "images"
    assert module.main(["--log", str(demo_log), "--run", str(run), "--out", str(out)]) == 0
    names = {p.name for p in out.glob("*.png")}
    assert {"gui-main.png", "gui-2d.png", "gui-resim.png", "gui-topics.png"} <= names
    for name in names:
        pixels = np.asarray(Image.open(out / name).convert("RGB"))
        assert pixels.shape[0] > 30
        assert pixels.shape[1] > 100
        assert pixels.std() > 10, f"{name} is (nearly) one colour"
