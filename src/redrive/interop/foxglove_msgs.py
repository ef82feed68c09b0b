"""Data-model values and shapes → Foxglove messages (``foxglove.messages``, protobuf-encoded).

=========================  ===========================  =========================================
value                      message                      notes
=========================  ===========================  =========================================
ShapeSet                   ``foxglove.SceneUpdate``     first a deletion of all the topic showed,
                                                        then one entity per box (a cube, its
                                                        velocity as an arrow), line, label
                                                        and triangle list (a filled surface)
tuple[Transform, ...]      ``foxglove.FrameTransforms`` one FrameTransform each, stamped with the
                                                        message's stamp (static ones too)
PointCloud                 ``foxglove.PointCloud``      x, y, z float32, then intensity as
                                                        float32 when the cloud has it
Image                      ``foxglove.CompressedImage`` JPEG (colour, quality 90) or PNG (mono,
                                                        16-bit, with alpha); float images are not
                                                        written
=========================  ===========================  =========================================

Needs ``foxglove-sdk`` (the ``foxglove`` extra); importing this module without it raises
ImportError, which callers turn into a message that says how to install it.
"""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np
from foxglove import messages as fm

from redrive.interop.shapes import (
    BoxShape,
    Color,
    LabelShape,
    LineShape,
    ShapeSet,
    TriangleShape,
    arrow_yaw_pitch,
    yaw_pitch_quaternion,
    yaw_quaternion,
)
from redrive.types import Image, PointCloud, Transform

__all__ = [
    "compressed_image",
    "frame_transforms",
    "point_cloud",
    "scene_update",
    "timestamp",
]

_MIN_ARROW_MPS = 0.1


def timestamp(stamp_ns: int) -> fm.Timestamp:
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return fm.Timestamp(sec, nsec)


def _color(c: Color) -> fm.Color:
    return fm.Color(r=c[0], g=c[1], b=c[2], a=c[3])


def _pose(position: Sequence[float], quaternion: Sequence[float] = (0.0, 0.0, 0.0, 1.0)) -> fm.Pose:
    return fm.Pose(
        position=fm.Vector3(x=float(position[0]), y=float(position[1]), z=float(position[2])),
        orientation=fm.Quaternion(
            x=quaternion[0], y=quaternion[1], z=quaternion[2], w=quaternion[3]
        ),
    )


def _box_entity(box: BoxShape, *, stamp: fm.Timestamp, frame_id: str) -> fm.SceneEntity:
    cube = fm.CubePrimitive(
        pose=_pose(box.center, yaw_quaternion(box.yaw_rad)),
        size=fm.Vector3(x=box.size[0], y=box.size[1], z=box.size[2]),
        color=_color(box.color),
    )
    arrows = []
    if box.velocity is not None and np.hypot(box.velocity[0], box.velocity[1]) > _MIN_ARROW_MPS:
        length, yaw, pitch = arrow_yaw_pitch(box.velocity)
        arrows.append(
            fm.ArrowPrimitive(
                pose=_pose(box.center, yaw_pitch_quaternion(yaw, pitch)),
                shaft_length=length,
                shaft_diameter=0.15,
                head_length=0.5,
                head_diameter=0.4,
                color=_color((box.color[0], box.color[1], box.color[2], 1.0)),
            )
        )
    return fm.SceneEntity(
        timestamp=stamp, frame_id=frame_id, id=box.id, cubes=[cube], arrows=arrows
    )


def _line_entity(line: LineShape, *, stamp: fm.Timestamp, frame_id: str) -> fm.SceneEntity:
    primitive = fm.LinePrimitive(
        type=fm.LinePrimitiveLineType.LineStrip,
        thickness=line.width_m,
        scale_invariant=False,
        points=[fm.Point3(x=p[0], y=p[1], z=p[2]) for p in line.points],
        color=_color(line.color),
        pose=_pose((0.0, 0.0, 0.0)),
    )
    return fm.SceneEntity(timestamp=stamp, frame_id=frame_id, id=line.id, lines=[primitive])


def _triangle_entity(
    surface: TriangleShape, *, stamp: fm.Timestamp, frame_id: str
) -> fm.SceneEntity:
    primitive = fm.TriangleListPrimitive(
        pose=_pose((0.0, 0.0, 0.0)),
        points=[fm.Point3(x=p[0], y=p[1], z=p[2]) for p in surface.points],
        color=_color(surface.color),
    )
    return fm.SceneEntity(timestamp=stamp, frame_id=frame_id, id=surface.id, triangles=[primitive])


def _label_entity(label: LabelShape, *, stamp: fm.Timestamp, frame_id: str) -> fm.SceneEntity:
    text = fm.TextPrimitive(
        pose=_pose(label.position),
        billboard=True,
        font_size=label.size_m,
        scale_invariant=False,
        color=_color(label.color),
        text=label.text,
    )
    return fm.SceneEntity(timestamp=stamp, frame_id=frame_id, id=label.id, texts=[text])


def scene_update(shapes: ShapeSet) -> fm.SceneUpdate:
    """The SceneUpdate that replaces what a topic showed with ``shapes``."""
    stamp = timestamp(shapes.stamp_ns)
    frame = shapes.frame_id
    entities = [_box_entity(b, stamp=stamp, frame_id=frame) for b in shapes.boxes]
    entities += [_line_entity(ln, stamp=stamp, frame_id=frame) for ln in shapes.lines]
    entities += [_label_entity(lb, stamp=stamp, frame_id=frame) for lb in shapes.labels]
    entities += [_triangle_entity(t, stamp=stamp, frame_id=frame) for t in shapes.triangles]
    deletion = fm.SceneEntityDeletion(timestamp=stamp, type=fm.SceneEntityDeletionType.All)
    return fm.SceneUpdate(deletions=[deletion], entities=entities)


def frame_transforms(transforms: Sequence[Transform], *, stamp_ns: int) -> fm.FrameTransforms:
    """``transforms`` (parent_from_child) as one FrameTransforms stamped ``stamp_ns``."""
    stamp = timestamp(stamp_ns)
    return fm.FrameTransforms(
        transforms=[
            fm.FrameTransform(
                timestamp=stamp,
                parent_frame_id=t.parent_frame,
                child_frame_id=t.child_frame,
                translation=fm.Vector3(
                    x=float(t.translation[0]), y=float(t.translation[1]), z=float(t.translation[2])
                ),
                rotation=fm.Quaternion(
                    x=float(t.rotation[0]),
                    y=float(t.rotation[1]),
                    z=float(t.rotation[2]),
                    w=float(t.rotation[3]),
                ),
            )
            for t in transforms
        ]
    )


def point_cloud(cloud: PointCloud, *, frame_id: str, stamp_ns: int) -> fm.PointCloud:
    """x, y, z (and intensity when the cloud has it) as float32, packed point by point."""
    names = ["x", "y", "z"]
    columns = [cloud.xyz[:, 0], cloud.xyz[:, 1], cloud.xyz[:, 2]]
    intensity = cloud.channels.get("intensity")
    if intensity is not None:
        names.append("intensity")
        columns.append(intensity)
    packed = np.empty((cloud.xyz.shape[0], len(names)), dtype="<f4")
    for i, column in enumerate(columns):
        packed[:, i] = column
    f32 = fm.PackedElementFieldNumericType.Float32
    return fm.PointCloud(
        timestamp=timestamp(stamp_ns),
        frame_id=frame_id,
        pose=_pose((0.0, 0.0, 0.0)),
        point_stride=4 * len(names),
        fields=[fm.PackedElementField(name=n, offset=4 * i, type=f32) for i, n in enumerate(names)],
        data=packed.tobytes(),
    )


def compressed_image(image: Image, *, frame_id: str, stamp_ns: int) -> fm.CompressedImage | None:
    """A colour image as JPEG (quality 90), a mono or 16-bit one as PNG; None for a float
    image (32FC1 depth), which neither format holds."""
    from PIL import Image as PilImage

    pixels = np.ascontiguousarray(image.pixels)
    if pixels.dtype not in (np.uint8, np.uint16):
        return None
    encoding = image.encoding.lower()
    if encoding == "bgr8":
        pixels = np.ascontiguousarray(pixels[..., ::-1])
    elif encoding == "bgra8":
        pixels = np.ascontiguousarray(pixels[..., [2, 1, 0, 3]])
    out = io.BytesIO()
    if pixels.ndim == 3 and pixels.dtype == np.uint8 and pixels.shape[2] == 3:
        PilImage.fromarray(pixels, "RGB").save(out, format="JPEG", quality=90)
        fmt = "jpeg"
    else:
        if pixels.ndim == 3 and pixels.shape[2] == 1:
            pixels = pixels[..., 0]
        PilImage.fromarray(pixels).save(out, format="PNG", compress_level=1)
        fmt = "png"
    return fm.CompressedImage(
        timestamp=timestamp(stamp_ns), frame_id=frame_id, data=out.getvalue(), format=fmt
    )
