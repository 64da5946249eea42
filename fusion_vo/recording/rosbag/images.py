"""Camera messages to grey images.

``sensor_msgs/Image`` rows of ``step`` bytes are cropped to ``width * channels * bytes per channel``,
16-bit data is read in the message's byte order, and colour, Bayer and YUV encodings are converted to
grey by OpenCV. ``sensor_msgs/CompressedImage`` data is decoded with ``cv2.imdecode`` (JPEG, PNG, ...).
Grey images keep their depth (8 or 16 bit).
"""

from __future__ import annotations

import cv2
import numpy as np

from fusion_vo.recording.reader import decode_image


#: sensor_msgs/Image encoding -> (numpy dtype, channels, OpenCV conversion to grey or None)
IMAGE_ENCODINGS: dict[str, tuple[str, int, int | None]] = {
    "mono8": ("u1", 1, None),
    "8uc1": ("u1", 1, None),
    "mono16": ("u2", 1, None),
    "16uc1": ("u2", 1, None),
    "bgr8": ("u1", 3, cv2.COLOR_BGR2GRAY),
    "8uc3": ("u1", 3, cv2.COLOR_BGR2GRAY),
    "rgb8": ("u1", 3, cv2.COLOR_RGB2GRAY),
    "bgra8": ("u1", 4, cv2.COLOR_BGRA2GRAY),
    "8uc4": ("u1", 4, cv2.COLOR_BGRA2GRAY),
    "rgba8": ("u1", 4, cv2.COLOR_RGBA2GRAY),
    "bgr16": ("u2", 3, cv2.COLOR_BGR2GRAY),
    "16uc3": ("u2", 3, cv2.COLOR_BGR2GRAY),
    "rgb16": ("u2", 3, cv2.COLOR_RGB2GRAY),
    "bgra16": ("u2", 4, cv2.COLOR_BGRA2GRAY),
    "rgba16": ("u2", 4, cv2.COLOR_RGBA2GRAY),
    "bayer_rggb8": ("u1", 1, cv2.COLOR_BayerRGGB2GRAY),
    "bayer_bggr8": ("u1", 1, cv2.COLOR_BayerBGGR2GRAY),
    "bayer_gbrg8": ("u1", 1, cv2.COLOR_BayerGBRG2GRAY),
    "bayer_grbg8": ("u1", 1, cv2.COLOR_BayerGRBG2GRAY),
    "uyvy": ("u1", 2, cv2.COLOR_YUV2GRAY_UYVY),
    "yuv422": ("u1", 2, cv2.COLOR_YUV2GRAY_UYVY),
    "yuyv": ("u1", 2, cv2.COLOR_YUV2GRAY_YUY2),
    "yuv422_yuy2": ("u1", 2, cv2.COLOR_YUV2GRAY_YUY2),
}


class UnsupportedImage(ValueError):
    """An image format the import cannot convert (as opposed to one damaged message)."""


def image_to_grey(msg) -> np.ndarray:
    """Grey ``uint8``/``uint16`` image of a ``sensor_msgs/Image`` message.

    Raises
    ------
    UnsupportedImage
        For an encoding that is not in :data:`IMAGE_ENCODINGS`.
    ValueError
        For a data buffer that does not match width, height and step.
    """
    enc = str(msg.encoding).strip().lower()
    if enc not in IMAGE_ENCODINGS:
        raise UnsupportedImage(f"image encoding '{msg.encoding}' is not supported "
                         f"(supported: {', '.join(sorted(IMAGE_ENCODINGS))})")
    kind, channels, code = IMAGE_ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    itemsize = 2 if kind == "u2" else 1
    row_bytes = w * channels * itemsize
    buf = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    if h <= 0 or w <= 0 or step < row_bytes or buf.size < h * step:
        raise ValueError(f"image data of {buf.size} bytes does not fit {w}x{h} {enc} with step {step}")
    raw = np.ascontiguousarray(buf[: h * step].reshape(h, step)[:, :row_bytes])
    if itemsize == 2:
        raw = raw.view(np.dtype((">" if msg.is_bigendian else "<") + "u2")).astype(np.uint16)
    img = raw.reshape(h, w, channels) if channels > 1 else raw.reshape(h, w)
    if code is not None:
        img = cv2.cvtColor(img, code)
    return np.ascontiguousarray(img)


def compressed_to_grey(msg) -> np.ndarray:
    """Grey image of a ``sensor_msgs/CompressedImage`` message (JPEG, PNG, ... via ``cv2.imdecode``).

    Raises
    ------
    UnsupportedImage
        For ``compressedDepth`` images.
    ValueError
        When the data cannot be decoded.
    """
    fmt = str(msg.format).lower()
    if "compresseddepth" in fmt:
        raise UnsupportedImage(f"compressed depth images ('{msg.format}') are not supported")
    data = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    img = decode_image(data)
    if img is None:
        raise ValueError(f"cannot decode compressed image (format '{msg.format}')")
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if img.dtype not in (np.uint8, np.uint16):
        raise UnsupportedImage(f"pixel type {img.dtype} is not supported")
    return img
