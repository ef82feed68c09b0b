"""Write docs/foxglove_layout.json: the Foxglove layout that shows an exported run.

Built with foxglove-sdk's own layout model (``foxglove.layouts``), so the file is what the app
imports (Layout → Import from file).  A 3D panel following ``base_link`` with the log's own
LiDAR cloud (``sensor_msgs/PointCloud2``, which Foxglove draws; the ``/foxglove/…`` copies of
``export --sensor-copies`` are not needed), ground truth, the tracker's boxes, the planner's
path, the ego and its ghost, and the bookmarks; the front camera (the log's
``sensor_msgs/Image``) beside it; the transform tree below.  Topics of algorithms with other
names appear in the 3D panel's topic list, off until switched on.

    python scripts/foxglove_layout.py [-o docs/foxglove_layout.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import foxglove.layouts as fl

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = ROOT / "docs" / "foxglove_layout.json"

SCENE_TOPICS = (
    "/redrive/ground_truth",
    "/redrive/detections/tracker",
    "/redrive/paths/planner",
    "/redrive/ego",
    "/redrive/ego_logged",
    "/redrive/bookmarks",
    "/redrive/map",
    "/redrive/traffic_lights",
)


def layout() -> fl.Layout:
    topics: dict[str, fl.BaseRendererTopicSettings] = {
        topic: fl.BaseRendererSceneUpdateTopicSettings(visible=True) for topic in SCENE_TOPICS
    }
    topics["/lidar_top"] = fl.BaseRendererPointCloudTopicSettings(
        visible=True, point_size=2.0, color_mode="colormap", color_field="intensity"
    )
    three_d = fl.ThreeDeePanel(
        title="redrive scene",
        config=fl.ThreeDeeConfig(
            follow_tf="base_link", follow_mode="follow-heading", fixed_frame="map", topics=topics
        ),
    )
    camera = fl.ImagePanel(
        title="front camera",
        config=fl.ImageConfig(image_mode=fl.ImageModeConfig(image_topic="/camera_front/image_raw")),
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="column",
            items=[
                fl.SplitItem(
                    proportion=3,
                    content=fl.SplitContainer(
                        direction="row",
                        items=[
                            fl.SplitItem(proportion=2, content=three_d),
                            fl.SplitItem(proportion=1, content=camera),
                        ],
                    ),
                ),
                fl.SplitItem(proportion=1, content=fl.TransformTreePanel(title="transforms")),
            ],
        )
    )


def layout_json() -> str:
    """The layout as the committed file holds it (indented, one trailing newline)."""
    return json.dumps(json.loads(layout().to_json()), indent=2) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, default=LAYOUT)
    args = parser.parse_args()
    args.output.write_text(layout_json(), encoding="utf-8")
    print(args.output)


if __name__ == "__main__":
    main()
