"""The HTML report renders in headless Chromium, from disk, with its plots (no network).

Skipped when ``/usr/bin/chromium`` is absent (``make test`` installs Debian's ``chromium``).
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from redrive.evaluation.plots import DETECTION_COLORS, GROUND_TRUTH_COLOR
from redrive.evaluation.report import write_report
from tests.evaluation.test_report import build_run, evaluate

CHROMIUM = Path("/usr/bin/chromium")
WIDTH_PX, HEIGHT_PX = 1280, 2800  # the timelines sit below the PR curves at 110 dpi

pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists(), reason="/usr/bin/chromium is not installed (apt-get install chromium)"
)


def _screenshot(page: Path, png: Path, profile: Path, *, height_px: int) -> np.ndarray:
    cmd = [
        str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
        "--no-first-run", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", f"--user-data-dir={profile}", f"--screenshot={png}",
        f"--window-size={WIDTH_PX},{height_px}", page.resolve().as_uri(),
    ]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert png.is_file(), f"chromium wrote no screenshot (exit {done.returncode}):\n{done.stderr}"
    with Image.open(png) as im:
        assert im.size == (WIDTH_PX, height_px)
        return np.asarray(im.convert("RGB"), dtype=np.int16)


def _near(rgb: np.ndarray, color: str, *, tol: int = 12) -> int:
    """Pixels within ``tol`` per channel of ``color`` (#rrggbb)."""
    want = np.array([int(color[i : i + 2], 16) for i in (1, 3, 5)], dtype=np.int16)
    return int(np.all(np.abs(rgb - want) <= tol, axis=-1).sum())


@pytest.fixture(scope="module")
def page(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The report of the 4-frame run, written once for both tests."""
    run_dir = build_run(tmp_path_factory.mktemp("chromium") / "run")
    evaluate(run_dir)
    return write_report(run_dir).html


@pytest.fixture(scope="module")
def whole_page(page: Path) -> np.ndarray:
    """One screenshot of the whole page (6000 px tall) for both tests: the layout does not depend
    on the window height (no viewport units), so its top rows are what a shorter window shows
    (checked: the same pixels but for the scrollbar at the right edge)."""
    return _screenshot(page, page.with_name("shot.png"), page.parent / "profile", height_px=6000)


def test_report_renders_its_plots(page: Path, whole_page: np.ndarray, tmp_path: Path) -> None:
    rgb = whole_page[:HEIGHT_PX]
    # not blank: many colours, not all one (each colour packed into one int: np.unique over
    # rows of 3 sorts 3.6 M rows lexicographically, ~50x the CPU time for the same count)
    flat = rgb.reshape(-1, 3).astype(np.int32)
    assert len(np.unique(flat[:, 0] << 16 | flat[:, 1] << 8 | flat[:, 2])) > 200
    # the plots are drawn: lines of the first two series colours of matplotlib's cycle
    # (PR curves and the tp timeline in #1f77b4, the "missed" timeline in #ff7f0e)
    assert _near(rgb, "#1f77b4") > 300
    assert _near(rgb, "#ff7f0e") > 40  # a short flat line (frames 0-2), antialiased at 110 dpi
    # control: the same page without its images has none of these colours
    bare = page.with_name("bare.html")
    bare.write_text(re.sub(r"<img [^>]*>", "", page.read_text(encoding="utf-8")), encoding="utf-8")
    rgb = _screenshot(bare, tmp_path / "bare.png", tmp_path / "profile", height_px=HEIGHT_PX)
    assert _near(rgb, "#1f77b4") == 0
    assert _near(rgb, "#ff7f0e") == 0


def test_birds_eye_snapshots_render(whole_page: np.ndarray) -> None:
    """The whole page (6000 px tall) shows the snapshots: ground-truth green and the first
    detector's red boxes."""
    assert _near(whole_page, GROUND_TRUTH_COLOR) > 100
    assert _near(whole_page, DETECTION_COLORS[0]) > 60
