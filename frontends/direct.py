"""Direct frontend: whole-image photometric alignment of a similarity, coarse to fine.

No corners, no matches: every pixel with a gradient votes. Both frames are first resampled into
rectified coordinates (the :class:`PointMap`'s lens and tilt correction, one precomputed
``cv2.remap``), normalised to zero mean and unit variance (so a global gain or offset change, e.g.
auto-exposure, does not bias the fit) and reduced into a pyramid. On each level, from the coarsest,
the similarity ``W(x; p)`` with ``p = (a, b, tx, ty)``::

    W(x; p) = [[1 + a, -b], [b, 1 + a]] x + (tx, ty)      (x relative to the image centre)

is refined by inverse-compositional Gauss-Newton (Baker & Matthews 2004): the steepest-descent images
``SD = ∇I_0 · ∂W/∂p = [I_x x + I_y y, -I_x y + I_y x, I_x, I_y]`` and the Hessian ``H = Σ w SD^T SD``
are those of the reference frame; each iteration warps the current frame back by ``W``, takes the
error ``e = I_1(W(x)) - I_0(x)`` and updates ``W <- W ∘ W(Δp)^{-1}`` with ``Δp = H^{-1} Σ w SD^T e``.
Huber weights ``w`` limit the pull of occlusions, specular highlights and pixels that left the view.

Starting points: the constant-velocity prediction when there is one, then the translation found by
phase correlation at the coarsest level, then zero motion. The first start whose result correlates
well with the reference (zero-normalised cross-correlation ``ZNCC`` over the overlap of at least
``min_correlation``) is taken; otherwise the best one, if any passes ``min_correlation_fallback``.

Covariance
----------
On the finest level, with residual variance ``σ²`` and the Gauss-Newton Hessian ``H`` (unit weights
on the inliers), ``Σ_p = κ σ² H^{-1}``. Neighbouring residuals are correlated (blur, interpolation),
so ``κ`` is the variance inflation of a field with a separable Gaussian autocorrelation,
``κ = Π_axes Σ_d ρ^(d²)``, with ``ρ`` the measured lag-one correlation of the residual image along
each axis (16 noisy frame pairs give a mean normalised squared error of 1.3-12 for 4 parameters,
asserted in ``tests/frontends``). ``Σ_p`` is then propagated to the ``(tx, ty, angle, log s)`` of
:mod:`frontends.base` in rectified pixels. A blurred or weakly textured frame has a small ``H`` and a
large ``σ``: it is weighted down, not dropped.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import ClassVar

import cv2
import numpy as np

from frontends.base import FrameMotion, IdentityMap, MotionStatus, PointMap, similarity_params
from frontends.config import AT_LEAST_0, AT_LEAST_1, FRACTION, POSITIVE, ConfigMixin, Range, check_ranges
from frontends.frame_check import check_frame
from frontends.prediction import MotionHistory, failed_motion, timed_measurement

logger = logging.getLogger(__name__)


@dataclass
class DirectConfig(ConfigMixin):
    """Settings of :class:`DirectFrontend` and of the per-frame dense fallback of the other frontends.

    Attributes
    ----------
    min_level_size : int
        The pyramid is reduced until its shorter side would fall below this [px].
    finest_level : int
        Finest pyramid level used (0: full resolution of the rectified image; 1: half).
    iterations : int
        Gauss-Newton iterations per level (fewer when the update falls below ``epsilon``).
    finest_iterations : int or None
        Gauss-Newton iterations on the finest level (``None``: ``iterations``); the coarser levels
        leave it a fraction of a pixel to correct.
    epsilon : float
        Convergence threshold on the largest point displacement of an update [px of the level].
    huber : float
        Huber threshold of the residual weights [standard deviations of the normalised image].
    smoothing : float
        Gaussian pre-smoothing of every level [px] (widens the capture range, tames noise).
    min_correlation : float
        ZNCC over the overlap above which a start is accepted without trying the next one.
    min_correlation_fallback : float
        Smallest ZNCC of any accepted result; below it the frame fails (``REJECTED``).
    min_overlap : float
        Smallest fraction of the reference that must stay in view (``TOO_FEW_FEATURES`` below).
    max_abs_log_scale : float
        Largest plausible ``|log s|`` between consecutive frames (``REJECTED`` above).
    min_texture : float
        Smallest mean neighbour difference of a usable frame [grey levels] (sensor noise of 1 grey level
        alone gives 1.1: a flat floor must not be aligned on its noise or a fixed highlight).
    min_texture_ratio : float
        A frame whose texture falls below this fraction of the reference frame's is featureless.
    max_prediction_gap : float
        The prediction is continued over at most this many times the last interval.
    max_failures : int
        Consecutive failures after which the frontend restarts from the current frame.
    min_sigma : float
        Floor of the per-pixel residual standard deviation used in the covariance [normalised grey].
    max_pixels : int
        Pixels used per level: those with the strongest gradient (the rest add little information).
    max_clipped : float
        A frame with more than this fraction of its pixels at 0 or 255 is saturated (or black) and
        not measured (``TOO_FEW_FEATURES``).
    central_region : float or None
        Fraction of the rectified image's width and height, about its centre, whose pixels are used
        (``None``: all, or the central half when the run is ``--uncalibrated``: the distortion the
        missing lens model leaves out grows with the distance from the centre, so the centre moves most
        nearly by one similarity).
    grid_limit : bool
        Sample the rectified image with a pitch that keeps its pixel count at most the raw frame's
        (a wide-angle lens's rectified image is otherwise larger than the frame: 1.3 times for the barrel
        lens of the realistic recordings, 2 times for their fisheye).
    """

    min_level_size: int = 24
    finest_level: int = 0
    iterations: int = 30
    finest_iterations: int | None = None
    epsilon: float = 0.005
    huber: float = 1.0
    smoothing: float = 1.0
    min_correlation: float = 0.6
    min_correlation_fallback: float = 0.3
    min_overlap: float = 0.3
    max_abs_log_scale: float = 0.15
    min_texture: float = 1.5
    min_texture_ratio: float = 0.05
    max_prediction_gap: float = 4.0
    max_failures: int = 3
    min_sigma: float = 1e-3
    max_pixels: int = 12000
    max_clipped: float = 0.5
    central_region: float | None = None
    grid_limit: bool = False

    #: the range of every number field (:func:`frontends.config.check_ranges`; ``None`` always passes)
    RANGES: ClassVar[dict[str, Range]] = {
        "min_level_size": Range(8), "finest_level": AT_LEAST_0, "iterations": AT_LEAST_1,
        "finest_iterations": AT_LEAST_1, "epsilon": AT_LEAST_0, "huber": POSITIVE, "smoothing": AT_LEAST_0,
        "min_correlation": Range(-1, 1), "min_correlation_fallback": Range(-1, 1),  # ZNCC
        "min_overlap": Range(0, 1, open_low=True), "max_abs_log_scale": POSITIVE, "min_texture": AT_LEAST_0,
        "min_texture_ratio": FRACTION, "max_prediction_gap": AT_LEAST_0, "max_failures": AT_LEAST_1,
        "min_sigma": AT_LEAST_0, "max_pixels": Range(4),  # a similarity has four parameters
        "max_clipped": FRACTION, "central_region": Range(0.1, 1),
    }

    def __post_init__(self) -> None:
        check_ranges(self, self.RANGES)

    @property
    def region(self) -> float:
        """``central_region`` in effect (1: the whole image)."""
        return 1.0 if self.central_region is None else float(self.central_region)


@dataclass
class Alignment:
    """Result of :meth:`DirectAligner.align`.

    Attributes
    ----------
    status : MotionStatus
    matrix : ndarray, shape (2, 3)
        Similarity from reference to current rectified coordinates.
    covariance : ndarray, shape (4, 4)
        Covariance of ``(tx, ty, angle, log s)``.
    correlation : float
        ZNCC of the aligned frames over their overlap.
    overlap : float
        Fraction of the reference still in view.
    start : str
        Starting point of the accepted solution.
    reason : str
    """

    status: MotionStatus
    matrix: np.ndarray
    covariance: np.ndarray
    correlation: float = float("nan")
    overlap: float = 0.0
    start: str = ""
    reason: str = ""


def _mat3(m: np.ndarray) -> np.ndarray:
    return np.vstack([np.asarray(m, dtype=np.float64), [0.0, 0.0, 1.0]])


class _Rectifier:
    """Resamples raw frames onto a regular grid of rectified coordinates (``rect = grid + origin``)."""

    def __init__(self, point_map: PointMap, shape: tuple[int, int], limit: bool = False):
        h, w = shape
        self.origin = np.zeros(2)
        self.pitch = 1.0  # rectified units per grid pixel
        self.maps: tuple[np.ndarray, np.ndarray] | None = None
        self.shape = shape
        if isinstance(point_map, IdentityMap) or getattr(point_map, "trivial", False):
            return
        # the rectified rectangle inscribed in the image of the raw frame's border
        n = 64
        xs, ys = np.linspace(0, w - 1, n), np.linspace(0, h - 1, n)
        left = point_map.to_rectified(np.column_stack([np.zeros(n), ys]))
        right = point_map.to_rectified(np.column_stack([np.full(n, w - 1.0), ys]))
        top = point_map.to_rectified(np.column_stack([xs, np.zeros(n)]))
        bottom = point_map.to_rectified(np.column_stack([xs, np.full(n, h - 1.0)]))
        x0, x1 = float(np.max(left[:, 0])), float(np.min(right[:, 0]))
        y0, y1 = float(np.max(top[:, 1])), float(np.min(bottom[:, 1]))
        if not (x1 - x0 > 16 and y1 - y0 > 16):
            raise ValueError("the point map leaves no usable rectified area")
        if limit:
            self.pitch = max(1.0, math.sqrt((x1 - x0) * (y1 - y0) / float(w * h)))
        gw, gh = int((x1 - x0) / self.pitch), int((y1 - y0) / self.pitch)
        self.origin = np.array([x0, y0])
        gx, gy = np.meshgrid(np.arange(gw, dtype=np.float64) * self.pitch + x0,
                             np.arange(gh, dtype=np.float64) * self.pitch + y0)
        raw = point_map.to_image(np.column_stack([gx.ravel(), gy.ravel()])).reshape(gh, gw, 2).astype(np.float32)
        self.maps = cv2.convertMaps(raw[..., 0], raw[..., 1], cv2.CV_16SC2)
        self.shape = (gh, gw)

    def __call__(self, image: np.ndarray) -> np.ndarray:
        if self.maps is None:
            return image
        return cv2.remap(image, self.maps[0], self.maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


class _Level:
    """One pyramid level of a normalised image, with its steepest-descent images when a reference."""

    def __init__(self, image: np.ndarray, scale: float, smoothing: float):
        img = image.astype(np.float32, copy=False)
        if smoothing > 0:
            img = cv2.GaussianBlur(img, (0, 0), smoothing)
        self.scale = scale
        self.image = img
        h, w = img.shape
        self.centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
        self._sd: np.ndarray | None = None

    def steepest_descent(self, border: int, max_pixels: int, region: float = 1.0
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``SD`` (N x 4, float32), the centred coordinates (2 x N) and the flat indices of the pixels used.

        Only the central ``region`` fraction of the width and height is used. When that holds more
        than ``max_pixels`` interior pixels, only those with the strongest gradient are used (the
        others add little to the Hessian and cost the same).
        """
        if self._sd is None:
            img = self.image
            h, w = img.shape
            gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
            gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
            bx = max(border, int(round(0.5 * (1.0 - region) * w)))
            by = max(border, int(round(0.5 * (1.0 - region) * h)))
            sw, sh = max(w - 2 * bx, 0), max(h - 2 * by, 0)
            n_inner = sw * sh
            if n_inner > max_pixels:
                # the inner pixels in row-major order, as flat indices of the sub-image
                sgx, sgy = gx[by : h - by, bx : w - bx], gy[by : h - by, bx : w - bx]
                mag = cv2.add(cv2.multiply(sgx, sgx), cv2.multiply(sgy, sgy)).ravel()
                # the gradient threshold that keeps about max_pixels, from a sample of at most 16384 pixels
                step = max(1, n_inner // 16384)
                sample = mag[::step]
                keep = len(sample) - max(1, (max_pixels * len(sample)) // n_inner)
                limit = np.partition(sample, keep)[keep]
                sub = np.flatnonzero(mag >= limit)
                if step == 1:
                    sub = sub[:max_pixels]
            else:
                sub = np.arange(n_inner)
            idx = (sub // max(sw, 1) + by) * w + (sub % max(sw, 1) + bx)
            gxf, gyf = gx.ravel()[idx], gy.ravel()[idx]
            xf = (idx % w).astype(np.float32) - np.float32(self.centre[0])
            yf = (idx // w).astype(np.float32) - np.float32(self.centre[1])
            self._sd_t = np.stack([gxf * xf + gyf * yf, -gxf * yf + gyf * xf, gxf, gyf])
            self._sd = np.ascontiguousarray(self._sd_t.T)
            self._xy = np.stack([xf, yf])
            self._idx = idx
        return self._sd, self._xy, self._idx

    def steepest_descent_t(self) -> np.ndarray:
        """``SD`` transposed (4 x N, contiguous) after :meth:`steepest_descent`."""
        return self._sd_t


def clipped_fraction(image: np.ndarray) -> float:
    """Fraction of the pixels of a ``uint8`` frame at 0 or 255 (under- or over-exposed)."""
    sub = image[::2, ::2]
    hist = cv2.calcHist([np.ascontiguousarray(sub)], [0], None, [256], [0, 256]).ravel()
    return float(hist[0] + hist[255]) / max(sub.size, 1)


def _normalise(image: np.ndarray) -> np.ndarray:
    """High-pass and standardise: vignetting, a fixed highlight and exposure changes do not pull the fit.

    The low-pass removed is a box filter of about a sixteenth of the image, applied twice.
    """
    img = image.astype(np.float32)
    k = max(3, (min(img.shape) // 16) | 1)
    low = cv2.blur(img, (k, k), borderType=cv2.BORDER_REFLECT)
    cv2.blur(low, (k, k), dst=low, borderType=cv2.BORDER_REFLECT)
    cv2.subtract(img, low, dst=img)  # in place: no temporary frames
    mean, std = cv2.meanStdDev(img)
    gain = 1.0 / max(float(std[0, 0]), 1e-3)
    return cv2.addWeighted(img, gain, img, 0.0, -float(mean[0, 0]) * gain, dtype=cv2.CV_32F)


class DirectAligner:
    """Photometric similarity alignment of two frames in rectified coordinates.

    Parameters
    ----------
    config : DirectConfig
    point_map : PointMap, optional
        Raw pixel <-> rectified coordinates (identity when omitted).
    """

    def __init__(self, config: DirectConfig | None = None, point_map: PointMap | None = None):
        self.config = config or DirectConfig()
        self.point_map = point_map if point_map is not None else IdentityMap()
        self._rectifier: _Rectifier | None = None
        self._hann: np.ndarray | None = None

    def prepare(self, image: np.ndarray) -> list[_Level]:
        """The rectified, normalised pyramid of a raw ``uint8`` frame (finest level first)."""
        if self._rectifier is None or self._rectifier_raw_shape != image.shape:
            self._rectifier = _Rectifier(self.point_map, image.shape, self.config.grid_limit)
            self._rectifier_raw_shape = image.shape
        cfg = self.config
        img = _normalise(self._rectifier(image))
        levels = []
        scale = 1.0
        k = 0
        while True:
            if k >= cfg.finest_level:
                levels.append(_Level(img, scale, cfg.smoothing))
            if min(img.shape) // 2 < cfg.min_level_size:
                break
            img = cv2.pyrDown(img)
            scale *= 0.5
            k += 1
        if not levels:  # finest_level beyond the coarsest level: use the coarsest
            levels.append(_Level(img, scale, cfg.smoothing))
        return levels

    # ---------------------------------------------------------------- conversions
    def _to_rectified(self, m_level: np.ndarray, level: _Level) -> np.ndarray:
        """A similarity on centred level coordinates as one on rectified coordinates."""
        a = self._level_to_rect(level)
        return (a @ _mat3(m_level) @ np.linalg.inv(a))[:2]

    def _level_to_rect(self, level: _Level) -> np.ndarray:
        """The 3 x 3 map from centred level coordinates to rectified coordinates."""
        s = level.scale
        p = self._rectifier.pitch
        # rect = pitch * ((x_level + centre) / s + offset) + origin, with the pyrDown pixel-centre convention
        a = np.array([[p / s, 0.0, p * (level.centre[0] / s + self._offset(s))],
                      [0.0, p / s, p * (level.centre[1] / s + self._offset(s))], [0.0, 0.0, 1.0]])
        a[:2, 2] += self._rectifier.origin
        return a

    def _to_level(self, m_rect: np.ndarray, level: _Level) -> np.ndarray:
        a = self._level_to_rect(level)
        return (np.linalg.inv(a) @ _mat3(m_rect) @ a)[:2]

    @staticmethod
    def _offset(s: float) -> float:
        # a pixel of a level reduced 1/s times covers full-resolution pixels centred at (x + 0.5) / s - 0.5
        return 0.5 / s - 0.5

    # ---------------------------------------------------------------- alignment
    def align(self, ref: list[_Level], cur: list[_Level], guesses: list[tuple[str, np.ndarray]]) -> Alignment:
        """Align ``cur`` to ``ref`` from each guess (rectified similarities) in turn; see the module."""
        cfg = self.config
        starts = list(guesses)
        shift = self._phase_shift(ref[-1], cur[-1])
        if shift is not None:
            starts.append(("global", shift))
        starts.append(("retry", np.eye(2, 3)))
        best: Alignment | None = None
        tried = []
        for name, guess in starts:
            if any(np.abs(guess - g).max() < 0.5 for g in tried):
                continue
            tried.append(guess)
            result = self._align_from(ref, cur, guess)
            result.start = name
            if result.status is MotionStatus.OK and result.correlation >= cfg.min_correlation:
                return result
            if best is None or (result.correlation > best.correlation or best.status is not MotionStatus.OK
                                and result.status is MotionStatus.OK):
                best = result
        if best is not None and best.status is MotionStatus.OK and best.correlation < cfg.min_correlation_fallback:
            best.status = MotionStatus.REJECTED
            best.reason = f"correlation {best.correlation:.2f} after alignment below {cfg.min_correlation_fallback:g}"
        return best

    def _phase_shift(self, ref: _Level, cur: _Level) -> np.ndarray | None:
        a, c = ref.image, cur.image
        if self._hann is None or self._hann.shape != a.shape:
            self._hann = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_32F)
        (dx, dy), response = cv2.phaseCorrelate(a, c, self._hann)
        if not response > 0.02:
            return None
        m_level = np.array([[1.0, 0.0, dx], [0.0, 1.0, dy]])
        return self._to_rectified(m_level, ref)

    def _align_from(self, ref: list[_Level], cur: list[_Level], guess: np.ndarray) -> Alignment:
        cfg = self.config
        fail = Alignment(MotionStatus.REJECTED, np.eye(2, 3), np.diag([np.inf] * 4))
        m_rect = np.asarray(guess, dtype=np.float64)
        for k in range(len(ref) - 1, -1, -1):
            m = self._to_level(m_rect, ref[k])
            m, stats = self._gauss_newton(ref[k], cur[k], m, final=(k == 0))
            if m is None:
                fail.reason = stats
                fail.status = MotionStatus.TOO_FEW_FEATURES
                return fail
            m_rect = self._to_rectified(m, ref[k])
        params = similarity_params(m_rect)
        if abs(params[3]) > cfg.max_abs_log_scale:
            fail.reason = f"implausible scale {math.exp(params[3]):.3f}"
            return fail
        cov_level, corr, overlap = stats
        # covariance of (a, b, tx, ty) on the finest level -> (tx, ty, angle, log s) in rectified px
        cov = self._propagate(cov_level, m, ref[0], m_rect)
        if not np.all(np.isfinite(cov)):
            fail.reason = "singular photometric Hessian"
            fail.status = MotionStatus.DEGENERATE
            return fail
        return Alignment(MotionStatus.OK, m_rect, cov, corr, overlap)

    def _propagate(self, cov_abt: np.ndarray, m_level: np.ndarray, level: _Level, m_rect: np.ndarray) -> np.ndarray:
        """Covariance of ``(tx, ty, angle, log s)`` of ``m_rect`` from that of the level's ``(a, b, tx, ty)``.

        Numerically: the Jacobian of the rectified parameters with respect to a right-composed
        perturbation ``W(δp)`` of the level similarity, by central differences.
        """
        base = _mat3(m_level)
        J = np.zeros((4, 4))
        h = 1e-6
        p0 = similarity_params(m_rect)
        for i in range(4):
            d = np.zeros(4)
            d[i] = h
            pert = np.array([[1 + d[0], -d[1], d[2]], [d[1], 1 + d[0], d[3]], [0, 0, 1]])
            plus = similarity_params(self._to_rectified((base @ pert)[:2], level))
            pert_m = np.array([[1 - d[0], d[1], -d[2]], [-d[1], 1 - d[0], -d[3]], [0, 0, 1]])
            minus = similarity_params(self._to_rectified((base @ pert_m)[:2], level))
            diff = plus - minus
            diff[2] = math.remainder(diff[2], 2 * math.pi)
            J[:, i] = diff / (2 * h)
        del p0
        return J @ cov_abt @ J.T

    def _gauss_newton(self, ref: _Level, cur: _Level, m: np.ndarray, final: bool):
        """Inverse-compositional Gauss-Newton on one level; ``(m, stats)`` or ``(None, reason)``."""
        cfg = self.config
        h, w = ref.image.shape
        border = 2
        sd, xy, idx = ref.steepest_descent(border, cfg.max_pixels, cfg.region)
        sd_t = ref.steepest_descent_t()
        t0 = ref.image.ravel()[idx]
        centre = ref.centre
        valid_frac = 0.0
        reach = math.hypot(w, h) / 2
        huber = np.float32(cfg.huber)
        iterations = cfg.iterations if not final or cfg.finest_iterations is None else cfg.finest_iterations
        for _ in range(iterations):
            # warp the current frame back: sample I1 at W(x) for every reference pixel x (float32 throughout:
            # the sums of the 4 x 4 normal equations lose nothing that matters at these pixel counts)
            i1 = _sample(cur.image, m, xy, centre)
            valid = np.isfinite(i1)
            n_valid = int(np.count_nonzero(valid))
            valid_frac = n_valid / len(idx)
            if valid_frac < cfg.min_overlap:
                return None, f"only {100 * valid_frac:.0f} % of the reference stays in view"
            e = i1 - t0
            e[~valid] = 0.0
            abs_e = np.abs(e)
            # Huber weights on the normalised residual; the scale from the median of at most 4096 residuals
            sample = abs_e[valid]
            if n_valid > 4096:
                sample = sample[:: n_valid // 4096]
            sigma = np.float32(1.4826 * float(np.median(sample)) + 1e-6)
            w_pix = np.minimum(np.float32(1.0), (huber * sigma) / np.maximum(abs_e, np.float32(1e-12)))
            w_pix[~valid] = 0.0
            sdw_t = sd_t * w_pix
            H = (sdw_t @ sd).astype(np.float64)
            g = (sdw_t @ e).astype(np.float64)
            try:
                dp = np.linalg.solve(H, g)
            except np.linalg.LinAlgError:
                return None, "singular photometric Hessian"
            upd = np.array([[1 + dp[0], -dp[1], dp[2]], [dp[1], 1 + dp[0], dp[3]], [0.0, 0.0, 1.0]])
            m = (_mat3(m) @ np.linalg.inv(upd))[:2]
            # largest displacement of the update over the level's corners
            if abs(dp[2]) + abs(dp[3]) + reach * (abs(dp[0]) + abs(dp[1])) < cfg.epsilon:
                break
        if not final:
            return m, None
        # statistics on the final warp
        i1 = _sample(cur.image, m, xy, centre).astype(np.float64)
        t0 = t0.astype(np.float64)
        sd = sd.astype(np.float64)
        valid = np.isfinite(i1)
        if np.count_nonzero(valid) < 64:
            return None, "the frames do not overlap"
        a, b = t0[valid], i1[valid]
        a0, b0 = a - a.mean(), b - b.mean()
        corr = float(np.dot(a0, b0) / max(math.sqrt(float(np.dot(a0, a0)) * float(np.dot(b0, b0))), 1e-12))
        e = np.where(valid, i1 - t0, 0.0)
        inlier = valid & (np.abs(e) <= 3.0 * (1.4826 * float(np.median(np.abs(e[valid]))) + 1e-6))
        n_in = int(np.count_nonzero(inlier))
        sd_in = sd[inlier]
        H = sd_in.T @ sd_in
        var = max(float(np.dot(e[inlier], e[inlier])) / max(n_in - 4, 1), cfg.min_sigma**2)
        kappa = _correlation_inflation(np.where(inlier, e, np.nan), idx, (h, w))
        try:
            cov = kappa * var * np.linalg.inv(H)
        except np.linalg.LinAlgError:
            return None, "singular photometric Hessian"
        return m, (cov, corr, valid_frac)


def _sample(image: np.ndarray, m: np.ndarray, xy: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``image`` (centred-coordinate similarity ``m``) at ``W(xy)``; NaN outside the image."""
    a = m[:, :2].astype(np.float32)
    b = (m[:, 2] + centre).astype(np.float32)
    mx = (xy[0] * a[0, 0] + xy[1] * a[0, 1] + b[0]).reshape(1, -1)
    my = (xy[0] * a[1, 0] + xy[1] * a[1, 1] + b[1]).reshape(1, -1)
    out = cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
    return out.ravel()


def _correlation_inflation(values: np.ndarray, idx: np.ndarray, shape: tuple[int, int]) -> float:
    """Variance inflation ``κ = Π_axes Σ_d ρ^(d²)`` of spatially correlated residuals.

    The residual image's autocorrelation is modelled as Gaussian, ``C(d) = ρ^(d²)`` along each axis
    (smoothing and interpolation make it so), with ``ρ`` its measured lag-one correlation; ``κ`` is the
    number of pixels that carry the information of one independent sample. ``values`` (NaN: not used)
    belong to the pixels of flat indices ``idx`` (increasing) of an image of ``shape``; the lag-one pairs
    are found among them by a sorted search rather than on the whole image.
    """
    h, w = shape
    idx = np.asarray(idx)
    kappa = 1.0
    for lag in (1, w):  # right neighbour, lower neighbour
        j = np.searchsorted(idx, idx + lag)
        j = np.minimum(j, len(idx) - 1)
        pair = idx[j] == idx + lag
        if lag == 1:
            pair &= (idx % w) != w - 1  # not across a row end
        x, y = values[pair], values[j[pair]]
        ok = np.isfinite(x) & np.isfinite(y)
        if np.count_nonzero(ok) < 16:
            continue
        x, y = x[ok].astype(np.float64), y[ok].astype(np.float64)
        rho = float(np.dot(x, y) / max(math.sqrt(float(np.dot(x, x)) * float(np.dot(y, y))), 1e-12))
        rho = min(max(rho, 0.0), 0.98)
        d = np.arange(1, 64, dtype=np.float64)
        kappa *= 1.0 + 2.0 * float(np.sum(rho ** (d * d)))
    return kappa


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
        self._ref: list[_Level] | None = None
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

    def _set_reference(self, levels: list[_Level], t: float, texture: float) -> None:
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
        self._cache: tuple[int, list[_Level]] | None = None

    def _levels(self, image: np.ndarray) -> list[_Level]:
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
        (little texture, blur, the fixed vignetting and highlight) it can slide into a wrong minimum,
        such as a 4.8 degree turn at correlation 0.33 where the points measured the true 0.04 degrees.
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
