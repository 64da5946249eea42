"""Synthetic frames: crops of scikit-image's CC0 floor photographs under known similarities.

A frame is rendered from a large canvas ``C`` by an affine map ``A`` from canvas to frame pixels,
with 2x supersampling (render at double resolution, then average 2x2 blocks) so that every frame is
interpolated alike. The motion between frames rendered with ``A0`` and ``A1`` is ``A1 A0^-1``.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
import skimage.data

WIDTH, HEIGHT = 640, 360


@functools.lru_cache(maxsize=4)
def canvas(name: str = "gravel") -> np.ndarray:
    """A 2048 x 2048 floor: the 512 x 512 photograph enlarged twice and mirrored into 2 x 2 tiles."""
    tex = getattr(skimage.data, name)()
    if tex.ndim == 3:
        tex = cv2.cvtColor(tex, cv2.COLOR_RGB2GRAY)
    tex = cv2.resize(tex, (1024, 1024), interpolation=cv2.INTER_CUBIC)
    top = np.hstack([tex, tex[:, ::-1]])
    return np.ascontiguousarray(np.vstack([top, top[::-1]]))


def as3(m: np.ndarray) -> np.ndarray:
    return np.vstack([m, [0.0, 0.0, 1.0]])


def similarity_about(cx: float, cy: float, tx: float, ty: float, angle_deg: float, scale: float = 1.0) -> np.ndarray:
    """2x3 similarity rotating/scaling about ``(cx, cy)`` then translating by ``(tx, ty)``."""
    a = np.deg2rad(angle_deg)
    c, s = scale * np.cos(a), scale * np.sin(a)
    r = np.array([[c, -s], [s, c]])
    t = np.array([cx, cy]) - r @ np.array([cx, cy]) + np.array([tx, ty])
    return np.hstack([r, t[:, None]])


def render(a: np.ndarray, name: str = "gravel", size=(WIDTH, HEIGHT)) -> np.ndarray:
    """Frame seen through the canvas-to-frame affine map ``a`` (2x3)."""
    up = np.array([[2.0, 0, 0.5], [0, 2.0, 0.5], [0, 0, 1]])
    big = cv2.warpAffine(canvas(name), (up @ as3(a))[:2], (2 * size[0], 2 * size[1]), flags=cv2.INTER_LINEAR)
    return cv2.resize(big, size, interpolation=cv2.INTER_AREA)


def start_map(x0: float = 700.0, y0: float = 800.0) -> np.ndarray:
    """Canvas-to-frame map of a frame whose top-left corner sits at canvas ``(x0, y0)``."""
    return np.array([[1.0, 0, -x0], [0, 1.0, -y0]])


def pair(motion: np.ndarray, name: str = "gravel", x0: float = 700.3, y0: float = 800.7):
    """Two frames related by ``motion`` (2x3, frame-0 pixels to frame-1 pixels)."""
    a0 = start_map(x0, y0)
    a1 = (as3(motion) @ as3(a0))[:2]
    return render(a0, name), render(a1, name)


def sequence(motions, name: str = "gravel", x0: float = 700.3, y0: float = 800.7):
    """Frames of a camera moving by the given per-frame motions (2x3 frame-k to frame-k+1 maps).

    Yields ``(frame, true_motion_into_this_frame_or_None)``.
    """
    a = start_map(x0, y0)
    yield render(a, name), None
    for m in motions:
        a = (as3(m) @ as3(a))[:2]
        yield render(a, name), m


def circle_motions(n: int, step_px: float, turn_deg: float, cx: float = WIDTH / 2, cy: float = HEIGHT / 2):
    """``n`` equal motions: image content moving down by ``step_px`` while rotating by ``turn_deg``."""
    return [similarity_about(cx, cy, 0.0, step_px, turn_deg) for _ in range(n)]
