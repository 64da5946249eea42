"""The contract every frontend fulfils.

A frontend is an object with

``process(image, timestamp) -> FrameMotion``
    ``image`` a 2-D ``uint8`` (or ``uint16``) grey array, ``timestamp`` in seconds. Returns the motion
    from the previous successfully processed frame to this one. The first frame returns status
    ``FIRST``. A frame that cannot be measured (dark, saturated, blurred, textureless, wrong size)
    returns a failed status and never raises.

``reset()``
    forget the previous frame (the next frame is treated as a first frame).

The similarity maps a point's rectified coordinates in the previous frame to its coordinates in the
current frame::

    [u1, v1]^T = M @ [u0, v0, 1]^T,   M = [[s cos a, -s sin a, tx],
                                          [s sin a,  s cos a, ty]]

Its covariance is over the parameters ``(tx, ty, a, log s)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

import numpy as np


class MotionStatus(str, Enum):
    """Outcome of one frame."""

    OK = "ok"
    FIRST = "first"  # first frame (or first after a reset): nothing to compare with
    TOO_FEW_FEATURES = "too_few_features"  # dark, saturated, blurred or textureless image
    DEGENERATE = "degenerate"  # points present but the estimate is ill-conditioned
    REJECTED = "rejected"  # an estimate was found but failed a consistency check
    BAD_FRAME = "bad_frame"  # wrong size, wrong type, NaN: the frame itself is unusable

    @property
    def ok(self) -> bool:
        return self is MotionStatus.OK


class PointMap(Protocol):
    """Maps raw pixel coordinates (``N x 2`` float arrays) to rectified coordinates and back."""

    def to_rectified(self, pts: np.ndarray) -> np.ndarray: ...

    def to_image(self, pts: np.ndarray) -> np.ndarray: ...


class IdentityMap:
    """The rectified coordinates are the pixel coordinates (no distortion, no tilt)."""

    def to_rectified(self, pts: np.ndarray) -> np.ndarray:
        return np.asarray(pts, dtype=np.float64)

    def to_image(self, pts: np.ndarray) -> np.ndarray:
        return np.asarray(pts, dtype=np.float64)


def similarity_matrix(tx: float, ty: float, angle: float, log_scale: float = 0.0) -> np.ndarray:
    """2x3 similarity from its parameters ``(tx, ty, angle, log s)``."""
    s = math.exp(log_scale)
    c, sn = s * math.cos(angle), s * math.sin(angle)
    return np.array([[c, -sn, tx], [sn, c, ty]], dtype=np.float64)


def similarity_params(matrix: np.ndarray) -> np.ndarray:
    """Parameters ``(tx, ty, angle, log s)`` of a 2x3 similarity."""
    m = np.asarray(matrix, dtype=np.float64)
    a = 0.5 * (m[0, 0] + m[1, 1])
    b = 0.5 * (m[1, 0] - m[0, 1])
    return np.array([m[0, 2], m[1, 2], math.atan2(b, a), math.log(math.hypot(a, b))])


@dataclass
class FrameMotion:
    """Motion of the image content between two consecutive frames.

    Attributes
    ----------
    timestamp : float
        Time of the current frame [s].
    prev_timestamp : float or None
        Time of the frame the motion is measured from [s] (``None`` for a first frame).
    matrix : ndarray, shape (2, 3)
        Similarity from previous-frame to current-frame rectified coordinates (identity when failed).
    covariance : ndarray, shape (4, 4)
        Covariance of ``(tx, ty, angle, log_scale)`` derived from the inlier residuals (infinite
        diagonal when failed).
    status : MotionStatus
    n_candidates : int
        Correspondences offered to the robust estimator.
    n_inliers : int
        Correspondences consistent with the estimate.
    residual_rms : float
        RMS of the inlier residuals [rectified px].
    n_features : int
        Features detected or tracked in the current frame.
    info : dict
        Frontend-specific diagnostics (timings, retries, ...).
    """

    timestamp: float
    prev_timestamp: float | None
    matrix: np.ndarray = field(default_factory=lambda: np.array([[1.0, 0, 0], [0, 1.0, 0]]))
    covariance: np.ndarray = field(default_factory=lambda: np.diag([np.inf] * 4))
    status: MotionStatus = MotionStatus.FIRST
    n_candidates: int = 0
    n_inliers: int = 0
    residual_rms: float = float("nan")
    n_features: int = 0
    info: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status is MotionStatus.OK

    @property
    def params(self) -> np.ndarray:
        """``(tx, ty, angle, log_scale)`` of :attr:`matrix`."""
        return similarity_params(self.matrix)

    @property
    def scale(self) -> float:
        return float(math.exp(self.params[3]))

    @property
    def angle(self) -> float:
        return float(self.params[2])
