"""Pyramidal Lucas-Kanade frontend with track-and-replenish and motion prediction.

Each frame, the points kept from the reference (previous good) frame are tracked into the new frame by
pyramidal Lucas-Kanade, which minimises for each point the windowed intensity difference

.. math::  \\sum_{x \\in W} \\big(I_1(x + d) - I_0(x)\\big)^2

over the displacement ``d`` by Gauss-Newton, coarse to fine. The tracker starts from a *prediction*:
the last measured similarity continued over the new time gap (constant velocity,
:func:`frontends.similarity.scale_motion`), mapped rectified -> image through the point map. So a
robot moving 120 px per frame is followed as long as its speed changes by less than the pyramid's
capture range from one frame to the next. If tracking from the prediction fails, it is retried from
zero motion, and last from a coarse global translation found by phase correlation of the images
reduced 4 times.

A forward-backward check tracks every point back from where it landed, starting from the same
prediction, and drops points that do not return within ``fb_threshold``. The similarity is
estimated on the rectified coordinates of the surviving points (RANSAC or LMedS, then least squares
on the inliers, :mod:`frontends.similarity`). At zero motion the tracker starts at the true position
and Lucas-Kanade converges to ``d = 0`` (no drift).

Only the inlier points are carried to the next frame; new Shi-Tomasi corners (minimum eigenvalue of
the structure tensor, ``cv2.goodFeaturesToTrack`` on the half-resolution image) are added only when
fewer than ``replenish_below`` remain, away from existing tracks.

Failures: a frame that cannot be measured leaves the reference unchanged, so the next frame is
measured against the last good frame (the motion then spans the gap). After ``max_failures``
consecutive failures the tracker restarts: the current frame, if it has texture, becomes the new
reference and the prediction is dropped.
"""

from __future__ import annotations

from concurrent.futures import Executor
from dataclasses import dataclass

import cv2
import numpy as np

from frontends.base import FrameMotion, IdentityMap, MotionStatus, PointMap
from frontends.corners import CornerPlan, new_corners, plan_corners
from frontends.direct import dense_fallback
from frontends.frame_check import check_frame, grey8, texture_measure
from frontends.klt_config import KltConfig
from frontends.klt_setup import Ahead, PreparedFrame, Setup, global_shift, make_setup, set_up_ahead
from frontends.prediction import MotionHistory, failed_motion, timed_measurement
from frontends.similarity import SimilarityFit, estimate_similarity, judge_fit
from frontends.tracking import (WARP_HERE, check_backward, exposure_correction, fit_affine, reduce_for_exposure,
                                track_forward)

__all__ = ["KltConfig", "KltFrontend", "PreparedFrame", "global_shift"]


@dataclass
class _Attempt:
    """One tracking attempt from a given initial guess."""

    path: str
    fit: SimilarityFit | None
    status: MotionStatus
    reason: str
    n_tracked: int = 0
    next_pts: np.ndarray | None = None  # current-frame positions of the fit's inliers


class KltFrontend:
    """Frame-to-frame similarity from Lucas-Kanade point tracks.

    Parameters
    ----------
    config : KltConfig, optional
    point_map : PointMap, optional
        Raw pixel <-> rectified coordinates (identity when omitted).
    """

    def __init__(self, config: KltConfig | None = None, point_map: PointMap | None = None):
        self.config = config or KltConfig()
        self.point_map = point_map if point_map is not None else IdentityMap()
        self._options = self.config.robust_options()
        self._rng = np.random.default_rng(self.config.seed)
        self._lk = self.config.lk_settings()
        self._hann: np.ndarray | None = None
        self._shape: tuple[int, int] | None = None
        self._dense = dense_fallback(self.point_map, self.config)
        self._corner_plan: tuple[tuple[int, int], CornerPlan] | None = None
        self._executor: Executor | None = None
        self._next_t: float | None = None
        self.reset()

    def set_executor(self, executor: Executor | None) -> None:
        """Let the frontend set up the next frame's tracking in ``executor`` (``None``: never).

        After a measured frame, when the next frame's timestamp is known (:meth:`expect`), the
        rectified reference points, the predicted motion as an image-space map and the reference warped
        by it are computed in ``executor`` while the caller goes on; the next :meth:`process` uses them
        when nothing changed meanwhile. The results are the same as without an executor.
        """
        self._executor = executor
        self._ahead = None

    def expect(self, timestamp: float | None) -> None:
        """The timestamp of the frame that the next :meth:`process` call will most likely get (a hint)."""
        self._next_t = timestamp

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget the reference frame and the motion prediction."""
        self._ref_img: np.ndarray | None = None
        self._ref_pts = np.zeros((0, 2), np.float32)
        self._ref_time: float | None = None
        self._history = MotionHistory(self.config.max_prediction_gap, self.config.max_failures)
        self._ref_texture: float | None = None
        self._ref_small: np.ndarray | None = None  # reduced reference for the exposure comparison
        self._cur_texture = float("nan")
        self._cur_small: np.ndarray | None = None
        self._ahead: Ahead | None = None

    # ------------------------------------------------------------ public API
    def process(self, image: np.ndarray | PreparedFrame, timestamp: float) -> FrameMotion:
        """Measure the motion from the reference frame to ``image`` (see :mod:`frontends.base`).

        ``image`` may also be the :meth:`prepare`-d frame; the result is the same.
        """
        return timed_measurement(self._process, self._failed, image, timestamp)

    @staticmethod
    def prepare(image: np.ndarray) -> PreparedFrame | np.ndarray:
        """The per-frame work that does not depend on earlier frames, for a thread ahead of :meth:`process`.

        Thread-safe (it reads no state). Measures the texture and reduces the frame for the exposure
        comparison; a frame that is not a 2-D ``uint8``/``uint16`` array is returned as it is (the
        checks of :meth:`process` report it).
        """
        grey = grey8(image, 8)
        if grey is None:
            return image
        try:
            return PreparedFrame(image, texture_measure(grey), reduce_for_exposure(grey))
        except cv2.error:  # left to process(), which reports it for this frame
            return image

    # -------------------------------------------------------------- pipeline
    def _process(self, image: np.ndarray | PreparedFrame, t: float) -> FrameMotion:
        cfg = self.config
        prepared = image if isinstance(image, PreparedFrame) else None
        if prepared is not None:
            image = prepared.image
        check = check_frame(image, self._shape, cfg.min_texture, self._ref_texture, cfg.min_texture_ratio,
                            texture=None if prepared is None else prepared.texture)
        if check.status is not None:
            dense = self._dense_motion(check.image, t, check.texture, check.reason) if check.image is not None else None
            return dense or self._failed(t, check.status, check.reason, texture=check.texture)
        img = check.image
        self._cur_texture = check.texture
        self._cur_small = reduce_for_exposure(img) if prepared is None else prepared.small
        if self._ref_img is None:
            self._shape = img.shape
            self._set_reference(img, t, np.zeros((0, 2), np.float32))
            return FrameMotion(t, None, status=MotionStatus.FIRST, n_features=len(self._ref_pts), info={"path": "first"})
        dt = t - self._ref_time
        if not dt > 0.0:
            return self._failed(t, MotionStatus.BAD_FRAME, f"timestamp {t} not after reference {self._ref_time}")
        if len(self._ref_pts) < cfg.min_inliers:
            dense = self._dense_motion(img, t, check.texture, "too few corners in the reference frame")
            if dense is not None:
                return dense
            self._set_reference(img, t, np.zeros((0, 2), np.float32))
            return self._failed(t, MotionStatus.TOO_FEW_FEATURES, "too few corners in the reference frame")

        attempts: list[_Attempt] = []
        prediction = self._history.predict(dt)
        ahead = self._take_ahead(prediction)
        if ahead is not None:
            ref_rect, setup = ahead
        else:
            ref_rect = self.point_map.to_rectified(self._ref_pts.astype(np.float64))
            setup = WARP_HERE
        if prediction is not None:
            attempts.append(self._attempt("predicted", img, ref_rect, prediction, cfg.pyramid_levels, setup))
        if not attempts or attempts[-1].status is not MotionStatus.OK:
            attempts.append(self._attempt("retry", img, ref_rect, np.eye(2, 3), cfg.retry_pyramid_levels))
        if attempts[-1].status is not MotionStatus.OK and cfg.global_fallback:
            shift = self._global_shift(img)
            if shift is not None:
                guess = np.array([[1.0, 0.0, shift[0]], [0.0, 1.0, shift[1]]])
                attempts.append(self._attempt("global", img, ref_rect, guess, cfg.retry_pyramid_levels))

        best = attempts[-1]
        info = {
            "path": best.path,
            "attempts": [a.path for a in attempts],
            "n_tracked": best.n_tracked,
            "texture": check.texture,
        }
        if best.status is not MotionStatus.OK:
            reasons = "; ".join(f"{a.path}: {a.reason}" for a in attempts)
            dense = self._dense_motion(img, t, check.texture, reasons)
            if dense is not None:
                return dense
            motion = self._failed(t, best.status, reasons, texture=check.texture, current=img)
            motion.info.update(info)
            if best.fit is not None:
                motion.n_candidates, motion.n_inliers = best.n_tracked, best.fit.n_inliers
            return motion

        fit = best.fit
        motion = FrameMotion(
            timestamp=t,
            prev_timestamp=self._ref_time,
            matrix=fit.matrix.copy(),
            covariance=fit.covariance.copy(),
            status=MotionStatus.OK,
            n_candidates=best.n_tracked,
            n_inliers=fit.n_inliers,
            residual_rms=fit.residual_rms,
            n_features=len(best.next_pts),
            info=info,
        )
        if self._dense is not None and fit.n_inliers < cfg.verify_below:
            checked = self._dense.verify(self._ref_img, img, motion, cfg.verify_tolerance)
            if checked is not None:
                checked.info["texture"] = check.texture
                self._history.succeeded(checked.matrix, dt)
                self._set_reference(img, t, np.zeros((0, 2), np.float32))
                return checked
        self._history.succeeded(fit.matrix, dt)
        self._set_reference(img, t, best.next_pts)
        self._start_ahead(t)
        return motion

    def _start_ahead(self, t: float) -> None:
        """Set up the next frame's predicted attempt in the executor (when there is one and a hint)."""
        if self._executor is None or self._next_t is None or not self._next_t > t:
            return
        prediction = self._history.predict(self._next_t - t)
        if prediction is None:
            return
        cfg = self.config
        future = self._executor.submit(set_up_ahead, self.point_map, self._ref_img, self._ref_pts, prediction,
                                       cfg.border, cfg.min_inliers, cfg.warp_tolerance)
        self._ahead = Ahead(self._ref_img, self._ref_pts, prediction, future)

    def _take_ahead(self, prediction: np.ndarray | None) -> tuple[np.ndarray, Setup | None] | None:
        """The set-up made ahead for this frame, when it was made for this state; consumed either way."""
        ahead, self._ahead = self._ahead, None
        if ahead is None or prediction is None or ahead.ref_img is not self._ref_img \
                or ahead.ref_pts is not self._ref_pts or not np.array_equal(ahead.prediction, prediction):
            return None
        return ahead.future.result()

    def _dense_motion(self, img: np.ndarray, t: float, texture: float, why: str) -> FrameMotion | None:
        """The per-frame dense fallback (``None`` when disabled or when it fails too)."""
        if self._dense is None or self._ref_img is None or self._ref_img.shape != img.shape:
            return None
        dt = t - self._ref_time
        if not dt > 0.0:
            return None
        motion = self._dense.motion(self._ref_img, img, t, self._ref_time, self._history.predict(dt), texture, why,
                                   self.config.min_texture)
        if motion is None:
            return None
        self._cur_texture = texture
        self._cur_small = reduce_for_exposure(img)
        self._history.succeeded(motion.matrix, dt)
        self._set_reference(img, t, np.zeros((0, 2), np.float32))
        motion.n_features = len(self._ref_pts)
        return motion

    def _attempt(self, path: str, img: np.ndarray, ref_rect: np.ndarray, guess: np.ndarray, levels: int,
                 setup: Setup | None | object = WARP_HERE) -> _Attempt:
        """Track the reference points from the rectified similarity ``guess`` and fit a similarity.

        The guess is turned into an image-space affine map ``A`` (least squares through the point
        map). When ``A`` rotates or scales, the reference image is warped by ``A`` first, so that
        Lucas-Kanade's translation-only model meets undeformed patches (tracking a rotated patch
        biases the measured rotation by a fraction of a percent). If the fitted motion then differs
        from ``A`` by more than ``refine_tolerance``, the points are tracked once more through the
        fitted motion at full resolution.

        ``setup`` is this attempt's :class:`Setup` when it was made ahead (``None``: too few points in
        view), ``WARP_HERE`` to make it here.
        """
        cfg = self.config
        if setup is WARP_HERE:
            setup = make_setup(self.point_map, self._ref_pts, ref_rect, guess, img.shape, cfg.border, cfg.min_inliers)
        if setup is None:
            return _Attempt(path, None, MotionStatus.TOO_FEW_FEATURES, "prediction leaves too few points in view")
        p0, src, affine = setup.p0, setup.src, setup.affine
        outcome = self._track(img, p0, src, affine, levels, warped=setup.warped)
        if isinstance(outcome, _Attempt):
            outcome.path = path
            return outcome
        fit, p1, n_tracked, keep = outcome
        refined = fit_affine(p0[keep][fit.inliers], p1[fit.inliers])
        exposure = exposure_correction(self._ref_small, self._cur_small, refined, cfg.exposure_tolerance)
        if exposure != (1.0, 0.0) or np.abs(refined[:, :2] - affine[:, :2]).max() > cfg.refine_tolerance:
            outcome2 = self._track(img, p0, src, refined, 0, exposure)
            if not isinstance(outcome2, _Attempt):
                fit, p1, n_tracked, keep = outcome2
        return self._judge(path, fit, n_tracked, p1)

    def _track(self, img, p0, src, affine, levels, exposure=(1.0, 0.0), warped=WARP_HERE):
        """Tracking from ``affine(p0)`` and a robust fit; an ``_Attempt`` on failure."""
        cfg = self.config
        forward = track_forward(self._ref_img, img, p0, affine, levels, self._lk, exposure=exposure, warped=warped)
        tr = forward.result
        if cfg.forward_backward and cfg.fb_skip_ratio is not None and len(tr.index) >= cfg.min_inliers:
            # the backward check only when the forward tracks do not agree on one motion
            fit = estimate_similarity(src[tr.index], self.point_map.to_rectified(tr.points), self._options, self._rng)
            if fit.status == "ok" and fit.n_inliers >= cfg.fb_skip_ratio * len(tr.index) and \
                    judge_fit(fit, tr.n_tracked, cfg.min_inlier_ratio, cfg.max_abs_log_scale)[0] is MotionStatus.OK:
                return fit, tr.points, tr.n_tracked, tr.index
        if cfg.forward_backward:
            tr = check_backward(forward, self._lk)
        if len(tr.index) < cfg.min_inliers:
            why = "too few points tracked" if tr.n_tracked < cfg.min_inliers else "too few points pass the forward-backward check"
            return _Attempt("", None, MotionStatus.TOO_FEW_FEATURES, why, tr.n_tracked)
        fit = estimate_similarity(src[tr.index], self.point_map.to_rectified(tr.points), self._options, self._rng)
        if fit.status != "ok":
            return self._judge("", fit, tr.n_tracked, tr.points)
        return fit, tr.points, tr.n_tracked, tr.index

    def _judge(self, path: str, fit: SimilarityFit, n_tracked: int, p1: np.ndarray) -> _Attempt:
        """Turn a fit into an accepted or failed attempt."""
        status, reason = judge_fit(fit, n_tracked, self.config.min_inlier_ratio, self.config.max_abs_log_scale)
        if status is not MotionStatus.OK:
            return _Attempt(path, fit, status, reason, n_tracked)
        return _Attempt(path, fit, MotionStatus.OK, "", n_tracked, p1[fit.inliers].astype(np.float32))

    def _global_shift(self, img: np.ndarray) -> tuple[float, float] | None:
        """Coarse translation (image px) of ``img`` against the reference by phase correlation."""
        shift, self._hann = global_shift(self._ref_img, img, self.config, self._hann)
        return shift

    # ------------------------------------------------------------ references
    def _set_reference(self, img: np.ndarray, t: float, pts: np.ndarray) -> None:
        self._ref_img, self._ref_time = img, t
        self._ref_texture = self._cur_texture
        self._ref_small = self._cur_small
        pts = np.asarray(pts, np.float32).reshape(-1, 2)
        plan = self._plan(img.shape)
        if self.config.region < 1.0:
            pts = pts[plan.inside(pts)]
        if len(pts) < plan.replenish_below:
            pts = np.vstack([pts, self._detect(img, pts)])
        self._ref_pts = pts

    def _plan(self, shape: tuple[int, int]) -> CornerPlan:
        """The corner settings in effect for frames of ``shape`` (:func:`frontends.corners.plan_corners`)."""
        if self._corner_plan is None or self._corner_plan[0] != shape:
            cfg = self.config
            if cfg.adaptive_corners:
                plan = plan_corners(shape, cfg.min_distance, cfg.block_size, cfg.border, cfg.max_tracks,
                                    cfg.replenish_below, cfg.region)
            else:
                h, w = shape
                plan = CornerPlan(1.0, cfg.min_distance, cfg.block_size, cfg.border, cfg.max_tracks,
                                  cfg.replenish_below, (cfg.border, cfg.border, w - cfg.border, h - cfg.border))
            self._corner_plan = (shape, plan)
        return self._corner_plan[1]

    def _detect(self, img: np.ndarray, existing: np.ndarray) -> np.ndarray:
        """New Shi-Tomasi corners away from ``existing`` points (:func:`frontends.corners.new_corners`): the
        spacing, block size and count follow the image size, the quality level may be lowered when too few
        corners come back, and the corners may be spread over a grid."""
        cfg = self.config
        adaptive = cfg.adaptive_corners
        min_quality = cfg.min_quality_level if adaptive and cfg.min_quality_level is not None else cfg.quality_level
        return new_corners(img, existing, self._plan(img.shape), cfg.window // 4 + 1, cfg.quality_level, min_quality,
                           cfg.min_inliers, cfg.grid_cell if adaptive else 0.0)

    def _failed(self, t: float, status: MotionStatus, reason: str, texture: float = float("nan"), current=None) -> FrameMotion:
        """A failed measurement; restarts from ``current`` after too many failures in a row."""
        restarted = self._history.failed(can_restart=current is not None)
        if restarted:
            self._set_reference(current, t, np.zeros((0, 2), np.float32))
        return failed_motion(t, None if restarted else self._ref_time, status, reason, texture, restarted)

