"""``sensor_msgs/msg/Image`` and ``sensor_msgs/msg/CompressedImage`` → :class:`~redrive.types.Image`.

Raw images honour ``step`` (row padding is cut off) and ``is_bigendian`` (16-bit and float
pixels are byte-swapped to native order).  Compressed images (JPEG, PNG) are decoded with Pillow
into ``rgb8`` (colour; an alpha channel is dropped), ``mono8`` or ``mono16`` (grey).
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.io.base import LogMessage
from redrive.io.ros.decoders._common import header_stamp_ns, raw_is_immutable, unsupported
from redrive.io.ros.decoders.base import Decoded, DecodedKind, Deserialize
from redrive.types import IMAGE_ENCODINGS, Image, SensorType

__all__ = ["CompressedImageDecoder", "ImageDecoder", "pixels_from_buffer"]


def pixels_from_buffer(
    data: npt.NDArray[np.uint8] | bytes,
    encoding: str,
    *,
    height: int,
    width: int,
    step: int,
    is_bigendian: bool,
) -> npt.NDArray[Any]:
    """The (H, W[, C]) pixel array of raw image bytes; a view when rows are not padded.

    Raises:
        ValueError: unknown encoding, or ``data`` / ``step`` too small for the image.
    """
    if encoding not in IMAGE_ENCODINGS:
        msg = f"image encoding {encoding!r} is not supported (supported: {sorted(IMAGE_ENCODINGS)})"
        raise ValueError(msg)
    scalar, channels = IMAGE_ENCODINGS[encoding]
    dtype = np.dtype(scalar).newbyteorder(">" if is_bigendian else "<")
    row_bytes = width * channels * dtype.itemsize
    if step < row_bytes:
        msg = f"step {step} is smaller than width × pixel size = {row_bytes}"
        raise ValueError(msg)
    flat = np.frombuffer(data, dtype=np.uint8)
    needed = step * (height - 1) + row_bytes if height else 0
    if flat.size < needed:
        msg = f"data holds {flat.size} bytes, {height} rows of step {step} need {needed}"
        raise ValueError(msg)
    if height == 0 or width == 0:
        rows = np.zeros((height, row_bytes), dtype=np.uint8)
    else:
        rows = np.lib.stride_tricks.as_strided(
            flat, shape=(height, row_bytes), strides=(step, 1), writeable=False
        )
    if step != row_bytes:
        rows = np.ascontiguousarray(rows)
    pixels = rows.view(dtype)
    if not pixels.dtype.isnative:
        pixels = pixels.astype(pixels.dtype.newbyteorder("="))
    shape = (height, width) if channels == 1 else (height, width, channels)
    return pixels.reshape(shape)


class ImageDecoder:
    """``sensor_msgs/msg/Image`` (rgb8, bgr8, rgba8, bgra8, mono8, mono16, 16UC1, 32FC1)."""

    name = "image"
    msgtypes: tuple[str, ...] = ("sensor_msgs/msg/Image",)
    kind = DecodedKind.SENSOR
    sensor_type: SensorType | None = SensorType.CAMERA

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        try:
            pixels = pixels_from_buffer(
                msg.data,
                str(msg.encoding),
                height=int(msg.height),
                width=int(msg.width),
                step=int(msg.step),
                is_bigendian=bool(msg.is_bigendian),
            )
        except ValueError as err:
            raise unsupported(
                message,
                f"Image cannot be decoded: {err}",
                "convert the images to a supported encoding (e.g. rgb8) or skip this topic",
            ) from err
        if not raw_is_immutable(message) and not pixels.flags.owndata:
            pixels = pixels.copy()  # the reader may reuse the buffer the bytes came from
        value = Image(pixels=pixels, encoding=str(msg.encoding))
        return Decoded(
            stamp_ns=header_stamp_ns(msg.header, message),
            frame_id=str(msg.header.frame_id),
            value=value,
        )


def _image_from_compressed(data: bytes) -> Image:
    from PIL import Image as PILImage

    try:
        pil: PILImage.Image = PILImage.open(io.BytesIO(data))
        pil.load()
    except PILImage.DecompressionBombError as err:
        raise ValueError(str(err)) from err
    mode = pil.mode
    if mode == "L":
        return Image(pixels=np.asarray(pil, dtype=np.uint8), encoding="mono8")
    if mode in ("I;16", "I;16L", "I;16B", "I;16N"):
        arr = np.asarray(pil)
        return Image(pixels=arr.astype(np.uint16), encoding="mono16")
    if mode == "I":
        arr = np.asarray(pil)
        if arr.size and (arr.min() < 0 or arr.max() > 0xFFFF):
            msg = "32-bit grey image does not fit mono16"
            raise ValueError(msg)
        return Image(pixels=arr.astype(np.uint16), encoding="mono16")
    if mode == "1":
        pil = pil.convert("L")
        return Image(pixels=np.asarray(pil, dtype=np.uint8), encoding="mono8")
    if mode != "RGB":
        pil = pil.convert("RGB")
    return Image(pixels=np.asarray(pil, dtype=np.uint8), encoding="rgb8")


class CompressedImageDecoder:
    """``sensor_msgs/msg/CompressedImage`` with JPEG or PNG data (``format`` says which)."""

    name = "compressed_image"
    msgtypes: tuple[str, ...] = ("sensor_msgs/msg/CompressedImage",)
    kind = DecodedKind.SENSOR
    sensor_type: SensorType | None = SensorType.CAMERA

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        fmt = str(msg.format).lower()
        if "compresseddepth" in fmt or not any(k in fmt for k in ("jpeg", "jpg", "png")):
            raise unsupported(
                message,
                f"CompressedImage format {msg.format!r} is not supported",
                "redrive decodes jpeg and png; republish as sensor_msgs/Image or skip the topic",
            )
        try:
            value = _image_from_compressed(bytes(msg.data))
        except (OSError, ValueError) as err:  # PIL.UnidentifiedImageError is an OSError
            raise unsupported(
                message,
                f"CompressedImage ({msg.format!r}, {len(msg.data)} bytes) does not decode: {err}",
                "check the image bytes, or skip this topic",
            ) from err
        return Decoded(
            stamp_ns=header_stamp_ns(msg.header, message),
            frame_id=str(msg.header.frame_id),
            value=value,
        )
