"""Make the pictures of docs/synthetic.md: a camera frame and a LiDAR bird's-eye view of `urban`.

Run from the repository root (≈30 s):

    .venv/bin/python docs/figures/make_sim_figures.py

It simulates the built-in ``urban`` scenario with ``redrive.sim.synth`` into a temporary MCAP,
reads it back through ``redrive.io`` (the same path as any recorded log: ``open_log`` →
``iter_frames``) and draws the frame closest to ``--at`` seconds: the camera image as it is, and
the LiDAR sweep from above in base_link with the ground-truth boxes (green: visible, with their
LiDAR point count; grey: occluded or out of sight).
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from redrive.assembly.frames import iter_frames
from redrive.geometry import transform_points
from redrive.io import open_log
from redrive.sim.rig import rig_from_mapping
from redrive.sim.scenario import load_scenario
from redrive.sim.synth import synthesize
from redrive.types import Frame, PointCloud
from redrive.types import Image as ImageData

HERE = Path(__file__).resolve().parent
BEV_RANGE_M = 40.0  # half-width of the bird's-eye view
BEV_PX_PER_M = 12


def _bev(frame: Frame, base_from_lidar: np.ndarray) -> Image.Image:
    size = int(2 * BEV_RANGE_M * BEV_PX_PER_M)
    canvas = Image.new("RGB", (size, size), (12, 14, 20))
    draw = ImageDraw.Draw(canvas)

    def px(x_m: np.ndarray, y_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # x forward = up, y left = left
        return (size / 2 - y_m * BEV_PX_PER_M), (size / 2 - x_m * BEV_PX_PER_M)

    for r in range(10, int(BEV_RANGE_M) + 1, 10):  # range rings every 10 m
        c = size / 2
        rr = r * BEV_PX_PER_M
        draw.ellipse((c - rr, c - rr, c + rr, c + rr), outline=(40, 44, 56))
    lidar = frame.sensors["lidar_top"].data
    assert isinstance(lidar, PointCloud)
    pts = transform_points(base_from_lidar, lidar.xyz.astype(np.float64))
    u, v = px(pts[:, 0], pts[:, 1])
    keep = (u >= 0) & (u < size) & (v >= 0) & (v < size)
    height = np.clip((pts[keep, 2] + 0.2) / 3.0, 0.0, 1.0)
    colors = np.stack(
        [80 + 175 * height, 120 + 100 * (1 - height), 255 - 155 * height], axis=1
    ).astype(np.uint8)
    pixels = np.asarray(canvas).copy()
    pixels[v[keep].astype(int), u[keep].astype(int)] = colors
    canvas = Image.fromarray(pixels)
    draw = ImageDraw.Draw(canvas)
    for obj in frame.ground_truth or ():
        cx, cy = obj.box.center[0], obj.box.center[1]
        length, width = obj.box.size[0], obj.box.size[1]
        c, s = math.cos(obj.box.yaw_rad), math.sin(obj.box.yaw_rad)
        corners = [
            (cx + c * dx - s * dy, cy + s * dx + c * dy)
            for dx, dy in (
                (length / 2, width / 2),
                (length / 2, -width / 2),
                (-length / 2, -width / 2),
                (-length / 2, width / 2),
            )
        ]
        poly = [tuple(float(a) for a in px(np.array(x), np.array(y))) for x, y in corners]
        color = (60, 220, 90) if obj.visible else (110, 110, 110)
        draw.polygon(poly, outline=color, width=2)
        if obj.visible:
            tx, ty = px(np.array(cx), np.array(cy))
            draw.text((float(tx) + 6, float(ty) - 6), str(obj.num_lidar_points), fill=color)
    ex, ey = px(np.array([0.0, 4.6]), np.array([0.0, 0.0]))  # the ego: rear axle → front
    draw.line((float(ex[0]), float(ey[0]), float(ex[1]), float(ey[1])), fill=(255, 80, 60), width=4)
    return canvas


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--at", type=float, default=27.0, help="seconds into the scenario")
    parser.add_argument("--out", type=Path, default=HERE)
    args = parser.parse_args()
    scenario = load_scenario("urban")
    rig = rig_from_mapping(scenario.rig, source=scenario.source)
    with tempfile.TemporaryDirectory() as tmp:
        log_path = Path(tmp) / "urban.mcap"
        synthesize(scenario, log_path, duration_s=args.at + 0.5)
        with open_log(log_path) as log:
            want_ns = log.start_ns + round(args.at * 1e9)
            frame = next(iter_frames(log, start_ns=want_ns - 60_000_000), None)
        assert frame is not None, "no frame at the requested time"
        camera = frame.sensors["camera_front_image_raw"].data
        assert isinstance(camera, ImageData)
        Image.fromarray(np.asarray(camera.pixels)).save(args.out / "urban_camera.png")
        _bev(frame, rig["lidar_top"].base_from_sensor()).save(args.out / "urban_lidar_bev.png")
    print(f"wrote {args.out / 'urban_camera.png'} and {args.out / 'urban_lidar_bev.png'}")


if __name__ == "__main__":
    main()
