"""Photometric effects applied to a rendered floor radiance (float32, 0..255) to make a camera frame.

In order: exposure gain (global ``gain`` times a slow drift ``1 + a sin(2π t / T)``), vignetting
(``1 - v r²`` with ``r`` the distance from the image centre relative to the half diagonal), a specular
highlight fixed in the image (a Gaussian blob adding up to ``2 × 255``, so it saturates), sensor noise
(Gaussian read noise plus shot noise ``sqrt(k · I)``), then rounding and clipping to 8 bits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class Photometry:
    """Photometric settings of the simulated camera."""

    gain: float = 1.0
    exposure_drift: float = 0.0
    exposure_period: float = 10.0
    vignetting: float = 0.0
    highlight_radius: float = 0.0
    highlight_center: tuple[float, float] = (0.55, 0.45)
    noise: float = 1.0
    shot_noise: float = 0.0


class Photometric:
    """Applies :class:`Photometry` to radiance images of one size (precomputes the fixed masks)."""

    def __init__(self, settings: Photometry, width: int, height: int):
        self.s = settings
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
        cx, cy = (width - 1) / 2, (height - 1) / 2
        r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / (cx**2 + cy**2)
        self.vignette = (1.0 - settings.vignetting * r2).astype(np.float32) if settings.vignetting else None
        if settings.highlight_radius > 0:
            hx = settings.highlight_center[0] * width
            hy = settings.highlight_center[1] * height
            d2 = ((xx - hx) ** 2 + (yy - hy) ** 2) / settings.highlight_radius**2
            self.highlight = (510.0 * np.exp(-0.5 * d2)).astype(np.float32)
        else:
            self.highlight = None

    def apply(self, radiance: np.ndarray, t: float, rng: np.random.Generator) -> np.ndarray:
        s = self.s
        gain = s.gain * (1.0 + s.exposure_drift * math.sin(2 * math.pi * t / s.exposure_period))
        img = radiance * np.float32(gain)
        if self.vignette is not None:
            img *= self.vignette
        if self.highlight is not None:
            img += self.highlight
        if s.noise > 0 or s.shot_noise > 0:
            sigma = np.float32(s.noise)
            if s.shot_noise > 0:
                sigma = np.sqrt(sigma**2 + np.float32(s.shot_noise) * np.maximum(img, 0))
            noise = rng.standard_normal(img.shape, dtype=np.float32)
            noise *= sigma
            img += noise
        np.rint(img, out=img)
        np.clip(img, 0, 255, out=img)
        return img.astype(np.uint8)
