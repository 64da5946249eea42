"""Motion prediction and failure bookkeeping shared by the frontends.

Prediction
----------
The similarity ``S`` measured over the last good interval ``dt_last`` is continued over the new gap
``dt`` at constant velocity (:func:`frontends.similarity.scale_motion`):

.. math::  \\hat S = S^k, \\qquad k = \\min(dt / dt_{last},\\ k_{max})

with ``k_max = max_prediction_gap``. There is no prediction before the first measured motion or after
a restart.

Failures
--------
A frame that cannot be measured leaves the reference unchanged, so the next frame is measured against
the last good one. After ``max_failures`` consecutive failures the frontend restarts: the current
frame, if usable, becomes the reference and the prediction is dropped.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from frontends.base import FrameMotion, MotionStatus
from frontends.similarity import scale_motion

logger = logging.getLogger(__name__)


@dataclass
class MotionHistory:
    """The last measured motion and the count of consecutive failures.

    Attributes
    ----------
    max_gap : float
        The prediction is continued over at most this many times the last interval.
    max_failures : int
        Consecutive failures after which the frontend restarts.
    last_motion : ndarray, shape (2, 3), or None
        Similarity of the last good interval.
    last_dt : float or None
        Length of that interval [s].
    failures : int
        Failures since the last good frame or restart.
    """

    max_gap: float
    max_failures: int
    last_motion: np.ndarray | None = None
    last_dt: float | None = None
    failures: int = 0

    def predict(self, dt: float) -> np.ndarray | None:
        """The expected similarity over the gap ``dt`` [s], or ``None`` without a measured motion."""
        if self.last_motion is None or not self.last_dt:
            return None
        return scale_motion(self.last_motion, min(dt / self.last_dt, self.max_gap))

    def succeeded(self, motion: np.ndarray, dt: float) -> None:
        """Record a good measurement ``motion`` over ``dt`` [s]."""
        self.last_motion, self.last_dt = motion, dt
        self.failures = 0

    def failed(self, can_restart: bool) -> bool:
        """Count a failure; ``True`` (and the history forgotten) when the frontend must restart."""
        self.failures += 1
        if self.failures >= self.max_failures and can_restart:
            self.forget()
            return True
        return False

    def forget(self) -> None:
        """Drop the prediction and the failure count."""
        self.last_motion, self.last_dt = None, None
        self.failures = 0


def failed_motion(t: float, prev_time: float | None, status: MotionStatus, reason: str, texture: float,
                  restarted: bool) -> FrameMotion:
    """The :class:`FrameMotion` of a frame at ``t`` that could not be measured."""
    logger.debug("frame t=%.6f failed (%s): %s", t, status.value, reason)
    return FrameMotion(t, prev_time, status=status,
                       info={"reason": reason, "texture": texture, "restarted": restarted, "path": "failed"})


def timed_measurement(measure: Callable[[np.ndarray, float], FrameMotion],
                      fail: Callable[[float, MotionStatus, str], FrameMotion],
                      image: np.ndarray, timestamp: float) -> FrameMotion:
    """``measure(image, t)`` with its run time in ``info["time_ms"]``; an OpenCV error is ``fail``-ed.

    OpenCV refusing an odd input is logged and turned into a ``BAD_FRAME`` measurement, so it never
    stops a run.
    """
    t0 = time.perf_counter()
    try:
        motion = measure(image, float(timestamp))
    except cv2.error as exc:
        logger.warning("frame at t=%.6f could not be processed: %s", timestamp, exc)
        motion = fail(float(timestamp), MotionStatus.BAD_FRAME, f"OpenCV error: {exc}")
    motion.info["time_ms"] = (time.perf_counter() - t0) * 1e3
    return motion
