"""Camera height from a straight drive of known length (the thesis' "pixels per centimetre").

The frames' rectified-pixel similarities are chained, ``M = S_n ··· S_1``, and the principal point ``c``
(the floor point under the camera in the first frame) is followed to ``M c``. The floor moved by the
driven distance ``D`` while its image moved by ``P = |M c - c|`` rectified pixels; the virtual nadir
camera of focal length ``f`` sees ``f / h`` pixels per metre, so::

    h = f D / P,     σ_h / h = sqrt((σ_P / P)² + (σ_D / D)²)

with ``σ_P²`` the sum of the frames' translation variances along the direction of travel (from the
frontend's covariances) and ``σ_D`` the uncertainty of the measured distance. A failed frame would
lose part of the motion, so the estimate refuses recordings with failed frames unless told otherwise.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from frontends.base import FrameMotion
from fusion_vo.errors import InputError

logger = logging.getLogger(__name__)


@dataclass
class HeightResult:
    """Height from a straight drive.

    Attributes
    ----------
    height, height_std : float
        Camera height above the floor and its standard deviation [m].
    pixels, pixels_std : float
        Image motion of the floor over the drive [rectified px].
    distance : float
        Driven distance [m].
    n_frames, n_failed : int
        Frame motions used and failed.
    """

    height: float
    height_std: float
    pixels: float
    pixels_std: float
    distance: float
    n_frames: int
    n_failed: int

    @property
    def pixels_per_metre(self) -> float:
        return self.pixels / self.distance

    def summary(self) -> str:
        return "\n".join([
            f"Height from a straight drive ({self.n_frames} frames, {self.n_failed} failed):",
            f"  Floor motion:   {self.pixels:.2f} +- {self.pixels_std:.2f} px over {self.distance:.4f} m "
            f"({self.pixels_per_metre / 100:.3f} px/cm)",
            f"  Height:         {self.height:.5f} +- {self.height_std:.5f} m",
        ])


def height_from_drive(motions: Sequence[FrameMotion], focal: float, centre: np.ndarray, distance: float,
                      distance_std: float = 0.0, allow_failed: bool = False) -> HeightResult:
    """Camera height from the frame motions of a straight drive of ``distance`` metres.

    Parameters
    ----------
    motions : the frontend's motions of consecutive frames (rectified pixels).
    focal : focal length ``f`` of the rectified (virtual nadir) camera [px].
    centre : its principal point ``c`` [px].
    distance, distance_std : driven distance and its standard deviation [m].
    allow_failed : chain over failed frames (their motion is lost) instead of raising.
    """
    if not (distance > 0 and math.isfinite(distance)):
        raise InputError(f"the driven distance must be positive, got {distance}")
    failed = [m for m in motions if not m.ok]
    if failed and not allow_failed:
        raise InputError(f"{len(failed)} of {len(motions)} frame motions failed (first at t = "
                         f"{failed[0].timestamp:.3f} s); the image motion would be incomplete")
    ok = [m for m in motions if m.ok]
    if not ok:
        raise InputError("no frame motion was measured")
    M = np.eye(3)
    for m in ok:
        M = np.vstack([m.matrix, [0.0, 0.0, 1.0]]) @ M
    c = np.asarray(centre, dtype=np.float64)
    d = (M @ np.append(c, 1.0))[:2] - c
    pixels = float(np.linalg.norm(d))
    if pixels < 1.0:
        raise InputError(f"the floor moved only {pixels:.2f} px: record a straight drive")
    u = d / pixels
    var = sum(float(u @ m.covariance[:2, :2] @ u) for m in ok)
    pixels_std = math.sqrt(var)
    h = focal * distance / pixels
    rel = math.hypot(pixels_std / pixels, distance_std / distance)
    logger.info("floor moved %.2f px over %.4f m", pixels, distance)
    return HeightResult(h, h * rel, pixels, pixels_std, float(distance), len(ok), len(failed))
