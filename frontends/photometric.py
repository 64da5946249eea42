"""Photometric alignment of a similarity between two frames, coarse to fine, with its covariance.

On each pyramid level (:mod:`frontends.pyramid`), from the coarsest, the similarity ``W(x; p)`` with
``p = (a, b, tx, ty)``::

    W(x; p) = [[1 + a, -b], [b, 1 + a]] x + (tx, ty)      (x relative to the image centre)

is refined by inverse-compositional Gauss-Newton (Baker & Matthews 2004): the steepest-descent images
``SD = ∇I_0 · ∂W/∂p = [I_x x + I_y y, -I_x y + I_y x, I_x, I_y]`` and the Hessian ``H = Σ w SD^T SD``
are those of the reference frame; each iteration warps the current frame back by ``W``, takes the
error ``e = I_1(W(x)) - I_0(x)`` and updates ``W <- W ∘ W(Δp)^{-1}`` with ``Δp = H^{-1} Σ w SD^T e``.
Huber weights ``w`` limit the pull of occlusions, specular highlights and pixels that left the view.

Starting points: the guesses given (a constant-velocity prediction), then the translation found by
phase correlation at the coarsest level, then zero motion. The first start whose result correlates
well with the reference (zero-normalised cross-correlation ``ZNCC`` over the overlap of at least
``min_correlation``) is taken; otherwise the best one, if any passes ``min_correlation_fallback``.

Covariance
----------
On the finest level, with residual variance ``σ²`` and the Gauss-Newton Hessian ``H`` (unit weights
on the inliers), ``Σ_p = κ σ² H^{-1}``. Neighbouring residuals are correlated (blur, interpolation),
so ``κ`` is the variance inflation of a field with a separable Gaussian autocorrelation,
``κ = Π_axes Σ_d ρ^(d²)``, with ``ρ`` the measured lag-one correlation of the residual image along
each axis. ``Σ_p`` is then propagated to the ``(tx, ty, angle, log s)`` of :mod:`frontends.base` in
rectified pixels. A blurred or weakly textured frame has a small ``H`` and a large ``σ``: it is
weighted down, not dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from frontends.base import IdentityMap, MotionStatus, PointMap, similarity_params
from frontends.direct_config import DirectConfig
from frontends.pyramid import Level, Rectifier, normalise, pyramid


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
        self._rectifier: Rectifier | None = None
        self._hann: np.ndarray | None = None

    def prepare(self, image: np.ndarray) -> list[Level]:
        """The rectified, normalised pyramid of a raw ``uint8`` frame (finest level first)."""
        if self._rectifier is None or self._rectifier_raw_shape != image.shape:
            self._rectifier = Rectifier(self.point_map, image.shape, self.config.grid_limit)
            self._rectifier_raw_shape = image.shape
        cfg = self.config
        return pyramid(normalise(self._rectifier(image)), cfg.min_level_size, cfg.finest_level, cfg.smoothing)

    # ---------------------------------------------------------------- conversions
    def _to_rectified(self, m_level: np.ndarray, level: Level) -> np.ndarray:
        """A similarity on centred level coordinates as one on rectified coordinates."""
        a = self._level_to_rect(level)
        return (a @ _mat3(m_level) @ np.linalg.inv(a))[:2]

    def _level_to_rect(self, level: Level) -> np.ndarray:
        """The 3 x 3 map from centred level coordinates to rectified coordinates."""
        s = level.scale
        p = self._rectifier.pitch
        # rect = pitch * ((x_level + centre) / s + offset) + origin, with the pyrDown pixel-centre convention
        a = np.array([[p / s, 0.0, p * (level.centre[0] / s + self._offset(s))],
                      [0.0, p / s, p * (level.centre[1] / s + self._offset(s))], [0.0, 0.0, 1.0]])
        a[:2, 2] += self._rectifier.origin
        return a

    def _to_level(self, m_rect: np.ndarray, level: Level) -> np.ndarray:
        a = self._level_to_rect(level)
        return (np.linalg.inv(a) @ _mat3(m_rect) @ a)[:2]

    @staticmethod
    def _offset(s: float) -> float:
        # a pixel of a level reduced 1/s times covers full-resolution pixels centred at (x + 0.5) / s - 0.5
        return 0.5 / s - 0.5

    # ---------------------------------------------------------------- alignment
    def align(self, ref: list[Level], cur: list[Level], guesses: list[tuple[str, np.ndarray]]) -> Alignment:
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

    def _phase_shift(self, ref: Level, cur: Level) -> np.ndarray | None:
        a, c = ref.image, cur.image
        if self._hann is None or self._hann.shape != a.shape:
            self._hann = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_32F)
        (dx, dy), response = cv2.phaseCorrelate(a, c, self._hann)
        if not response > 0.02:
            return None
        m_level = np.array([[1.0, 0.0, dx], [0.0, 1.0, dy]])
        return self._to_rectified(m_level, ref)

    def _align_from(self, ref: list[Level], cur: list[Level], guess: np.ndarray) -> Alignment:
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

    def _propagate(self, cov_abt: np.ndarray, m_level: np.ndarray, level: Level, m_rect: np.ndarray) -> np.ndarray:
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

    def _gauss_newton(self, ref: Level, cur: Level, m: np.ndarray, final: bool):
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
