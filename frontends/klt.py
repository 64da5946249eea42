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

from concurrent.futures import Executor, Future
from dataclasses import dataclass
from typing import ClassVar

import cv2
import numpy as np

from frontends.base import FrameMotion, IdentityMap, MotionStatus, PointMap
from frontends.config import (AT_LEAST_0, AT_LEAST_1, FRACTION, POSITIVE, ConfigMixin, Range, check_ranges,
                              shared_ranges)
from frontends.corners import CornerPlan, grid_shape, plan_corners, spread_corners
from frontends.direct import DenseFallback, DirectConfig
from frontends.frame_check import check_frame, texture_measure
from frontends.prediction import MotionHistory, failed_motion, timed_measurement
from frontends.similarity import RobustOptions, SimilarityFit, apply_similarity, estimate_similarity, judge_fit
from frontends.tracking import (WARP_HERE, LkSettings, check_backward, exposure_correction, fit_affine,
                                reduce_for_exposure, track_forward, warp_reference)


@dataclass
class KltConfig(ConfigMixin):
    """Settings of :class:`KltFrontend` (every field has a working default).

    Attributes
    ----------
    max_tracks : int
        Number of points tracked after a replenish.
    replenish_below : int
        New corners are detected only when fewer tracks than this survive.
    quality_level : float
        Shi-Tomasi minimum eigenvalue relative to the strongest corner of the image (0-1).
    min_distance : float
        Minimum distance between tracked points [px].
    block_size : int
        Neighbourhood of the structure tensor used for corner detection [px, at half resolution].
    window : int
        Lucas-Kanade window side [px] (odd).
    pyramid_levels : int
        Pyramid levels above full resolution used when tracking from a prediction.
    retry_pyramid_levels : int
        Pyramid levels used for the zero-motion retry and the global-estimate retry.
    lk_iterations : int
        Maximum Gauss-Newton iterations per level.
    lk_epsilon : float
        Convergence threshold of the Lucas-Kanade update [px].
    min_eigen : float
        Lucas-Kanade's own minimum-eigenvalue threshold (OpenCV units): points below are dropped.
    fb_threshold : float
        Maximum forward-backward error [px].
    forward_backward : bool
        Whether to run the forward-backward check (it doubles the tracking time).
    fb_skip_ratio : float or None
        Run the forward-backward check only when it is needed: a similarity is first fitted on the
        forward tracks, and when at least this fraction of them are its inliers (and the fit is
        accepted) the check is skipped; otherwise the points are checked backward and the fit is made
        again on the survivors. ``None`` (the default): always check. Faster, less accurate on some
        recordings (``benchmarks/findings/speed.md``, "Speed").
    warp_tolerance : float
        When the guessed motion's linear part differs from the identity by more than this (largest
        element; 0.015 is about 0.86 deg or 1.5 % scale), the reference is warped by it before
        tracking. Below it the rotation bias of unwarped tracking is under 0.1 % of the angle
        (0.07 % measured at 0.4 and 0.8 deg per frame on the gravel photograph).
    refine_tolerance : float
        When the fitted motion's linear part differs from the guess by more than this, the points are
        tracked again through the fitted motion (at full resolution).
    exposure_tolerance : float
        When the brightness changed by more than this fraction between the frames (gain, or offset
        relative to 128 grey levels), the points are tracked again with the reference corrected.
    border : int
        Points closer than this to the image border are not tracked [px].
    method : str
        Robust estimator, ``"ransac"`` or ``"lmeds"``.
    threshold : float
        Inlier distance of the robust estimator [rectified px].
    confidence : float
        RANSAC confidence.
    max_iterations : int
        Maximum number of robust-estimator hypotheses.
    seed : int
        Seed of the estimator's random generator (each frontend owns its generator).
    min_sigma : float
        Floor of the residual standard deviation used for the covariance [px].
    min_inliers : int
        Fewer inliers reject the frame (``TOO_FEW_FEATURES``).
    min_inlier_ratio : float
        Fewer inliers than this fraction of the tracked points rejects the estimate.
    max_abs_log_scale : float
        Largest plausible ``|log s|`` between consecutive frames; larger is rejected.
    min_spread : float
        Smallest standard deviation of the inliers along their weakest axis [px] (``DEGENERATE``).
    min_texture_ratio : float
        A frame whose texture falls below this fraction of the reference frame's is featureless
        (sudden blur, exposure loss).
    min_texture : float
        Smallest mean neighbour difference of a usable frame [grey levels]
        (:func:`frontends.frame_check.texture_measure`).
    max_prediction_gap : float
        The prediction is continued over at most this many times the last interval.
    max_failures : int
        Consecutive failures after which the tracker restarts from the current frame.
    global_fallback : bool
        Whether to try phase correlation when both tracking attempts fail.
    global_downsample : int
        Reduction factor of the images for phase correlation.
    min_global_response : float
        Smallest phase-correlation peak response accepted.
    dense_fallback : bool
        When the points cannot measure a frame that still has texture (too few corners, too few
        inliers, points out of view, sudden blur), align the whole frames photometrically instead
        (:class:`frontends.direct.DenseFallback`); the frame is then weighted by the photometric
        covariance rather than dropped.
    verify_below : int
        A point estimate with fewer inliers than this is checked against a dense alignment started
        from it (:meth:`frontends.direct.DenseFallback.verify`), which replaces it when the two
        disagree by more than ``verify_tolerance`` px anywhere in the image (0: never checked).
    verify_tolerance : float
        See ``verify_below`` [px].
    adaptive_corners : bool
        Adapt the corner search to the image (:mod:`frontends.corners`): ``min_distance``,
        ``block_size`` and ``border`` are for a 640 x 360 image and scale with the image diagonal,
        ``max_tracks`` and ``replenish_below`` with its area (never below their values); the quality
        level can be lowered when corners are scarce (``min_quality_level``) and the corners spread
        over a grid (``grid_cell``).
    min_quality_level : float or None
        When set, the quality level is divided by 4 down to this while fewer than ``min_inliers``
        corners come back (``adaptive_corners``). Off by default: on a coarse checkerboard the extra
        corners are faint texture on the squares' edges, which slides along them; on
        ``real_barrel_coarse`` the end point moved from 0.12 % to 0.18 % of the path and the heading
        from 0.07 deg to 0.47 deg (frames without enough corners go to the dense alignment instead).
    grid_cell : float
        Side of the cells over which corners are spread [px] (``adaptive_corners``; 0, the default: no
        grid). Every cell gets its strongest corner (:func:`frontends.corners.spread_corners`). Off by
        default: on the gravel recordings the spread-out corners are weaker; on ``random60`` (``fusion-vo
        simulate R --standard random60``, then ``fusion-vo run R --backend none`` with and without
        ``klt: {grid_cell: 160}`` in ``--config``) the end point moves from 0.0024 % to 0.0201 % of the
        10.05 m path and the ATE from 0.30 to 0.36 mm.
    central_region : float or None
        Fraction of the width and height, about the image centre, where corners are detected and kept
        and whose pixels the dense fallback uses (``None``: all, or the central half when the run is
        ``--uncalibrated``: the distortion of a lens without a model grows with the distance from the
        centre).
    """

    max_tracks: int = 60
    replenish_below: int = 40
    quality_level: float = 0.02
    min_distance: float = 24.0
    block_size: int = 3
    window: int = 13
    pyramid_levels: int = 1
    retry_pyramid_levels: int = 3
    lk_iterations: int = 20
    lk_epsilon: float = 0.01
    min_eigen: float = 1e-3
    fb_threshold: float = 0.5
    forward_backward: bool = True
    fb_skip_ratio: float | None = None
    warp_tolerance: float = 0.015
    refine_tolerance: float = 0.015
    exposure_tolerance: float = 0.01
    border: int = 10
    method: str = "ransac"
    threshold: float = 1.0
    confidence: float = 0.999
    max_iterations: int = 256
    seed: int = 0
    min_sigma: float = 0.02
    min_inliers: int = 10
    min_inlier_ratio: float = 0.5
    max_abs_log_scale: float = 0.1
    min_spread: float = 20.0
    min_texture: float = 2.0
    min_texture_ratio: float = 0.35
    max_prediction_gap: float = 4.0
    max_failures: int = 3
    global_fallback: bool = True
    global_downsample: int = 4
    min_global_response: float = 0.05
    dense_fallback: bool = True
    verify_below: int = 30
    verify_tolerance: float = 1.0
    adaptive_corners: bool = True
    min_quality_level: float | None = None
    grid_cell: float = 0.0
    central_region: float | None = None

    #: the range of every number field (:func:`frontends.config.check_ranges`; ``None`` always passes)
    RANGES: ClassVar[dict[str, Range]] = shared_ranges(RobustOptions.RANGES, "threshold", "confidence",
                                                       "max_iterations", "min_sigma", "min_inliers",
                                                       "max_abs_log_scale", "min_spread") | {
        "max_tracks": AT_LEAST_1, "replenish_below": AT_LEAST_0, "quality_level": Range(0, 1, open_low=True),
        "min_distance": AT_LEAST_0, "block_size": AT_LEAST_1, "pyramid_levels": AT_LEAST_0,
        "retry_pyramid_levels": AT_LEAST_0, "lk_iterations": AT_LEAST_1, "lk_epsilon": AT_LEAST_0,
        "min_eigen": AT_LEAST_0, "fb_threshold": POSITIVE, "fb_skip_ratio": Range(0, 1, open_low=True),
        "warp_tolerance": AT_LEAST_0, "refine_tolerance": AT_LEAST_0, "exposure_tolerance": AT_LEAST_0,
        "border": AT_LEAST_0, "seed": AT_LEAST_0, "min_inlier_ratio": FRACTION, "min_texture": AT_LEAST_0,
        "min_texture_ratio": FRACTION, "max_prediction_gap": AT_LEAST_0, "max_failures": AT_LEAST_1,
        "global_downsample": AT_LEAST_1, "min_global_response": AT_LEAST_0, "verify_below": AT_LEAST_0,
        "verify_tolerance": AT_LEAST_0, "min_quality_level": Range(0, 1, open_low=True), "grid_cell": AT_LEAST_0,
        "central_region": Range(0.1, 1),
    }

    def __post_init__(self) -> None:
        if self.window < 5 or self.window % 2 == 0:
            raise ValueError(f"window must be an odd number of at least 5, not {self.window}")
        check_ranges(self, self.RANGES)
        if self.max_tracks < self.min_inliers or self.replenish_below > self.max_tracks:
            raise ValueError("need min_inliers <= replenish_below <= max_tracks")
        if self.min_quality_level is not None and not 0.0 < self.min_quality_level <= self.quality_level:
            raise ValueError("need 0 < min_quality_level <= quality_level")
        self.robust_options()  # validates method, threshold, confidence

    @property
    def region(self) -> float:
        """``central_region`` in effect (1: the whole image)."""
        return 1.0 if self.central_region is None else float(self.central_region)

    def lk_settings(self) -> LkSettings:
        """The Lucas-Kanade settings derived from this configuration."""
        return LkSettings(
            window=self.window,
            iterations=self.lk_iterations,
            epsilon=self.lk_epsilon,
            min_eigen=self.min_eigen,
            fb_threshold=self.fb_threshold,
            border=self.border,
            warp_tolerance=self.warp_tolerance,
            forward_backward=self.forward_backward,
        )

    def robust_options(self) -> RobustOptions:
        """The estimator settings derived from this configuration."""
        return RobustOptions(
            method=self.method,
            threshold=self.threshold,
            confidence=self.confidence,
            max_iterations=self.max_iterations,
            max_abs_log_scale=2.0 * self.max_abs_log_scale,
            min_sigma=self.min_sigma,
            min_inliers=self.min_inliers,
            min_spread=self.min_spread,
        )


@dataclass
class PreparedFrame:
    """The work on a frame that does not depend on earlier frames (see :meth:`KltFrontend.prepare`).

    Attributes
    ----------
    image : ndarray
        The frame as given.
    texture : float
        :func:`frontends.frame_check.texture_measure` of its 8-bit version.
    small : ndarray
        :func:`frontends.tracking.reduce_for_exposure` of its 8-bit version.
    """

    image: np.ndarray
    texture: float
    small: np.ndarray


@dataclass
class _Setup:
    """Where an attempt starts: the reference points in view of the guess and the image-space motion.

    Attributes
    ----------
    p0 : ndarray, shape (k, 2)
        The reference points that the guess keeps in view (raw image coordinates, float64).
    src : ndarray, shape (k, 2)
        Their rectified coordinates.
    affine : ndarray, shape (2, 3)
        The guess as an image-space affine map (least squares through the point map).
    warped : ndarray or None or WARP_HERE
        :func:`frontends.tracking.warp_reference` of the reference by ``affine``, when it was made
        ahead; ``WARP_HERE`` when the tracker is to make it.
    """

    p0: np.ndarray
    src: np.ndarray
    affine: np.ndarray
    warped: object = WARP_HERE


def _setup(point_map: PointMap, ref_pts: np.ndarray, ref_rect: np.ndarray, guess: np.ndarray,
           shape: tuple[int, int], border: int, min_inliers: int) -> _Setup | None:
    """The :class:`_Setup` of tracking ``ref_pts`` (rectified: ``ref_rect``) from the rectified similarity
    ``guess`` in frames of ``shape``; ``None`` when fewer than ``min_inliers`` points stay in view."""
    h, w = shape
    b = border
    init = point_map.to_image(apply_similarity(guess, ref_rect))
    inside = (init[:, 0] >= b) & (init[:, 0] <= w - 1 - b) & (init[:, 1] >= b) & (init[:, 1] <= h - 1 - b)
    if np.count_nonzero(inside) < min_inliers:
        return None
    p0 = ref_pts[inside].astype(np.float64)
    return _Setup(p0, ref_rect[inside], fit_affine(p0, init[inside]))


@dataclass
class _Ahead:
    """The predicted attempt of the next frame, set up in another thread (:meth:`KltFrontend.set_executor`).

    It is used only when the frontend is in the state it was made for: the same reference image and
    points, and the same prediction (so the same next timestamp); it is then what the tracker would
    have computed itself, bit for bit.
    """

    ref_img: np.ndarray
    ref_pts: np.ndarray
    prediction: np.ndarray
    future: Future  # of (ref_rect, _Setup or None)


def _set_up_ahead(point_map: PointMap, ref_img: np.ndarray, ref_pts: np.ndarray, prediction: np.ndarray,
                  border: int, min_inliers: int, warp_tolerance: float) -> tuple[np.ndarray, _Setup | None]:
    """What :meth:`KltFrontend._process` computes first for the predicted attempt: the rectified
    reference points and the attempt's :class:`_Setup` with the reference warped."""
    ref_rect = point_map.to_rectified(ref_pts.astype(np.float64))
    setup = _setup(point_map, ref_pts, ref_rect, prediction, ref_img.shape, border, min_inliers)
    if setup is not None:
        setup.warped = warp_reference(ref_img, setup.affine, warp_tolerance)
    return ref_rect, setup


def global_shift(ref: np.ndarray, img: np.ndarray, config: KltConfig,
                 hann: np.ndarray | None = None) -> tuple[tuple[float, float] | None, np.ndarray]:
    """Coarse translation (image px) of ``img`` against ``ref`` by phase correlation at ``config``'s
    ``global_downsample`` (None below ``min_global_response``), and the Hanning window used (pass it back in
    to reuse it for frames of the same size)."""
    f = config.global_downsample
    size = (img.shape[1] // f, img.shape[0] // f)
    a = cv2.resize(ref, size, interpolation=cv2.INTER_AREA).astype(np.float32)
    c = cv2.resize(img, size, interpolation=cv2.INTER_AREA).astype(np.float32)
    if hann is None or hann.shape != a.shape:
        hann = cv2.createHanningWindow(size, cv2.CV_32F)
    (dx, dy), response = cv2.phaseCorrelate(a, c, hann)
    if response < config.min_global_response:
        return None, hann
    return (dx * f, dy * f), hann


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
        self._dense = DenseFallback(self.point_map, DirectConfig(central_region=self.config.central_region)) \
            if self.config.dense_fallback else None
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
        self._ahead: _Ahead | None = None

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
        if not isinstance(image, np.ndarray) or image.ndim != 2 or image.dtype not in (np.uint8, np.uint16) \
                or min(image.shape) < 8:
            return image
        grey = np.ascontiguousarray((image // 257).astype(np.uint8) if image.dtype == np.uint16 else image)
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
        future = self._executor.submit(_set_up_ahead, self.point_map, self._ref_img, self._ref_pts, prediction,
                                       cfg.border, cfg.min_inliers, cfg.warp_tolerance)
        self._ahead = _Ahead(self._ref_img, self._ref_pts, prediction, future)

    def _take_ahead(self, prediction: np.ndarray | None) -> tuple[np.ndarray, _Setup | None] | None:
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
                 setup: _Setup | None | object = WARP_HERE) -> _Attempt:
        """Track the reference points from the rectified similarity ``guess`` and fit a similarity.

        The guess is turned into an image-space affine map ``A`` (least squares through the point
        map). When ``A`` rotates or scales, the reference image is warped by ``A`` first, so that
        Lucas-Kanade's translation-only model meets undeformed patches (tracking a rotated patch
        biases the measured rotation by a fraction of a percent). If the fitted motion then differs
        from ``A`` by more than ``refine_tolerance``, the points are tracked once more through the
        fitted motion at full resolution.

        ``setup`` is this attempt's :class:`_Setup` when it was made ahead (``None``: too few points in
        view), ``WARP_HERE`` to make it here.
        """
        cfg = self.config
        if setup is WARP_HERE:
            setup = _setup(self.point_map, self._ref_pts, ref_rect, guess, img.shape, cfg.border, cfg.min_inliers)
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
        """New Shi-Tomasi corners on the half-resolution image, away from ``existing`` points.

        Spacing, block size and count follow the image size, the quality level is lowered when too
        few corners come back, and the corners are spread over a grid (:mod:`frontends.corners`).
        """
        cfg = self.config
        plan = self._plan(img.shape)
        half = cv2.pyrDown(img)
        hh, hw = half.shape
        margin = cfg.window // 4 + 1
        x0, y0, x1, y1 = plan.region
        mask = np.zeros((hh, hw), np.uint8)
        mask[y0 // 2 + margin : (y1 + 1) // 2 - margin, x0 // 2 + margin : (x1 + 1) // 2 - margin] = 255
        cell = max(int(plan.min_distance // 2), 1)
        if len(existing):
            # blank the grid cells (and their neighbours) holding an existing track
            gi = np.clip((existing[:, 1] / 2) // cell, 0, (hh - 1) // cell).astype(int)
            gj = np.clip((existing[:, 0] / 2) // cell, 0, (hw - 1) // cell).astype(int)
            occ = np.zeros(((hh - 1) // cell + 3, (hw - 1) // cell + 3), bool)
            for di in (0, 1, 2):
                for dj in (0, 1, 2):
                    occ[gi + di, gj + dj] = True
            occ = occ[1:-1, 1:-1]
            big = np.repeat(np.repeat(occ, cell, axis=0), cell, axis=1)[:hh, :hw]
            mask[big] = 0
        wanted = plan.max_corners - len(existing)
        if wanted <= 0:
            return np.zeros((0, 2), np.float32)
        min_quality = cfg.quality_level if cfg.min_quality_level is None or not cfg.adaptive_corners \
            else cfg.min_quality_level
        enough = min(wanted, cfg.min_inliers)
        grid = grid_shape((hh, hw), cfg.grid_cell / 2) if cfg.adaptive_corners and cfg.grid_cell > 0 else (1, 1)
        corners = spread_corners(half, mask, wanted, cfg.quality_level, min_quality, plan.min_distance / 2,
                                 plan.block_size, grid, enough)
        return corners * 2.0

    def _failed(self, t: float, status: MotionStatus, reason: str, texture: float = float("nan"), current=None) -> FrameMotion:
        """A failed measurement; restarts from ``current`` after too many failures in a row."""
        restarted = self._history.failed(can_restart=current is not None)
        if restarted:
            self._set_reference(current, t, np.zeros((0, 2), np.float32))
        return failed_motion(t, None if restarted else self._ref_time, status, reason, texture, restarted)

