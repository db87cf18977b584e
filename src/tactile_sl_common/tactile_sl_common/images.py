"""sensor_msgs/Image <-> numpy without cv_bridge (not available as a wheel).

Works on rclpy messages and on messages decoded from bags alike (duck typing on the
Image fields), so nodes and offline tools share one conversion.
"""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np

CHANNELS = {"mono8": 1, "8UC1": 1, "bgr8": 3, "rgb8": 3, "8UC3": 3, "bgra8": 4, "rgba8": 4}


class ImageFormatError(ValueError):
    """An Image message this project cannot interpret (encoding, size, step, data length)."""


def image_to_array(msg: Any) -> np.ndarray:
    """View an Image message's pixels as (H, W) or (H, W, C) uint8 (no copy if possible)."""
    encoding = str(msg.encoding)
    if encoding not in CHANNELS:
        raise ImageFormatError(f"unsupported image encoding {encoding!r} "
                               f"(expected one of {', '.join(sorted(CHANNELS))})")
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    channels = CHANNELS[encoding]
    if height <= 0 or width <= 0:
        raise ImageFormatError(f"empty image ({width}x{height})")
    if step < width * channels:
        raise ImageFormatError(f"image step {step} is smaller than width*channels "
                               f"{width * channels}")
    data = msg.data
    try:     # bytes, bytearray, array.array (rclpy's uint8[]), numpy: a view, no copy
        buffer = np.frombuffer(memoryview(data).cast("B"), dtype=np.uint8)
    except (TypeError, ValueError):    # a list of ints (a message built by hand)
        buffer = np.frombuffer(bytes(data), dtype=np.uint8)
    if buffer.size < step * height:
        raise ImageFormatError(f"image data has {buffer.size} bytes, expected "
                               f"step*height = {step * height}")
    rows = buffer[: step * height].reshape(height, step)[:, : width * channels]
    return rows.reshape(height, width) if channels == 1 else rows.reshape(height, width, channels)


def to_gray(msg: Any) -> np.ndarray:
    """Grey levels (H, W) uint8 of an Image message in any supported encoding."""
    pixels = image_to_array(msg)
    encoding = str(msg.encoding)
    if pixels.ndim == 2:
        return pixels
    codes = {"bgr8": cv2.COLOR_BGR2GRAY, "8UC3": cv2.COLOR_BGR2GRAY, "rgb8": cv2.COLOR_RGB2GRAY,
             "bgra8": cv2.COLOR_BGRA2GRAY, "rgba8": cv2.COLOR_RGBA2GRAY}
    return cv2.cvtColor(np.ascontiguousarray(pixels), codes[encoding])


def image_fields(pixels: np.ndarray, encoding: str | None = None) -> dict[str, Any]:
    """The Image fields (height, width, encoding, is_bigendian, step, data) for an array."""
    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    if encoding is None:
        encoding = "mono8" if pixels.ndim == 2 else "bgr8"
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    if CHANNELS.get(encoding) != channels:
        raise ImageFormatError(f"array with {channels} channel(s) cannot be {encoding}")
    height, width = pixels.shape[:2]
    return {"height": height, "width": width, "encoding": encoding, "is_bigendian": 0,
            "step": width * channels, "data": pixels.tobytes()}
