"""What the frontends' settings share: options defined once (type, range, unit, description) and the
settings derived from them. The robust estimator's options are defined with it, in
:mod:`frontends.similarity`.

A settings model gives such an option its own default, e.g. ``min_texture: MinTexture = 2.0``; a
model may word the description for itself with ``Field(default, description=...)``.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from frontends.config import INTEGER, NUMBER, Settings
from frontends.similarity import RobustOptions

# ---------------------------------------------------------------- frames, prediction and restarts
MinTexture = Annotated[float, Field(
    ge=0, le=255, description="Smallest mean neighbour difference of a usable frame [grey levels]. See "
                              ":func:`frontends.frame_check.texture_measure`."), NUMBER]
TextureRatio = Annotated[float, Field(
    ge=0, le=1, description="A frame whose texture falls below this fraction of the reference frame's is "
                            "featureless (sudden blur, exposure loss)."), NUMBER]
PredictionGap = Annotated[float, Field(
    ge=0, le=100, description="The prediction is continued over at most this many times the last interval."), NUMBER]
MaxFailures = Annotated[int, Field(
    ge=1, le=1000, description="Consecutive failures after which the frontend restarts from the current "
                               "frame."), INTEGER]
CentralRegion = Annotated[Annotated[float, Field(ge=0.1, le=1), NUMBER] | None, Field(
    description="Fraction of the width and height, about the image centre, that is used (``None``: all). Corners "
                "are detected and kept there, and the dense alignment uses its pixels.")]

# ---------------------------------------------------------------- the point-based frontends (KLT, features)
InlierRatio = Annotated[float, Field(
    ge=0, le=1, description="Fewer inliers than this fraction of the correspondences reject the estimate."), NUMBER]
Seed = Annotated[int, Field(ge=0, description="Seed of the frontend's own random generator."), INTEGER]
FbThreshold = Annotated[float, Field(gt=0, description="Maximum forward-backward error of a track [px]."), NUMBER]
UseDenseFallback = Annotated[bool, Field(
    description="Align the whole frames photometrically when the points cannot measure a frame that still has "
                "texture. That is, with too few corners or inliers, points out of view or a sudden blur "
                "(:class:`frontends.direct.DenseFallback`); the frame is then weighted by the photometric "
                "covariance.")]
VerifyBelow = Annotated[int, Field(
    ge=0, le=10_000, description="A point estimate with fewer inliers than this is checked by a dense alignment "
                                 "(0: never). The alignment, started from it, replaces it when the two disagree "
                                 "by more than ``verify_tolerance`` anywhere in the image "
                                 "(:meth:`frontends.direct.DenseFallback.verify`)."), INTEGER]
VerifyTolerance = Annotated[float, Field(ge=0, description="See ``verify_below`` [px]."), NUMBER]


class FrontendSettings(Settings):
    """Base of a frontend's settings, which have a ``central_region`` field (:data:`CentralRegion`)."""

    @property
    def region(self) -> float:
        """``central_region`` in effect (1: the whole image)."""
        return 1.0 if self.central_region is None else float(self.central_region)


class PointSettings(FrontendSettings):
    """Base of a point-based frontend's settings, which also have the robust estimator's fields
    (``method``, ``threshold``, ``confidence``, ``max_iterations``, ``min_sigma``, ``min_inliers``,
    ``max_abs_log_scale``, ``min_spread``)."""

    def robust_options(self, threshold: float | None = None) -> RobustOptions:
        """The estimator settings, with the inlier distance ``threshold`` (default: the ``threshold`` field).

        Hypotheses may change the scale twice as much as a frame is allowed to (``max_abs_log_scale``).
        """
        return RobustOptions(method=self.method, threshold=self.threshold if threshold is None else threshold,
                             confidence=self.confidence, max_iterations=self.max_iterations,
                             max_abs_log_scale=2.0 * self.max_abs_log_scale, min_sigma=self.min_sigma,
                             min_inliers=self.min_inliers, min_spread=self.min_spread)
