"""Interoperation with the viewers robotics people already use (L5: reads logs and runs).

* :mod:`.mcap_export` — ``redrive export RUN --format mcap``: the log and the run's results in
  one MCAP with Foxglove's scene schemas (``foxglove.SceneUpdate``, ``FrameTransforms``; with
  ``--sensor-copies`` also ``PointCloud``, ``CompressedImage``) and
  ``visualization_msgs/MarkerArray`` for RViz, next to the log's own ROS channels (an MCAP log's
  chunks copied as they are by :mod:`.mcap_splice`);
* :mod:`.serve` — ``redrive serve RUN|LOG``: the same stream live on Foxglove's WebSocket
  protocol, paced at the log's rate, with the app's play / pause / seek / speed.
* :mod:`.live_view` — ``redrive live … --foxglove``: a live session's topics as they arrive and
  each frame's results, on the same channels (the CLI feeds it from the session's streams).

Both need ``foxglove-sdk`` (``pip install 'redrive[foxglove]'``); the modules of this package
import it, so import them only where it is needed (:func:`require_foxglove` says how to get it).
"""

from __future__ import annotations

from redrive.errors import ConfigError

__all__ = ["require_foxglove"]


def require_foxglove() -> None:
    """Raise ConfigError saying how to install ``foxglove-sdk`` when it is missing."""
    try:
        import foxglove  # noqa: F401
    except ImportError as err:
        msg = (
            "this needs the Foxglove SDK, which is not installed; install it with "
            "`pip install 'redrive[foxglove]'` (or `pip install foxglove-sdk`)"
        )
        raise ConfigError(msg) from err
