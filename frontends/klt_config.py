"""Settings of the KLT frontend (:class:`frontends.klt.KltFrontend`): every option with its default, range and unit."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from frontends.config import NUMBER, Float, Int
from frontends.options import (CentralRegion, FbThreshold, InlierRatio, MaxFailures, MinTexture, PointSettings,
                               PredictionGap, Seed, TextureRatio, UseDenseFallback, VerifyBelow, VerifyTolerance)
from frontends.similarity import (Confidence, Hypotheses, InlierDistance, MaxLogScale, MinInliers, MinSpread,
                                  ResidualFloor, RobustMethod)
from frontends.tracking import LkSettings

#: the smallest cell of the corner grid [px]: half of it at the half resolution where corners are detected
MIN_GRID_CELL = 16.0


class KltConfig(PointSettings):
    """Settings of :class:`frontends.klt.KltFrontend` (every option has a working default).

    Besides the ranges of the fields: ``window`` is odd; ``min_inliers <= replenish_below <= max_tracks``;
    ``min_quality_level``, when set, is at most ``quality_level``; ``grid_cell`` is 0 (no grid) or at
    least :data:`MIN_GRID_CELL`.
    """

    max_tracks: Int = Field(60, ge=1, le=10_000, description="Number of points tracked after a replenish.")
    replenish_below: Int = Field(40, ge=0, le=10_000, description=(
        "New corners are detected only when fewer tracks than this survive."))
    quality_level: Float = Field(0.02, gt=0, le=1, description=(
        "Shi-Tomasi minimum eigenvalue relative to the strongest corner of the image (0-1)."))
    min_distance: Float = Field(24.0, ge=0, le=10_000, description="Minimum distance between tracked points [px].")
    block_size: Int = Field(3, ge=1, le=99, description=(
        "Neighbourhood of the structure tensor used for corner detection [px, at half resolution]."))
    window: Int = Field(13, ge=5, le=101, description="Lucas-Kanade window side [px] (odd).")
    pyramid_levels: Int = Field(1, ge=0, le=8, description=(
        "Pyramid levels above full resolution used when tracking from a prediction."))
    retry_pyramid_levels: Int = Field(3, ge=0, le=8, description=(
        "Pyramid levels used for the zero-motion retry and the global-estimate retry."))
    lk_iterations: Int = Field(20, ge=1, le=1000, description="Maximum Gauss-Newton iterations per level.")
    lk_epsilon: Float = Field(0.01, ge=0, description="Convergence threshold of the Lucas-Kanade update [px].")
    min_eigen: Float = Field(1e-3, ge=0, description=(
        "Lucas-Kanade's own minimum-eigenvalue threshold (OpenCV units): points below are dropped."))
    fb_threshold: FbThreshold = 0.5
    forward_backward: bool = Field(True, description=(
        "Whether to run the forward-backward check (it doubles the tracking time)."))
    fb_skip_ratio: Annotated[float, Field(gt=0, le=1), NUMBER] | None = Field(None, description=(
        "Run the forward-backward check only when it is needed: a similarity is first fitted on the forward "
        "tracks, and when at least this fraction of them are its inliers (and the fit is accepted) the check is "
        "skipped; otherwise the points are checked backward and the fit is made again on the survivors. ``None``: "
        "always check. Faster, less accurate on some recordings."))
    warp_tolerance: Float = Field(0.015, ge=0, description=(
        "When the guessed motion's linear part differs from the identity by more than this (largest element; 0.015 "
        "is about 0.86 deg or 1.5 % scale), the reference is warped by it before tracking. Below it the rotation "
        "bias of unwarped tracking is under 0.1 % of the angle."))
    refine_tolerance: Float = Field(0.015, ge=0, description=(
        "When the fitted motion's linear part differs from the guess by more than this, the points are tracked "
        "again through the fitted motion (at full resolution)."))
    exposure_tolerance: Float = Field(0.01, ge=0, description=(
        "When the brightness changed by more than this fraction between the frames (gain, or offset relative to "
        "128 grey levels), the points are tracked again with the reference corrected."))
    border: Int = Field(10, ge=0, le=10_000, description="Points closer than this to the image border are not "
                                                         "tracked [px].")
    method: RobustMethod = "ransac"
    threshold: InlierDistance = 1.0
    confidence: Confidence = 0.999
    max_iterations: Hypotheses = 256
    seed: Seed = 0
    min_sigma: ResidualFloor = 0.01
    min_inliers: MinInliers = 10
    min_inlier_ratio: InlierRatio = Field(0.5, description=(
        "Fewer inliers than this fraction of the tracked points reject the estimate."))
    max_abs_log_scale: MaxLogScale = 0.1
    min_spread: MinSpread = 20.0
    min_texture: MinTexture = 2.0
    min_texture_ratio: TextureRatio = 0.35
    max_prediction_gap: PredictionGap = 4.0
    max_failures: MaxFailures = 3
    global_fallback: bool = Field(True, description="Whether to try phase correlation when both tracking attempts "
                                                    "fail.")
    global_downsample: Int = Field(4, ge=1, le=32, description="Reduction factor of the images for phase "
                                                               "correlation.")
    min_global_response: Float = Field(0.05, ge=0, description="Smallest phase-correlation peak response accepted.")
    dense_fallback: UseDenseFallback = True
    verify_below: VerifyBelow = 30
    verify_tolerance: VerifyTolerance = 1.0
    adaptive_corners: bool = Field(True, description=(
        "Adapt the corner search to the image (:mod:`frontends.corners`): ``min_distance``, ``block_size`` and "
        "``border`` are for a 640 x 360 image and scale with the image diagonal, ``max_tracks`` and "
        "``replenish_below`` with its area (never below their values); the quality level can be lowered when "
        "corners are scarce (``min_quality_level``) and the corners spread over a grid (``grid_cell``)."))
    min_quality_level: Annotated[float, Field(gt=0, le=1), NUMBER] | None = Field(None, description=(
        "When set, the quality level is divided by 4 down to this while fewer than ``min_inliers`` corners come "
        "back (``adaptive_corners``). Off by default: on a coarse checkerboard the extra corners are faint texture "
        "on the squares' edges, which slides along them."))
    grid_cell: Float = Field(0.0, ge=0, le=10_000, description=(
        f"Side of the cells over which corners are spread [px] (0: no grid; else at least {MIN_GRID_CELL:g}). With "
        "``adaptive_corners``, every cell gets its strongest corner (:func:`frontends.corners.spread_corners`). "
        "Off by default: on the gravel recordings the spread-out corners are weaker and the track less accurate."))
    central_region: CentralRegion = None

    @model_validator(mode="after")
    def _consistent(self) -> KltConfig:
        if self.window % 2 == 0:
            raise ValueError(f"window must be an odd number, not {self.window}")
        if self.max_tracks < self.min_inliers or self.replenish_below > self.max_tracks:
            raise ValueError("need min_inliers <= replenish_below <= max_tracks")
        if self.min_quality_level is not None and self.min_quality_level > self.quality_level:
            raise ValueError("need min_quality_level <= quality_level")
        if 0.0 < self.grid_cell < MIN_GRID_CELL:
            raise ValueError(f"grid_cell must be 0 (no grid) or at least {MIN_GRID_CELL:g} px, not {self.grid_cell}")
        return self

    def lk_settings(self) -> LkSettings:
        """The Lucas-Kanade settings derived from this configuration."""
        return LkSettings(window=self.window, iterations=self.lk_iterations, epsilon=self.lk_epsilon,
                          min_eigen=self.min_eigen, fb_threshold=self.fb_threshold, border=self.border,
                          warp_tolerance=self.warp_tolerance, forward_backward=self.forward_backward)
