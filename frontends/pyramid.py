"""The images the direct alignment works on: rectified, normalised, reduced into a pyramid.

Both frames are resampled into rectified coordinates (the :class:`~frontends.base.PointMap`'s lens and tilt
correction, one precomputed ``cv2.remap``, :class:`Rectifier`), high-pass filtered and normalised to
zero mean and unit variance (:func:`normalise`: a global gain or offset change, e.g. auto-exposure,
vignetting or a fixed highlight, does not pull the fit) and reduced into a pyramid (:func:`pyramid`).
Each :class:`Level` of the reference frame also provides its steepest-descent images for
:mod:`frontends.photometric`.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from frontends.base import IdentityMap, PointMap


class Rectifier:
    """Resamples raw frames onto a regular grid of rectified coordinates: ``rect = pitch * grid + origin``.

    The grid covers the rectified rectangle inscribed in the image of the raw frame's border. With the
    identity point map (or one that says it is ``trivial``) frames are used as they are.

    Parameters
    ----------
    point_map : PointMap
    shape : tuple of int
        ``(rows, cols)`` of the raw frames.
    limit : bool
        Choose the ``pitch`` (rectified units per grid pixel, at least 1) that keeps the grid's pixel count
        at most the raw frame's (otherwise 1).
    """

    def __init__(self, point_map: PointMap, shape: tuple[int, int], limit: bool = False):
        h, w = shape
        self.origin = np.zeros(2)
        self.pitch = 1.0  # rectified units per grid pixel
        self.maps: tuple[np.ndarray, np.ndarray] | None = None
        self.shape = shape
        if isinstance(point_map, IdentityMap) or getattr(point_map, "trivial", False):
            return
        # the rectified rectangle inscribed in the image of the raw frame's border
        n = 64
        xs, ys = np.linspace(0, w - 1, n), np.linspace(0, h - 1, n)
        left = point_map.to_rectified(np.column_stack([np.zeros(n), ys]))
        right = point_map.to_rectified(np.column_stack([np.full(n, w - 1.0), ys]))
        top = point_map.to_rectified(np.column_stack([xs, np.zeros(n)]))
        bottom = point_map.to_rectified(np.column_stack([xs, np.full(n, h - 1.0)]))
        x0, x1 = float(np.max(left[:, 0])), float(np.min(right[:, 0]))
        y0, y1 = float(np.max(top[:, 1])), float(np.min(bottom[:, 1]))
        if not (x1 - x0 > 16 and y1 - y0 > 16):
            raise ValueError("the point map leaves no usable rectified area")
        if limit:
            self.pitch = max(1.0, math.sqrt((x1 - x0) * (y1 - y0) / float(w * h)))
        gw, gh = int((x1 - x0) / self.pitch), int((y1 - y0) / self.pitch)
        self.origin = np.array([x0, y0])
        gx, gy = np.meshgrid(np.arange(gw, dtype=np.float64) * self.pitch + x0,
                             np.arange(gh, dtype=np.float64) * self.pitch + y0)
        raw = point_map.to_image(np.column_stack([gx.ravel(), gy.ravel()])).reshape(gh, gw, 2).astype(np.float32)
        self.maps = cv2.convertMaps(raw[..., 0], raw[..., 1], cv2.CV_16SC2)
        self.shape = (gh, gw)

    def __call__(self, image: np.ndarray) -> np.ndarray:
        if self.maps is None:
            return image
        return cv2.remap(image, self.maps[0], self.maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


class Level:
    """One pyramid level of a normalised image, with its steepest-descent images when a reference."""

    def __init__(self, image: np.ndarray, scale: float, smoothing: float):
        img = image.astype(np.float32, copy=False)
        if smoothing > 0:
            img = cv2.GaussianBlur(img, (0, 0), smoothing)
        self.scale = scale
        self.image = img
        h, w = img.shape
        self.centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
        self._sd: np.ndarray | None = None

    def steepest_descent(self, border: int, max_pixels: int, region: float = 1.0
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``SD`` (N x 4, float32), the centred coordinates (2 x N) and the flat indices of the pixels used.

        Only the central ``region`` fraction of the width and height is used. When that holds more
        than ``max_pixels`` interior pixels, only those with the strongest gradient are used (the
        others add little to the Hessian and cost the same).
        """
        if self._sd is None:
            img = self.image
            h, w = img.shape
            gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
            gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
            bx = max(border, int(round(0.5 * (1.0 - region) * w)))
            by = max(border, int(round(0.5 * (1.0 - region) * h)))
            sw, sh = max(w - 2 * bx, 0), max(h - 2 * by, 0)
            n_inner = sw * sh
            if n_inner > max_pixels:
                # the inner pixels in row-major order, as flat indices of the sub-image
                sgx, sgy = gx[by : h - by, bx : w - bx], gy[by : h - by, bx : w - bx]
                mag = cv2.add(cv2.multiply(sgx, sgx), cv2.multiply(sgy, sgy)).ravel()
                # the gradient threshold that keeps about max_pixels, from a sample of at most 16384 pixels
                step = max(1, n_inner // 16384)
                sample = mag[::step]
                keep = len(sample) - max(1, (max_pixels * len(sample)) // n_inner)
                limit = np.partition(sample, keep)[keep]
                sub = np.flatnonzero(mag >= limit)
                if step == 1:
                    sub = sub[:max_pixels]
            else:
                sub = np.arange(n_inner)
            idx = (sub // max(sw, 1) + by) * w + (sub % max(sw, 1) + bx)
            gxf, gyf = gx.ravel()[idx], gy.ravel()[idx]
            xf = (idx % w).astype(np.float32) - np.float32(self.centre[0])
            yf = (idx // w).astype(np.float32) - np.float32(self.centre[1])
            self._sd_t = np.stack([gxf * xf + gyf * yf, -gxf * yf + gyf * xf, gxf, gyf])
            self._sd = np.ascontiguousarray(self._sd_t.T)
            self._xy = np.stack([xf, yf])
            self._idx = idx
        return self._sd, self._xy, self._idx

    def steepest_descent_t(self) -> np.ndarray:
        """``SD`` transposed (4 x N, contiguous) after :meth:`steepest_descent`."""
        return self._sd_t


def clipped_fraction(image: np.ndarray) -> float:
    """Fraction of the pixels of a ``uint8`` frame at 0 or 255 (under- or over-exposed)."""
    sub = image[::2, ::2]
    hist = cv2.calcHist([np.ascontiguousarray(sub)], [0], None, [256], [0, 256]).ravel()
    return float(hist[0] + hist[255]) / max(sub.size, 1)


def normalise(image: np.ndarray) -> np.ndarray:
    """High-pass and standardise: vignetting, a fixed highlight and exposure changes do not pull the fit.

    The low-pass removed is a box filter of about a sixteenth of the image, applied twice.
    """
    img = image.astype(np.float32)
    k = max(3, (min(img.shape) // 16) | 1)
    low = cv2.blur(img, (k, k), borderType=cv2.BORDER_REFLECT)
    cv2.blur(low, (k, k), dst=low, borderType=cv2.BORDER_REFLECT)
    cv2.subtract(img, low, dst=img)  # in place: no temporary frames
    mean, std = cv2.meanStdDev(img)
    gain = 1.0 / max(float(std[0, 0]), 1e-3)
    return cv2.addWeighted(img, gain, img, 0.0, -float(mean[0, 0]) * gain, dtype=cv2.CV_32F)


def pyramid(image: np.ndarray, min_level_size: int, finest_level: int, smoothing: float) -> list[Level]:
    """The levels of a normalised image, finest first: reduced by ``cv2.pyrDown`` until the shorter side
    would fall below ``min_level_size``, from level ``finest_level`` on (the coarsest level when the
    pyramid has fewer levels), each smoothed by a Gaussian of ``smoothing`` px."""
    levels = []
    scale = 1.0
    k = 0
    while True:
        if k >= finest_level:
            levels.append(Level(image, scale, smoothing))
        if min(image.shape) // 2 < min_level_size:
            break
        image = cv2.pyrDown(image)
        scale *= 0.5
        k += 1
    if not levels:  # finest_level beyond the coarsest level: use the coarsest
        levels.append(Level(image, scale, smoothing))
    return levels
