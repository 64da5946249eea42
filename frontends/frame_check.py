"""Checks that a frame can be measured at all, before any feature work is spent on it.

A frame is *unusable* (``BAD_FRAME``) when it is not a 2-D ``uint8``/``uint16`` array or its size differs
from the first frame's. It is *featureless* (``TOO_FEW_FEATURES``) when its texture is too weak to
localise points: dark, saturated, heavily blurred or constant images all have a small mean absolute
intensity difference between neighbouring pixels,

.. math::  g = \\tfrac12 \\big( \\overline{|I(x+2, y) - I(x, y)|} + \\overline{|I(x, y+2) - I(x, y)|} \\big),

computed on every other pixel of the 8-bit image (a cheap sharpness and contrast measure). The frame
is featureless when ``g < min_texture`` or when ``g`` dropped below ``min_ratio`` times that of the
reference frame (a sudden blur or exposure loss on an otherwise usable floor). For scale: the sharp
scikit-image gravel, grass and brick photographs give ``g`` = 13, 20 and 3.6; a Gaussian blur of sigma
8 px brings gravel to 2.2 (ratio 0.17), a black or saturated frame gives 0.
``uint16`` frames are divided by 257 (full 16-bit range onto 8 bits).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from frontends.base import MotionStatus


@dataclass
class FrameCheck:
    """Outcome of :func:`check_frame`.

    Attributes
    ----------
    status : MotionStatus or None
        ``None`` when the frame is usable, else ``BAD_FRAME`` or ``TOO_FEW_FEATURES``.
    image : ndarray or None
        The frame as a contiguous ``uint8`` array (``None`` for a bad frame).
    texture : float
        The mean neighbour difference ``g`` [grey levels] (``nan`` for a bad frame).
    reason : str
        Plain-words explanation of a failure ('' when usable).
    """

    status: MotionStatus | None
    image: np.ndarray | None
    texture: float
    reason: str = ""


@dataclass
class Prepared:
    """A frame with the work on it that does not depend on earlier frames, made by a frontend's ``prepare``
    (possibly in another thread, ahead of its ``process``).

    Attributes
    ----------
    image : ndarray
        The frame as given.
    texture : float
        :func:`texture_measure` of its 8-bit version.
    """

    image: np.ndarray
    texture: float


def texture_measure(image: np.ndarray) -> float:
    """Mean absolute difference between pixels two apart, on every other pixel (grey levels)."""
    sub = np.ascontiguousarray(image[::2, ::2])
    if sub.shape[0] < 2 or sub.shape[1] < 2:
        return 0.0
    dx = cv2.mean(cv2.absdiff(sub[:, 1:], sub[:, :-1]))[0]
    dy = cv2.mean(cv2.absdiff(sub[1:, :], sub[:-1, :]))[0]
    return 0.5 * float(dx + dy)


def grey8(image, min_size: int) -> np.ndarray | None:
    """``image`` as a contiguous ``uint8`` array (``uint16`` divided by 257), or ``None`` when it is not a 2-D
    ``uint8``/``uint16`` array of at least ``min_size`` pixels a side."""
    if not isinstance(image, np.ndarray) or image.ndim != 2 or image.dtype not in (np.uint8, np.uint16) \
            or min(image.shape) < min_size:
        return None
    return np.ascontiguousarray((image // 257).astype(np.uint8) if image.dtype == np.uint16 else image)


def check_frame(
    image,
    expected_shape: tuple[int, int] | None,
    min_texture: float,
    reference_texture: float | None = None,
    min_ratio: float = 0.0,
    min_size: int = 32,
    texture: float | None = None,
) -> FrameCheck:
    """Validate a frame and measure its texture; never raises.

    Parameters
    ----------
    image : array-like
        The frame handed to a frontend.
    expected_shape : (rows, cols) or None
        Shape every frame must have (``None``: accept any size of at least ``min_size``).
    min_texture : float
        Smallest acceptable :func:`texture_measure` [grey levels].
    reference_texture : float, optional
        Texture of the frame the motion will be measured from.
    min_ratio : float
        Smallest acceptable ratio of this frame's texture to ``reference_texture``.
    min_size : int
        Smallest acceptable side length [px].
    texture : float, optional
        :func:`texture_measure` of the frame when it was already computed (by a frontend's
        ``prepare`` in another thread); measured here otherwise.
    """
    if not isinstance(image, np.ndarray):
        return FrameCheck(MotionStatus.BAD_FRAME, None, float("nan"), "not an array")
    if image.ndim != 2:
        return FrameCheck(MotionStatus.BAD_FRAME, None, float("nan"), f"expected a 2-D grey image, got shape {image.shape}")
    if image.dtype == np.uint16:
        image = (image // 257).astype(np.uint8)
    elif image.dtype != np.uint8:
        return FrameCheck(MotionStatus.BAD_FRAME, None, float("nan"), f"unsupported pixel type {image.dtype}")
    if expected_shape is not None and image.shape != tuple(expected_shape):
        return FrameCheck(
            MotionStatus.BAD_FRAME, None, float("nan"), f"frame size {image.shape} differs from {tuple(expected_shape)}"
        )
    if min(image.shape) < min_size:
        return FrameCheck(MotionStatus.BAD_FRAME, None, float("nan"), f"frame too small {image.shape}")
    image = np.ascontiguousarray(image)
    g = texture_measure(image) if texture is None else float(texture)
    if g < min_texture:
        return FrameCheck(MotionStatus.TOO_FEW_FEATURES, image, g, f"texture {g:.2f} below {min_texture:g}")
    if reference_texture is not None and g < min_ratio * reference_texture:
        return FrameCheck(
            MotionStatus.TOO_FEW_FEATURES, image, g, f"texture {g:.2f} fell below {min_ratio:g} x {reference_texture:.2f}"
        )
    return FrameCheck(None, image, g)

