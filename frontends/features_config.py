"""Settings of the feature frontend (:class:`frontends.features.FeatureFrontend`): every option with its default,
range and unit."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from frontends.config import INTEGER, NUMBER, Float, Int
from frontends.descriptors import DESCRIPTORS
from frontends.detectors import DETECTORS, DetectorSettings
from frontends.matching import MATCHERS
from frontends.options import (CentralRegion, FbThreshold, InlierRatio, MaxFailures, MinTexture, PointSettings,
                               PredictionGap, Seed, TextureRatio, UseDenseFallback, VerifyBelow, VerifyTolerance)
from frontends.similarity import (Confidence, Hypotheses, InlierDistance, MaxLogScale, MinInliers, MinSpread,
                                  ResidualFloor, RobustMethod)

#: the descriptor distance limit of each descriptor when ``max_distance`` is ``None``
DEFAULT_MAX_DISTANCE = {"patch": 0.9, "orb": 80.0}
#: one side of the non-maximum-suppression neighbourhood [px of the detection image]
_Side = Annotated[int, Field(ge=1, le=99), INTEGER]


class FeatureConfig(PointSettings):
    """Settings of :class:`frontends.features.FeatureFrontend` (every option has a working default).

    Besides the ranges of the fields: ``neighbourhood`` is two odd numbers (one number stands for both);
    ``max_corners`` is at least ``min_inliers``.
    """

    detector: Literal[DETECTORS] = Field("shi_tomasi", description="Corner detector: ``harris``, ``shi_tomasi`` or "
                                                                   "``fast``.")
    max_corners: Int = Field(150, ge=1, le=10_000, description="Maximum number of corners kept per frame (thesis: "
                                                               "80).")
    min_quality: Float = Field(0.01, ge=0, le=1, description=(
        "Corner response relative to the strongest one below which corners are dropped (0-1)."))
    min_metric: Float = Field(0.0, ge=0, description=(
        "Absolute minimum corner response (image scaled to [0, 1]; thesis: 0.001; 0 disables)."))
    neighbourhood: tuple[_Side, _Side] = Field(
        (9, 9), description="Non-maximum-suppression neighbourhood ``(rows, cols)``, odd [px of the detection image].")
    detect_level: Int = Field(1, ge=0, le=5, description=(
        "Corners are detected on the image reduced ``2^detect_level`` times (0: full resolution); the descriptors "
        "and the refinement always use the full-resolution image."))
    harris_k: Float = Field(0.04, ge=0, description=(
        "Harris sensitivity ``k`` in ``det M - k trace(M)^2`` (thesis: 0.001, usual: 0.04)."))
    block_size: Int = Field(3, ge=1, le=99, description="Structure tensor neighbourhood [px].")
    fast_threshold: Int = Field(20, ge=0, le=255, description="FAST intensity difference threshold [grey levels].")
    descriptor: Literal[DESCRIPTORS] = Field("patch", description=(
        "``patch`` (normalised intensity patch) or ``orb``."))
    patch_radius: Int = Field(5, ge=1, le=64, description="Half side of the normalised patch [px].")
    matcher: Literal[MATCHERS] = Field("ratio", description="``threshold``, ``nearest`` or ``ratio``.")
    max_distance: Annotated[float, Field(gt=0), NUMBER] | None = Field(None, description=(
        "Largest accepted descriptor distance (``None``: 0.9 for patches, 80 bits for ORB)."))
    ratio: Float = Field(0.8, gt=0, le=1, description="Nearest-neighbour distance ratio limit.")
    mutual: bool = Field(True, description="Keep only mutually nearest matches.")
    gate_radius: Float = Field(40.0, ge=0, le=10_000, description=(
        "Matches must lie within this distance of the predicted position [px] (0 disables gating)."))
    refine: Literal["lk", "subpix", "none"] = Field("lk", description=(
        "Refinement of the matched corners: ``lk``, ``subpix`` or ``none``. ``lk`` tracks them by Lucas-Kanade "
        "through the fitted motion, ``subpix`` moves them to sub-pixel corner positions (:mod:`frontends.features`)."))
    window: Int = Field(15, ge=3, le=101, description="Lucas-Kanade window for ``refine: lk`` [px].")
    fb_threshold: FbThreshold = Field(0.5, description="Forward-backward limit of the Lucas-Kanade refinement [px].")
    method: RobustMethod = "ransac"
    threshold: InlierDistance = Field(2.0, description="Inlier distance for matched corner positions [rectified px].")
    refine_threshold: InlierDistance = Field(1.0, description=(
        "Inlier distance after the Lucas-Kanade refinement [rectified px]."))
    confidence: Confidence = 0.999
    max_iterations: Hypotheses = 256
    seed: Seed = 0
    min_sigma: ResidualFloor = 0.02
    min_inliers: MinInliers = 10
    min_inlier_ratio: InlierRatio = Field(0.3, description=(
        "Fewer inliers than this fraction of the matches reject the estimate."))
    max_abs_log_scale: MaxLogScale = 0.1
    min_spread: MinSpread = 20.0
    min_texture: MinTexture = 2.0
    min_texture_ratio: TextureRatio = 0.35
    max_prediction_gap: PredictionGap = 4.0
    max_failures: MaxFailures = 3
    dense_fallback: UseDenseFallback = True
    verify_below: VerifyBelow = 30
    verify_tolerance: VerifyTolerance = 1.0
    central_region: CentralRegion = None
    adaptive_detector: bool = Field(True, description=(
        "Scale the detector settings, given for 640 x 360, to the frame's size and (FAST) contrast "
        "(:func:`frontends.corners.scale_detector`)."))

    @field_validator("neighbourhood", mode="before")
    @classmethod
    def _pair(cls, value):
        """One number stands for both sides."""
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return (value, value)
        return value

    @model_validator(mode="after")
    def _consistent(self) -> FeatureConfig:
        if any(v % 2 == 0 for v in self.neighbourhood):
            raise ValueError(f"neighbourhood must be two odd numbers, not {self.neighbourhood}")
        if self.max_corners < self.min_inliers:
            raise ValueError("max_corners must be at least min_inliers")
        return self

    @property
    def distance_limit(self) -> float:
        """The descriptor distance limit in effect."""
        return DEFAULT_MAX_DISTANCE[self.descriptor] if self.max_distance is None else float(self.max_distance)

    def detector_settings(self) -> DetectorSettings:
        """The corner detector settings derived from this configuration (the border keeps every descriptor
        and refinement window inside the image)."""
        border = max(self.patch_radius, 16 if self.descriptor == "orb" else 0, self.window // 2) + 2
        return DetectorSettings(
            method=self.detector, max_corners=self.max_corners, min_quality=self.min_quality,
            min_metric=self.min_metric, neighbourhood=self.neighbourhood, harris_k=self.harris_k,
            block_size=self.block_size, fast_threshold=self.fast_threshold, border=border,
            subpixel=self.refine == "subpix", level=self.detect_level,
        )
