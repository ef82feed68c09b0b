"""``python -m benchmarks gui``: how fast the main window plays a log and opens a big one, against
pyqtgraph's own ceiling measured in the same run (issue 7).

The logs are written by redrive's own :class:`~redrive.io.mcap.writer.McapWriter` (ROS 2 CDR, zstd
chunks, as ``redrive synth`` writes them), one frame every 100 ms (10 Hz):

=============================  ==========================================  ========================
topic                          type                                        what
=============================  ==========================================  ========================
``/lidar_top``                 ``sensor_msgs/msg/PointCloud2``             ``points`` (120,000)
                                                                           x, y, z + intensity; a
                                                                           64-beam sweep of
                                                                           ``benchmarks.synth_log``
                                                                           (ground and walls
                                                                           10–60 m)
``/camera_front/image_raw``    ``sensor_msgs/msg/Image``                   1280 × 720 rgb8
``/camera_front/camera_info``  ``sensor_msgs/msg/CameraInfo``              fx = fy = 900 px
``/ground_truth/objects``      ``redrive_msgs/msg/GroundTruthObjectArray`` ``boxes`` (50) moving
                                                                           cars in base_link
``/ground_truth/ego_state``    ``nav_msgs/msg/Odometry``                   the ego, 10 m/s
``/tf``, ``/tf_static``        ``tf2_msgs/msg/TFMessage``                  map → base_link;
                                                                           base_link → LiDAR and
                                                                           camera (so the camera
                                                                           is calibrated and the
                                                                           window projects boxes
                                                                           and splats points)
=============================  ==========================================  ========================

A playback log of ``frames`` (100) frames and, unless skipped, a "1 GB" log of the same frames
repeated until the file is about ``big_bytes``; both are cached in a directory by their
parameters, so a rerun does not write them again.

Measures, each in a fresh :class:`~redrive.gui.mainwindow.MainWindow` of ``window_size``
(1600 × 1000), driven by a ``QApplication.processEvents`` loop (blocking for events, woken at
least every 10 ms; no sleeps):

- **flat out** (3D, then 2D after "Convert 2D Planview"): each ``frame_shown`` asks for the next
  frame (``go_to(i + 1)``, wrapping to 0 at the end), for ``seconds``.  The frame rate is the
  number of *distinct frames the planview painted* per second (a scene handed to the views but
  replaced before a paint does not count); frames handed to the views per second are reported too.
- **timer 8×**: the window's own playback (Replay at 8×: 80 log frames/s wanted, the timer skips
  ticks while a frame is on its way); frames painted per second, ticks skipped, and how fast the
  log advanced.
- **ceilings** (the same-run baselines): a bare top-level ``GLViewWidget`` with one
  ``GLScatterPlotItem`` (same camera, point size and GL options as the planview) fed the window's
  own scenes (same points and colours), ``setData`` then wait for the paint, in a loop, at the
  planview's size; a bare ``ImageItem`` in a ``ViewBox`` fed the window's 2D rasters at the 2D
  view's size; the same fed the 1280 × 720 camera images at the camera view's size.  The window's
  frame rate is reported as a fraction of its ceiling.
- **open → first frame** on the big log: wall time from ``open_path`` to the first
  ``frame_shown`` and to the planview's first paint of it (median of ``open_repeats`` fresh
  windows; the page cache is warm: the log was just written or read).  Baseline: one full read
  of the log (``for m in open_log(p).messages(): pass``).

Where the time goes (per frame, from wrappers installed on the window's objects: the window's code
is not changed): the loader thread's ``LogSession.frame`` (read + decode + assemble) and the rest
of its request (``build_scene``); the GUI thread's hand-over of the scene to the views
(``show_scene`` and friends), the planview's and the camera's paint, and the top-level window's
updates (every dirty widget painted, then the window composed through GL and flushed); the CPU
time of the GUI thread and of the process, and the machine's busy share (``/proc/stat``).
"""

from __future__ import annotations

from benchmarks.gui.logs import BenchLog, bench_log, write_bench_log
from benchmarks.gui.logs import default_cache as default_cache
from benchmarks.gui.result import (
    TARGET_FPS_2D,
    TARGET_FPS_3D,
    TARGET_OPEN_S,
    CeilingResult,
    GuiBenchResult,
    OpenResult,
    PlaybackResult,
)
from benchmarks.gui.run import bench_gui

__all__ = [
    "TARGET_FPS_2D",
    "TARGET_FPS_3D",
    "TARGET_OPEN_S",
    "BenchLog",
    "CeilingResult",
    "GuiBenchResult",
    "OpenResult",
    "PlaybackResult",
    "bench_gui",
    "bench_log",
    "write_bench_log",
]
