"""Direct frontend: whole-image photometric alignment of a similarity, coarse to fine.

No corners, no matches: every pixel with a gradient votes (:mod:`frontends.photometric`, on the
rectified, normalised pyramids of :mod:`frontends.pyramid`). :class:`DirectFrontend` measures each
frame against the last good one, starting from the constant-velocity prediction
(:mod:`frontends.prediction`); a frame with too little texture or too many clipped pixels is not
measured. :class:`DenseFallback` gives the point-based frontends the same alignment for the frames
their points cannot measure, and checks their estimates made from few points.
"""

from __future__ import annotations

import logging

import numpy as np

from frontends.base import FrameMotion, IdentityMap, MotionStatus, PointMap
from frontends.direct_config import DirectConfig
from frontends.frame_check import check_frame
from frontends.options import PointSettings
from frontends.photometric import Alignment, DirectAligner
from frontends.prediction import MotionHistory, failed_motion, timed_measurement
from frontends.pyramid import Level, clipped_fraction

__all__ = ["Alignment", "DenseFallback", "DirectAligner", "DirectConfig", "DirectFrontend", "clipped_fraction",
           "dense_fallback"]

logger = logging.getLogger(__name__)


class DirectFrontend:
    """Frame-to-frame similarity by whole-image photometric alignment (see the module description).

    Parameters
    ----------
    config : DirectConfig, optional
    point_map : PointMap, optional
        Raw pixel <-> rectified coordinates (identity when omitted).
    """

    def __init__(self, config: DirectConfig | None = None, point_map: PointMap | None = None):
        self.config = config or DirectConfig()
        self.point_map = point_map if point_map is not None else IdentityMap()
        self.aligner = DirectAligner(self.config, self.point_map)
        self._shape: tuple[int, int] | None = None
        self.reset()

    def reset(self) -> None:
        """Forget the reference frame and the motion prediction."""
        self._ref: list[Level] | None = None
        self._ref_time: float | None = None
        self._ref_texture: float | None = None
        self._history = MotionHistory(self.config.max_prediction_gap, self.config.max_failures)

    def process(self, image: np.ndarray, timestamp: float) -> FrameMotion:
        """Measure the motion from the reference frame to ``image`` (see :mod:`frontends.base`)."""
        return timed_measurement(self._process, self._failed, image, timestamp)

    def _process(self, image: np.ndarray, t: float) -> FrameMotion:
        cfg = self.config
        check = check_frame(image, self._shape, cfg.min_texture, self._ref_texture, cfg.min_texture_ratio)
        if check.status is not None:
            return self._failed(t, check.status, check.reason, check.texture)
        img = check.image
        clipped = clipped_fraction(img)
        if clipped > cfg.max_clipped:
            return self._failed(t, MotionStatus.TOO_FEW_FEATURES, f"{100 * clipped:.0f} % of the pixels clipped",
                                check.texture)
        levels = self.aligner.prepare(img)
        if self._ref is None:
            self._shape = img.shape
            self._set_reference(levels, t, check.texture)
            return FrameMotion(t, None, status=MotionStatus.FIRST, info={"path": "first"})
        dt = t - self._ref_time
        if not dt > 0.0:
            return self._failed(t, MotionStatus.BAD_FRAME, f"timestamp {t} not after reference {self._ref_time}")
        guesses = []
        prediction = self._history.predict(dt)
        if prediction is not None:
            guesses.append(("predicted", prediction))
        result = self.aligner.align(self._ref, levels, guesses)
        info = {"path": result.start, "start": result.start, "correlation": result.correlation,
                "overlap": result.overlap, "texture": check.texture}
        if result.status is not MotionStatus.OK:
            motion = self._failed(t, result.status, result.reason, check.texture, current=(levels, check.texture))
            motion.info.update(info)
            return motion
        motion = FrameMotion(t, self._ref_time, matrix=result.matrix, covariance=result.covariance,
                             status=MotionStatus.OK, info=info)
        self._history.succeeded(result.matrix, dt)
        self._set_reference(levels, t, check.texture)
        return motion

    def _set_reference(self, levels: list[Level], t: float, texture: float) -> None:
        self._ref, self._ref_time, self._ref_texture = levels, t, texture

    def _failed(self, t: float, status: MotionStatus, reason: str, texture: float = float("nan"),
                current=None) -> FrameMotion:
        restarted = self._history.failed(can_restart=current is not None)
        if restarted:
            self._set_reference(current[0], t, current[1])
        return failed_motion(t, None if restarted else self._ref_time, status, reason, texture, restarted)


class DenseFallback:
    """Per-frame dense fallback for the point-based frontends: aligns two raw frames directly.

    Parameters
    ----------
    point_map : PointMap
    config : DirectConfig, optional
    """

    def __init__(self, point_map: PointMap, config: DirectConfig | None = None):
        self.aligner = DirectAligner(config or DirectConfig(), point_map)
        self._cache: tuple[int, list[Level]] | None = None

    def _levels(self, image: np.ndarray) -> list[Level]:
        key = id(image)
        if self._cache is not None and self._cache[0] == key and self._cache[2] is image:  # the last current frame
            return self._cache[1]
        levels = self.aligner.prepare(image)
        self._cache = (key, levels, image)
        return levels

    def motion(self, ref: np.ndarray, cur: np.ndarray, t: float, ref_time: float, prediction: np.ndarray | None,
               texture: float, why: str, min_texture: float = 0.0) -> FrameMotion | None:
        """An accepted :class:`FrameMotion` from ``ref`` (at ``ref_time``) to ``cur`` (at ``t``), or ``None``.

        ``why`` (the point-based failure) is kept in ``info["point_failure"]``. A frame whose texture
        is below ``min_texture`` (the calling frontend's own limit) or this fallback's is not tried: on
        a flat floor the only structure left is fixed in the image (noise pattern, highlight), and an
        alignment would lock onto it and report a standstill.
        """
        cfg = self.aligner.config
        if not texture >= max(cfg.min_texture, min_texture) or clipped_fraction(cur) > cfg.max_clipped:
            return None
        result = self.measure(ref, cur, prediction)
        if result.status is not MotionStatus.OK:
            logger.debug("dense fallback at t=%.6f failed too: %s", t, result.reason)
            return None
        info = {"path": "dense", "point_failure": why, "start": result.start, "correlation": result.correlation,
                "texture": texture}
        return FrameMotion(t, ref_time, matrix=result.matrix, covariance=result.covariance, status=MotionStatus.OK,
                           info=info)

    def verify(self, ref: np.ndarray, cur: np.ndarray, motion: FrameMotion, tolerance: float) -> FrameMotion | None:
        """Check a point-based ``motion`` against a dense alignment started from it.

        Few points on a coarse pattern can all slide along the same edges (the aperture problem) and
        agree on a wrong motion. The dense alignment, started from that motion, is decisive when it is
        sure of itself: when its correlation after alignment reaches ``min_correlation`` (the level at
        which the aligner accepts a start without trying others) and it moves any image corner by more
        than ``tolerance`` px from where the points put it, its result replaces the points'
        (``info["path"] = "dense"``); otherwise ``None`` (the points stand). A weaker alignment does not
        overrule points that passed the robust fit: on a frame coming out of a featureless stretch
        (little texture, blur, the fixed vignetting and highlight) it can slide into a wrong minimum.
        """
        result = self.measure(ref, cur, motion.matrix)
        if result.status is not MotionStatus.OK:
            return None
        h, w = cur.shape
        corners = np.array([[0.0, 0.0], [w - 1.0, 0.0], [0.0, h - 1.0], [w - 1.0, h - 1.0]])
        a = corners @ motion.matrix[:, :2].T + motion.matrix[:, 2]
        b = corners @ result.matrix[:, :2].T + result.matrix[:, 2]
        moved = float(np.max(np.linalg.norm(a - b, axis=1)))
        if moved <= tolerance:
            return None
        if not result.correlation >= self.aligner.config.min_correlation:
            logger.debug("t=%.6f: dense alignment moves the points' estimate by %.2f px at correlation %.2f only; "
                         "the points stand", motion.timestamp, moved, result.correlation)
            return None
        logger.debug("t=%.6f: dense alignment moves the points' estimate by %.2f px at correlation %.2f; using it",
                     motion.timestamp, moved, result.correlation)
        info = {"path": "dense", "point_failure": f"points disagree with the dense alignment by {moved:.1f} px",
                "start": result.start, "correlation": result.correlation}
        return FrameMotion(motion.timestamp, motion.prev_timestamp, matrix=result.matrix,
                           covariance=result.covariance, status=MotionStatus.OK, n_features=motion.n_features,
                           info=info)

    def measure(self, ref: np.ndarray, cur: np.ndarray, prediction: np.ndarray | None) -> Alignment:
        """The similarity from ``ref`` to ``cur`` (raw ``uint8`` frames of the same size)."""
        guesses = [("predicted", prediction)] if prediction is not None else []
        ref_levels = self._levels(ref)
        cur_levels = self.aligner.prepare(cur)
        self._cache = (id(cur), cur_levels, cur)
        return self.aligner.align(ref_levels, cur_levels, guesses)


def dense_fallback(point_map: PointMap, settings: PointSettings) -> DenseFallback | None:
    """The dense fallback of a point-based frontend with ``settings`` (``None`` when they turn it off): the
    direct alignment's defaults, on the same ``central_region``."""
    if not settings.dense_fallback:
        return None
    return DenseFallback(point_map, DirectConfig(central_region=settings.central_region))
