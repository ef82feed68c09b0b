"""Screenshots of the GUI's panels for the README and docs/gui.md (run under Xvfb).

    make screenshots                      # = make demo, then this script under xvfb-run
    xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python scripts/gui_screenshots.py \\
        --log .demo/urban.mcap --run .demo/run --out docs/images

The run should be evaluated (``make demo`` does) so the timeline has its failure bookmarks and
the plots a per-frame metric.  The window uses a throw-away settings file, not the user's.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from redrive.gui.app import ensure_app
from redrive.gui.mainwindow import MainWindow
from redrive.gui.resim import ResimPanel
from redrive.gui.topics import TopicPicker
from redrive.io import open_log


def pump(app: QtWidgets.QApplication, until: Callable[[], bool], timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not until():
        if time.monotonic() > deadline:
            msg = "timed out waiting for the GUI"
            raise TimeoutError(msg)
        app.processEvents()
        time.sleep(0.01)


def settle(app: QtWidgets.QApplication, seconds: float = 0.5) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        app.processEvents()
        time.sleep(0.01)


def show_frame(app: QtWidgets.QApplication, win: MainWindow, index: int) -> None:
    win.go_to(index)
    pump(app, lambda: win.scene is not None and win.scene.index == index and not win.loader.busy)
    settle(app)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", type=Path, default=Path(".demo/urban.mcap"))
    parser.add_argument("--run", type=Path, default=Path(".demo/run"))
    parser.add_argument("--out", type=Path, default=Path("docs/images"))
    parser.add_argument("--frame", type=int, default=62, help="the frame to show")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    app = ensure_app()
    ini = Path(tempfile.mkdtemp()) / "gui.ini"
    win = MainWindow(settings=QtCore.QSettings(str(ini), QtCore.QSettings.Format.IniFormat))
    win.resize(1600, 1000)
    win.show()
    win.open_path(args.run)
    pump(app, lambda: win.scene is not None)
    pump(app, lambda: win.loader.session is not None and win.loader.session.indexed)
    pump(app, lambda: win._series is not None)  # the plots' series are read after the index
    show_frame(app, win, args.frame)
    win.grab_window().save(str(args.out / "gui-main.png"))
    win.camera.grab().save(str(args.out / "gui-camera.png"))
    win.docks["Timeline"].grab().save(str(args.out / "gui-timeline.png"))
    win.plots.grab().save(str(args.out / "gui-plots.png"))
    win.planview.convert_button.setChecked(True)
    pump(app, lambda: win.scene is not None and win.scene.raster is not None)
    settle(app)
    win.grab_window().save(str(args.out / "gui-2d.png"))

    with open_log(args.log) as log:
        topics, duration_s = dict(log.topics), (log.end_ns - log.start_ns) / 1e9
    picker = TopicPicker.for_log(topics, duration_s=duration_s, parent=win)
    picker.show_topics(["/lidar_top", "/camera_front/image_raw"])
    picker.resize(900, 480)
    picker.show()
    settle(app)
    picker.grab().save(str(args.out / "gui-topics.png"))
    picker.close()

    panel = ResimPanel()
    panel.resize(1300, 760)
    panel.load_log(args.log)
    panel.set_algorithm("perception", "cluster-detector")
    if not panel.open_run(args.run):
        return 1
    panel.show()
    panel.set_frame(args.frame)
    settle(app, 1.0)
    panel.grab().save(str(args.out / "gui-resim.png"))
    panel.close()
    win.close()
    for name in sorted(p.name for p in args.out.glob("gui-*.png")):
        sys.stdout.write(f"{args.out / name}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
