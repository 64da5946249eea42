"""Feature frontend: corners, descriptors, matching and a robust similarity (thesis chapter 4).

Per frame:

1. detect corners (Harris, Shi-Tomasi or FAST; :mod:`frontends.detectors`) and describe them
   (normalised patches or ORB; :mod:`frontends.descriptors`);
2. match them to the previous frame's corners (threshold, nearest neighbour or distance ratio, with an
   optional mutual check; :mod:`frontends.matching`). When a motion prediction exists (the last
   measured similarity continued over the new time gap) a current corner may only match a previous
   corner whose predicted position lies within ``gate_radius``; if that fails, matching is retried
   without the gate;
3. estimate the similarity on the rectified coordinates of the matches by RANSAC or LMedS followed by
   least squares on the inliers (:mod:`frontends.similarity`);
4. refine (``refine="lk"``): corner positions are only repeatable to a few tenths of a pixel, so the
   inlier corners of the previous frame are located in the current frame by Lucas-Kanade through the
   fitted motion (:func:`frontends.tracking.track_points`, area-based matching at full resolution)
   and the similarity is fitted again. ``refine="subpix"`` instead moves both corner sets to their
   sub-pixel gradient-orthogonality positions; ``"none"`` keeps whole-pixel corners.

Failures leave the reference (last good frame) unchanged; after ``max_failures`` consecutive
failures the current frame, if textured, becomes the new reference (restart).
"""

from __future__ import annotations

import dataclasses
import threading
from concurrent.futures import Executor
from dataclasses import dataclass, field

import cv2
import numpy as np

from frontends.base import FrameMotion, IdentityMap, MotionStatus, PointMap
from frontends.corners import scale_detector
from frontends.descriptors import distance_matrix, orb_descriptors, patch_descriptors
from frontends.detectors import detect_corners
from frontends.direct import dense_fallback
from frontends.features_config import FeatureConfig
from frontends.frame_check import Prepared, check_frame, grey8, texture_measure
from frontends.matching import gate_distances, match_descriptors
from frontends.prediction import MotionHistory, failed_motion, timed_measurement
from frontends.similarity import apply_similarity, estimate_similarity, judge_fit
from frontends.tracking import (WARP_HERE, LkSettings, exposure_correction, fit_affine, reduce_for_exposure,
                                track_points, warp_reference)

__all__ = ["FeatureConfig", "FeatureFrontend", "PreparedFrame"]


@dataclass
class _Frame:
    image: np.ndarray
    time: float
    pts: np.ndarray  # corners with a descriptor (raw image coordinates)
    desc: np.ndarray
    rect: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    texture: float = float("nan")
    small: np.ndarray | None = None  # reduced copy for the exposure comparison


@dataclass
class PreparedFrame(Prepared):
    """A frame prepared by :meth:`FeatureFrontend.prepare`.

    Attributes
    ----------
    described : _Frame
        Corners, descriptors, rectified positions and the exposure thumbnail (time not yet set).
    """

    described: _Frame


class FeatureFrontend:
    """Frame-to-frame similarity from matched corners.

    Parameters
    ----------
    config : FeatureConfig, optional
    point_map : PointMap, optional
        Raw pixel <-> rectified coordinates (identity when omitted).
    """

    def __init__(self, config: FeatureConfig | None = None, point_map: PointMap | None = None):
        self.config = config or FeatureConfig()
        self.point_map = point_map if point_map is not None else IdentityMap()
        cfg = self.config
        self._detector = cfg.detector_settings()
        self._coarse = cfg.robust_options(cfg.threshold)
        self._fine = cfg.robust_options(cfg.refine_threshold)
        self._lk = LkSettings(window=cfg.window, fb_threshold=cfg.fb_threshold, border=2)
        self._rng = np.random.default_rng(cfg.seed)
        # an ORB object per thread: prepare() may run in several threads at once (cv2.ORB is not thread-safe)
        self._orb_local = threading.local()
        self._executor: Executor | None = None
        self._shape: tuple[int, int] | None = None
        self._dense = dense_fallback(self.point_map, cfg)
        self.reset()

    def set_executor(self, executor: Executor | None) -> None:
        """Let the frontend warp the reference for the refinement in ``executor`` (``None``: never), while
        it measures the exposure change in the calling thread. The results are the same without it."""
        self._executor = executor

    def reset(self) -> None:
        """Forget the reference frame and the motion prediction."""
        self._ref: _Frame | None = None
        self._history = MotionHistory(self.config.max_prediction_gap, self.config.max_failures)

    def process(self, image: np.ndarray | PreparedFrame, timestamp: float) -> FrameMotion:
        """Measure the motion from the reference frame to ``image`` (see :mod:`frontends.base`).

        ``image`` may also be the :meth:`prepare`-d frame; the result is the same.
        """
        return timed_measurement(self._process, self._failed, image, timestamp)

    def prepare(self, image: np.ndarray) -> PreparedFrame | np.ndarray:
        """Corners and descriptors of a frame, for a thread ahead of :meth:`process` (they do not
        depend on earlier frames).

        Thread-safe: it may run in several threads at once while :meth:`process` runs (it reads only
        the configuration and the point map, and every thread gets its own ORB object). A frame that
        is not a 2-D ``uint8``/``uint16`` array, or that OpenCV refuses, is returned as it is (the
        checks of :meth:`process` report it).
        """
        grey = grey8(image, 32)
        if grey is None:
            return image
        try:
            return PreparedFrame(image, texture_measure(grey), self._describe(grey, float("nan")))
        except cv2.error:
            return image

    # -------------------------------------------------------------- pipeline
    def _thread_orb(self) -> cv2.ORB:
        """The calling thread's ORB object (made on first use)."""
        orb = getattr(self._orb_local, "orb", None)
        if orb is None:
            orb = cv2.ORB_create(nfeatures=self.config.max_corners, edgeThreshold=16, patchSize=31)
            self._orb_local.orb = orb
        return orb

    def _describe(self, img: np.ndarray, t: float) -> _Frame:
        settings = scale_detector(self._detector, img) if self.config.adaptive_detector else self._detector
        pts = detect_corners(img, settings)
        if self.config.region < 1.0:
            h, w = img.shape
            half = 0.5 * self.config.region * np.array([w, h], np.float32)
            centre = 0.5 * np.array([w - 1, h - 1], np.float32)
            pts = pts[np.all(np.abs(pts - centre) <= half, axis=1)]
        if self.config.descriptor == "orb":
            desc, idx = orb_descriptors(img, pts, self._thread_orb())
        else:
            desc, idx = patch_descriptors(img, pts, self.config.patch_radius)
        pts = pts[idx]
        rect = self.point_map.to_rectified(pts.astype(np.float64))
        return _Frame(img, t, pts, desc, rect, small=reduce_for_exposure(img))

    def _process(self, image: np.ndarray | PreparedFrame, t: float) -> FrameMotion:
        cfg = self.config
        prepared = image if isinstance(image, PreparedFrame) else None
        if prepared is not None:
            image = prepared.image
        ref_texture = None if self._ref is None else self._ref.texture
        check = check_frame(image, self._shape, cfg.min_texture, ref_texture, cfg.min_texture_ratio,
                            texture=None if prepared is None else prepared.texture)
        if check.status is not None:
            dense = self._dense_motion(check.image, t, check.texture, check.reason) if check.image is not None else None
            return dense or self._failed(t, check.status, check.reason, texture=check.texture)
        img = check.image
        if self._ref is not None and not t > self._ref.time:
            return self._failed(t, MotionStatus.BAD_FRAME, f"timestamp {t} not after reference {self._ref.time}")
        cur = self._describe(img, t) if prepared is None else dataclasses.replace(prepared.described, time=t)
        cur.texture = check.texture
        if self._ref is None:
            self._shape = img.shape
            self._ref = cur
            return FrameMotion(t, None, status=MotionStatus.FIRST, n_features=len(cur.pts), info={"path": "first"})
        ref = self._ref
        if len(ref.pts) < cfg.min_inliers or len(cur.pts) < cfg.min_inliers:
            dense = self._dense_motion(img, t, check.texture, "too few corners", cur)
            if dense is not None:
                return dense
            return self._failed(t, MotionStatus.TOO_FEW_FEATURES, "too few corners", check.texture, cur)

        dt = t - ref.time
        dist = distance_matrix(ref.desc, cur.desc, cfg.descriptor)
        prediction = self._history.predict(dt)
        results = []
        if prediction is not None and cfg.gate_radius > 0:
            predicted = self.point_map.to_image(apply_similarity(prediction, ref.rect))
            gated = gate_distances(dist, predicted, cur.pts, cfg.gate_radius)
            results.append(self._attempt("predicted", gated, ref, cur))
        if not results or results[-1][1] is not MotionStatus.OK:
            results.append(self._attempt("retry", dist, ref, cur))
        path, status, fit, n_matches, reason = results[-1]
        info = {"path": path, "attempts": [r[0] for r in results], "n_matches": n_matches, "texture": check.texture}
        if status is not MotionStatus.OK:
            why = "; ".join(f"{r[0]}: {r[4]}" for r in results)
            dense = self._dense_motion(img, t, check.texture, why, cur)
            if dense is not None:
                return dense
            motion = self._failed(t, status, why, check.texture, cur)
            motion.info.update(info)
            motion.n_candidates = n_matches
            motion.n_inliers = fit.n_inliers if fit is not None else 0
            return motion
        motion = FrameMotion(
            timestamp=t, prev_timestamp=ref.time, matrix=fit.matrix.copy(), covariance=fit.covariance.copy(),
            status=MotionStatus.OK, n_candidates=n_matches, n_inliers=fit.n_inliers,
            residual_rms=fit.residual_rms, n_features=len(cur.pts), info=info,
        )
        if self._dense is not None and fit.n_inliers < cfg.verify_below:
            checked = self._dense.verify(ref.image, img, motion, cfg.verify_tolerance)
            if checked is not None:
                checked.info["texture"] = check.texture
                motion = checked
        self._history.succeeded(motion.matrix, dt)
        self._ref = cur
        return motion

    def _dense_motion(self, img: np.ndarray, t: float, texture: float, why: str,
                      cur: _Frame | None = None) -> FrameMotion | None:
        """The per-frame dense fallback (``None`` when disabled or when it fails too)."""
        ref = self._ref
        if self._dense is None or ref is None or ref.image.shape != img.shape or not t > ref.time:
            return None
        dt = t - ref.time
        motion = self._dense.motion(ref.image, img, t, ref.time, self._history.predict(dt), texture, why,
                                   self.config.min_texture)
        if motion is None:
            return None
        if cur is None:
            cur = self._describe(img, t)
        cur.texture = texture
        self._history.succeeded(motion.matrix, dt)
        self._ref = cur
        motion.n_features = len(cur.pts)
        return motion

    def _attempt(self, path: str, dist: np.ndarray, ref: _Frame, cur: _Frame):
        """Match, fit and refine; returns ``(path, status, fit, n_matches, reason)``."""
        cfg = self.config
        i0, i1 = match_descriptors(dist, cfg.matcher, cfg.distance_limit, cfg.ratio, cfg.mutual)
        n = len(i0)
        if n < cfg.min_inliers:
            return path, MotionStatus.TOO_FEW_FEATURES, None, n, f"{n} matches"
        fit = estimate_similarity(ref.rect[i0], cur.rect[i1], self._coarse, self._rng)
        status, reason = judge_fit(fit, n, cfg.min_inlier_ratio, cfg.max_abs_log_scale)
        if status is not MotionStatus.OK or cfg.refine != "lk":
            return path, status, fit, n, reason
        p0 = ref.pts[i0[fit.inliers]].astype(np.float64)
        affine = fit_affine(p0, cur.pts[i1[fit.inliers]].astype(np.float64))
        warping = None if self._executor is None else \
            self._executor.submit(warp_reference, ref.image, affine, self._lk.warp_tolerance)
        exposure = exposure_correction(ref.small, cur.small, affine, 0.01)
        tr = track_points(ref.image, cur.image, p0, affine, 1, self._lk, exposure=exposure,
                          warped=WARP_HERE if warping is None else warping.result())
        if len(tr.index) < cfg.min_inliers:
            return path, MotionStatus.TOO_FEW_FEATURES, fit, n, "refinement lost the points"
        src = ref.rect[i0[fit.inliers]][tr.index]
        fine = estimate_similarity(src, self.point_map.to_rectified(tr.points), self._fine, self._rng)
        status, reason = judge_fit(fine, n, cfg.min_inlier_ratio, cfg.max_abs_log_scale, fit.n_inliers)
        return path, status, fine, n, reason

    def _failed(self, t: float, status: MotionStatus, reason: str, texture: float = float("nan"), current=None) -> FrameMotion:
        """A failed measurement; restarts from ``current`` after too many failures in a row."""
        restarted = self._history.failed(can_restart=current is not None)
        if restarted:
            self._ref = current
        prev = None if restarted or self._ref is None else self._ref.time
        return failed_motion(t, prev, status, reason, texture, restarted)
