"""The camera's lever arm from a turn in place.

When the robot turns about its axle, the floor point under the axle does not move, so its rectified
image ``p`` is the fixed point of every frame's similarity ``S_k = (A_k, t_k)``, ``A_k = s_k R(θ_k)``::

    p = A_k p + t_k    <=>    (I - A_k) p = t_k

Stacking these two equations per frame gives a linear least-squares problem in ``p``. Frames that
barely turn carry no information and are left out; frames whose residual exceeds ``threshold`` robust
standard deviations (``1.4826 · MAD``) are rejected and the fit repeated until no more are.
The fixed point's covariance is ``σ² (AᵀA)^-1`` with ``σ²`` the residual variance of the kept frames.

A rectified pixel ``u'`` is the floor point ``q = t_xy + (h / f) R2 (u' - c)`` of the body frame
(:mod:`fusion_vo.geometry.ground`); the axle is ``q = 0``, so the camera's lever arm is::

    t_xy = -(h / f) R2 (p - c)

with covariance ``(h/f)² R2 Σ_p R2ᵀ + (t_xy / h)(t_xy / h)ᵀ σ_h²``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fusion_vo.errors import InputError
from fusion_vo.geometry.ground import GroundGeometry

logger = logging.getLogger(__name__)


@dataclass
class FixedPoint:
    """The common fixed point of a set of similarities.

    Attributes
    ----------
    point : ndarray (2,)
        Fixed point [rectified px].
    cov : ndarray (2, 2)
        Its covariance [px²].
    inliers : ndarray of bool
        Which of the given similarities were used.
    n_turning : int
        Similarities that turned enough to be used at all.
    rms : float
        RMS residual of the kept equations [px].
    """

    point: np.ndarray
    cov: np.ndarray
    inliers: np.ndarray
    n_turning: int
    rms: float


@dataclass
class LeverArmResult:
    """Lever arm ``(x, y)`` of the camera centre from the rotation centre, in the body frame [m]."""

    lever_arm: np.ndarray
    cov: np.ndarray
    fixed_point: FixedPoint
    height: float
    turned_deg: float

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    def summary(self) -> str:
        fp = self.fixed_point
        s = self.std
        return "\n".join([
            f"Lever arm from a turn in place ({fp.inliers.sum()} of {fp.n_turning} turning frames used, "
            f"{self.turned_deg:.1f} deg turned, residual RMS {fp.rms:.3f} px):",
            f"  Rotation centre:  [{fp.point[0]:.2f} {fp.point[1]:.2f}] +- "
            f"[{math.sqrt(fp.cov[0, 0]):.2f} {math.sqrt(fp.cov[1, 1]):.2f}] rectified px",
            f"  Lever arm:        x = {self.lever_arm[0]:.5f} +- {s[0]:.5f} m,  y = {self.lever_arm[1]:.5f} +- {s[1]:.5f} m"
            f"   (height {self.height:.4f} m)",
        ])


def fixed_point(matrices: Sequence[np.ndarray], min_angle: float = 2e-3, threshold: float = 3.0,
                max_iterations: int = 10) -> FixedPoint:
    """Robust least-squares fixed point of similarities ``S_k`` (2 x 3 each), see the module docstring."""
    S = np.asarray(matrices, dtype=np.float64).reshape(-1, 2, 3)
    angles = np.arctan2(S[:, 1, 0], S[:, 0, 0])
    turning = np.abs(angles) >= min_angle
    n_turning = int(turning.sum())
    if n_turning < 3:
        raise InputError(f"only {n_turning} frames turn by more than {math.degrees(min_angle):.2f} deg: "
                         "record a turn in place")
    M = np.eye(2)[None] - S[:, :, :2]
    t = S[:, :, 2]
    keep = turning.copy()
    p = np.zeros(2)
    for _ in range(max_iterations):
        A = M[keep].reshape(-1, 2)
        p, *_ = np.linalg.lstsq(A, t[keep].ravel(), rcond=None)
        r = np.linalg.norm(np.einsum("kij,j->ki", M, p) - t, axis=1)
        scale = max(1.4826 * float(np.median(r[keep])), 1e-3)
        new = turning & (r <= threshold * scale)
        if np.array_equal(new, keep) or new.sum() < 3:
            break
        keep = new
    A = M[keep].reshape(-1, 2)
    res = A @ p - t[keep].ravel()
    sigma2 = float(res @ res) / max(1, len(res) - 2)
    cov = sigma2 * np.linalg.inv(A.T @ A)
    logger.info("fixed point %s from %d of %d turning frames", p, keep.sum(), n_turning)
    return FixedPoint(p, cov, keep, n_turning, math.sqrt(float(res @ res) / len(res)))


def lever_arm_from_turn(matrices: Sequence[np.ndarray], geometry: GroundGeometry, height_std: float = 0.0,
                        **options) -> LeverArmResult:
    """The camera's lever arm from the similarities of a turn in place.

    Parameters
    ----------
    matrices : the frames' rectified-pixel similarities (``FrameMotion.matrix`` of the successful frames).
    geometry : the camera's ground geometry (height, orientation and rectification).
    height_std : standard deviation of the height [m], propagated into the lever arm.
    **options : passed to :func:`fixed_point`.
    """
    fp = fixed_point(matrices, **options)
    rect = geometry.rectifier
    k = geometry.height / rect.f
    R2 = rect.R_BV[:2, :2]
    lever = -k * R2 @ (fp.point - rect.c)
    cov = k**2 * R2 @ fp.cov @ R2.T + np.outer(lever, lever) * (height_std / geometry.height) ** 2
    S = np.asarray(matrices, dtype=np.float64).reshape(-1, 2, 3)
    turned = float(np.sum(np.arctan2(S[:, 1, 0], S[:, 0, 0])))
    return LeverArmResult(lever, cov, fp, float(geometry.height), abs(math.degrees(turned)))
