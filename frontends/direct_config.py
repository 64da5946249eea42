"""Settings of the direct frontend (:class:`frontends.direct.DirectFrontend`) and of the per-frame dense fallback
of the point-based frontends: every option with its default, range and unit."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from frontends.config import INTEGER, NUMBER, Float, Int
from frontends.options import CentralRegion, FrontendSettings, MaxFailures, MinTexture, PredictionGap, TextureRatio
from frontends.similarity import MaxLogScale

#: a Gauss-Newton iteration count
_Iterations = Annotated[int, Field(ge=1, le=1000), INTEGER]
#: a zero-normalised cross-correlation
_Correlation = Annotated[float, Field(ge=-1, le=1), NUMBER]


class DirectConfig(FrontendSettings):
    """Settings of :class:`frontends.direct.DirectFrontend` and of :class:`frontends.direct.DenseFallback`
    (every option has a working default)."""

    min_level_size: Int = Field(24, ge=8, le=10_000, description=(
        "The pyramid is reduced until its shorter side would fall below this [px]."))
    finest_level: Int = Field(0, ge=0, le=8, description=(
        "Finest pyramid level used (0: full resolution of the rectified image; 1: half)."))
    iterations: _Iterations = Field(30, description=(
        "Gauss-Newton iterations per level (fewer when the update falls below ``epsilon``)."))
    finest_iterations: _Iterations | None = Field(None, description=(
        "Gauss-Newton iterations on the finest level (``None``: ``iterations``); the coarser levels leave it a "
        "fraction of a pixel to correct."))
    epsilon: Float = Field(0.005, ge=0, description=(
        "Convergence threshold on the largest point displacement of an update [px of the level]."))
    huber: Float = Field(1.0, gt=0, description=(
        "Huber threshold of the residual weights [standard deviations of the normalised image]."))
    smoothing: Float = Field(1.0, ge=0, le=50, description=(
        "Gaussian pre-smoothing of every level [px] (widens the capture range, tames noise)."))
    min_correlation: _Correlation = Field(0.6, description=(
        "ZNCC over the overlap above which a start is accepted without trying the next one."))
    min_correlation_fallback: _Correlation = Field(0.3, description=(
        "Smallest ZNCC of any accepted result; below it the frame fails (``REJECTED``)."))
    min_overlap: Float = Field(0.3, gt=0, le=1, description=(
        "Smallest fraction of the reference that must stay in view (``TOO_FEW_FEATURES`` below)."))
    max_abs_log_scale: MaxLogScale = Field(0.15, description=(
        "Largest plausible ``|log s|`` between consecutive frames (``REJECTED`` above)."))
    min_texture: MinTexture = Field(1.5, description=(
        "Smallest mean neighbour difference of a usable frame [grey levels]. Sensor noise of 1 grey level alone "
        "gives 1.1, and a flat floor must not be aligned on its noise or a fixed highlight."))
    min_texture_ratio: TextureRatio = 0.05
    max_prediction_gap: PredictionGap = 4.0
    max_failures: MaxFailures = 3
    min_sigma: Float = Field(1e-3, ge=0, description=(
        "Floor of the per-pixel residual standard deviation used in the covariance [normalised grey]."))
    max_pixels: Int = Field(12000, ge=4, le=100_000_000, description=(
        "Pixels used per level, at least one per parameter of the similarity. They are those with the strongest "
        "gradient: the rest add little information."))
    max_clipped: Float = Field(0.5, ge=0, le=1, description=(
        "A frame with more than this fraction of its pixels at 0 or 255 is saturated (or black) and not measured "
        "(``TOO_FEW_FEATURES``)."))
    central_region: CentralRegion = Field(None, description=(
        "Fraction of the rectified image's width and height, about its centre, whose pixels are used (``None``: "
        "all). The distortion that a missing lens model leaves out grows with the distance from the centre."))
    grid_limit: bool = Field(False, description=(
        "Sample the rectified image with a pitch that keeps its pixel count at most the raw frame's (a wide-angle "
        "lens's rectified image is otherwise larger than the frame)."))
