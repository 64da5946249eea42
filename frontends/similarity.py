"""Robust estimation of a non-reflective similarity from point correspondences.

Model
-----
Writing a point as the complex number ``z = u + i v``, a non-reflective similarity is

.. math::  w = a z + b,\\qquad a = s\\,e^{i\\theta},\\quad b = t_x + i t_y

with parameters ``p = (tx, ty, theta, log s)`` (the order used by :mod:`frontends.base`).

Minimal solver
    two correspondences fix it: ``a = (w1 - w2) / (z1 - z2)``, ``b = w1 - a z1``.

Least squares
    on ``n`` correspondences the linear least-squares solution (Umeyama / Horn, exact for this model) is
    ``a = sum (w_k - w_bar) conj(z_k - z_bar) / sum |z_k - z_bar|^2`` and ``b = w_bar - a z_bar``.

Covariance
    the residual Jacobian with respect to ``p`` for a correspondence whose rotated-and-scaled source is
    ``q = a z`` has rows ``[1, 0, -Im q, Re q]`` and ``[0, 1, Re q, Im q]``, so that

    .. math::  \\Sigma_p = \\sigma^2 (J^T J)^{-1},\\qquad
               \\sigma^2 = \\max\\Big(\\frac{\\sum_k |r_k|^2}{2n - 4},\\ \\sigma_{min}^2\\Big)

    The floor ``sigma_min`` keeps a perfect (noise-free) match from claiming a zero covariance.

Robust search
    RANSAC scores hypotheses with the truncated quadratic (MSAC) cost ``sum min(r^2, t^2)`` and stops
    after ``N = log(1 - confidence) / log(1 - w^2)`` hypotheses, ``w`` the best inlier ratio so far.
    LMedS keeps the hypothesis with the least median squared residual and takes as inliers the points
    within ``2.5 sigma_r`` with ``sigma_r = 1.4826 (1 + 5 / (n - 2)) sqrt(median r^2)`` (Rousseeuw).
    Both are followed by alternating least-squares refits and inlier re-selection.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np
from pydantic import Field

from frontends.base import MotionStatus
from frontends.config import INTEGER, NUMBER, Float, Int, Settings

logger = logging.getLogger(__name__)

_BATCH = 32  # hypotheses scored per vectorised batch
_LOG_ONE_MINUS_EPS = math.log1p(-1e-12)

#: the estimator's options, which the point-based frontends' settings share (each with its own default;
#: see :mod:`frontends.options`)
RobustMethod = Annotated[Literal["ransac", "lmeds"], Field(
    description="Robust estimator: ``ransac`` or ``lmeds``. RANSAC scores hypotheses by MSAC and draws as many as "
                "``confidence`` needs; LMedS keeps the one of least median squared residual.")]
InlierDistance = Annotated[float, Field(
    gt=0, description="Inlier distance of the robust estimator [rectified px]."), NUMBER]
Confidence = Annotated[float, Field(
    gt=0, lt=1, description="RANSAC confidence. The search ends when at least one all-inlier sample has been drawn "
                            "with this probability."), NUMBER]
Hypotheses = Annotated[int, Field(
    ge=1, le=100_000, description="Maximum number of robust-estimator hypotheses."), INTEGER]
ResidualFloor = Annotated[float, Field(
    ge=0, description="Floor of the residual standard deviation used for the covariance [px]. 0: the residuals' "
                      "own spread, however small."), NUMBER]
MinInliers = Annotated[int, Field(
    ge=2, le=10_000, description="Fewer inliers reject the frame (``TOO_FEW_FEATURES``). A similarity needs two "
                                 "points."), INTEGER]
MaxLogScale = Annotated[float, Field(
    gt=0, le=10, description="Largest plausible ``|log s|`` between consecutive frames; a larger scale change "
                             "is rejected."), NUMBER]
MinSpread = Annotated[float, Field(
    ge=0, description="Smallest standard deviation of the inliers along their weakest axis [px] (``DEGENERATE`` "
                      "below). Below it the points are nearly collinear or clustered."), NUMBER]


class RobustOptions(Settings):
    """Settings of the robust similarity estimator (:func:`estimate_similarity`)."""

    method: RobustMethod = "ransac"
    threshold: InlierDistance = Field(1.0, description=(
        "Inlier distance [rectified px] for RANSAC; also the upper bound of the LMedS inlier distance."))
    confidence: Confidence = 0.999
    max_iterations: Hypotheses = 256
    min_sample_distance: Float = Field(8.0, ge=0, description=(
        "Two-point samples closer than this are discarded: they fix the angle poorly [px]."))
    max_abs_log_scale: MaxLogScale = Field(0.2, description="Hypotheses with ``|log s|`` above this are discarded "
                                                            "before scoring.")
    refine_iterations: Int = Field(3, ge=0, le=100, description=(
        "Alternations of least-squares refit and inlier re-selection after the search."))
    min_sigma: ResidualFloor = 0.02
    min_inliers: MinInliers = Field(6, description="Fewer inliers than this give the status ``too_few``.")
    min_spread: MinSpread = 10.0


@dataclass
class SimilarityFit:
    """Result of :func:`estimate_similarity`.

    Attributes
    ----------
    status : str
        ``"ok"``, ``"too_few"`` (not enough correspondences or inliers) or ``"degenerate"``.
    matrix : ndarray, shape (2, 3)
        Similarity mapping source to destination points (identity unless ``status == "ok"``).
    params : ndarray, shape (4,)
        ``(tx, ty, angle, log_scale)`` of ``matrix``.
    covariance : ndarray, shape (4, 4)
        Covariance of ``params`` (infinite diagonal unless ``status == "ok"``).
    inliers : ndarray of bool, shape (n,)
        Correspondences consistent with the estimate.
    n_inliers : int
    residual_rms : float
        RMS of the inlier residual vectors [px].
    sigma : float
        Per-coordinate residual standard deviation used for the covariance (after the floor) [px].
    iterations : int
        Hypotheses drawn by the robust search.
    prior_deviation : float
        Largest distance [px] between the estimate and the prior over the inliers (``nan`` without a prior).
    """

    status: str
    matrix: np.ndarray = field(default_factory=lambda: np.eye(2, 3))
    params: np.ndarray = field(default_factory=lambda: np.zeros(4))
    covariance: np.ndarray = field(default_factory=lambda: np.diag([np.inf] * 4))
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    n_inliers: int = 0
    residual_rms: float = float("nan")
    sigma: float = float("nan")
    iterations: int = 0
    prior_deviation: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def _complex(pts: np.ndarray) -> np.ndarray:
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    return pts[:, 0] + 1j * pts[:, 1]


def fit_least_squares(z: np.ndarray, w: np.ndarray) -> tuple[complex, complex]:
    """Closed-form least-squares similarity ``w ~ a z + b`` of complex point arrays."""
    zm, wm = z.sum() / len(z), w.sum() / len(w)  # np.mean's arithmetic without its call overhead
    dz = z - zm
    den = float(np.vdot(dz, dz).real)
    if den <= 0.0:
        return 1.0 + 0j, wm - zm
    a = np.vdot(dz, w - wm) / den  # vdot conjugates its first argument
    return complex(a), complex(wm - a * zm)


def _to_matrix(a: complex, b: complex) -> np.ndarray:
    return np.array([[a.real, -a.imag, b.real], [a.imag, a.real, b.imag]])


def _to_params(a: complex, b: complex) -> np.ndarray:
    return np.array([b.real, b.imag, math.atan2(a.imag, a.real), math.log(abs(a))])


def similarity_covariance(z: np.ndarray, a: complex, sigma: float) -> np.ndarray:
    """Covariance of ``(tx, ty, angle, log s)`` for complex source points ``z`` and residual ``sigma``.

    Uses the closed form of ``J^T J`` (the angle / log-scale cross term vanishes).
    """
    q = a * z
    n = float(len(z))
    sr, si, sq = float(q.real.sum()), float(q.imag.sum()), float(np.vdot(q, q).real)
    jtj = np.array(
        [
            [n, 0.0, -si, sr],
            [0.0, n, sr, si],
            [-si, sr, sq, 0.0],
            [sr, si, 0.0, sq],
        ]
    )
    return sigma * sigma * np.linalg.inv(jtj)


def _hypotheses(z, w, rng, count, opts):
    n = len(z)
    i = rng.integers(0, n, size=count)
    j = rng.integers(0, n - 1, size=count)
    j = j + (j >= i)  # distinct pairs without rejection
    dz = z[i] - z[j]
    valid = np.abs(dz) >= opts.min_sample_distance
    dz = np.where(valid, dz, 1.0)
    a = (w[i] - w[j]) / dz
    b = w[i] - a * z[i]
    valid &= np.abs(np.log(np.maximum(np.abs(a), 1e-12))) <= opts.max_abs_log_scale
    return a[valid], b[valid]


def _residuals_sq(z, w, a, b):
    """``|w - a z - b|^2`` for every hypothesis (rows) and correspondence (columns)."""
    r = w[None, :] - a[:, None] * z[None, :] - b[:, None]
    return r.real**2 + r.imag**2


def _search_ransac(z, w, rng, opts):
    t2 = opts.threshold**2
    best_cost, best = np.inf, None
    needed, drawn = opts.max_iterations, 0
    log_fail = math.log(1.0 - opts.confidence)
    n = len(z)
    while drawn < min(needed, opts.max_iterations):
        a, b = _hypotheses(z, w, rng, _BATCH, opts)
        drawn += _BATCH
        if len(a) == 0:
            continue
        r2 = _residuals_sq(z, w, a, b)
        cost = np.minimum(r2, t2).sum(axis=1)
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best_cost, best = cost[k], (complex(a[k]), complex(b[k]))
            ratio = float(np.count_nonzero(r2[k] < t2)) / n
            p_good = min(ratio * ratio, 1.0 - 1e-12)
            needed = 1 if p_good >= 1.0 - 1e-12 else int(math.ceil(log_fail / math.log1p(-p_good)))
    if best is None:
        return None, drawn, t2
    return best, drawn, t2


def _search_lmeds(z, w, rng, opts):
    # outlier ratio unknown: plan for up to 50 % outliers
    needed = int(math.ceil(math.log(1.0 - opts.confidence) / math.log(1.0 - 0.25)))
    best_med, best, drawn = np.inf, None, 0
    while drawn < min(needed, opts.max_iterations):
        a, b = _hypotheses(z, w, rng, _BATCH, opts)
        drawn += _BATCH
        if len(a) == 0:
            continue
        med = np.median(_residuals_sq(z, w, a, b), axis=1)
        k = int(np.argmin(med))
        if med[k] < best_med:
            best_med, best = med[k], (complex(a[k]), complex(b[k]))
    if best is None:
        return None, drawn, 0.0
    n = len(z)
    sigma_r = 1.4826 * (1.0 + 5.0 / max(n - 2, 1)) * math.sqrt(best_med)
    t = min(max(2.5 * sigma_r, 2.0 * opts.min_sigma), opts.threshold)
    return best, drawn, t * t


def estimate_similarity(
    src: np.ndarray,
    dst: np.ndarray,
    options: RobustOptions | None = None,
    rng: np.random.Generator | None = None,
    prior: np.ndarray | None = None,
) -> SimilarityFit:
    """Robustly estimate the similarity mapping ``src`` points onto ``dst`` points.

    Parameters
    ----------
    src, dst : ndarray, shape (n, 2)
        Corresponding points (rectified pixel coordinates).
    options : RobustOptions, optional
        Estimator settings (defaults of :class:`RobustOptions` when omitted).
    rng : numpy.random.Generator, optional
        Source of the random samples; a generator seeded with 0 when omitted (deterministic).
    prior : ndarray, shape (2, 3), optional
        Expected similarity; when given, :attr:`SimilarityFit.prior_deviation` reports how far the
        estimate moves the inliers away from where the prior puts them.

    Returns
    -------
    SimilarityFit
    """
    opts = options or RobustOptions()
    rng = rng if rng is not None else np.random.default_rng(0)
    z, w = _complex(src), _complex(dst)
    n = len(z)
    if len(w) != n:
        raise ValueError("src and dst must have the same number of points")
    finite = np.isfinite(z) & np.isfinite(w)
    if not finite.all():
        z, w = z[finite], w[finite]
    if len(z) < max(opts.min_inliers, 2):
        return SimilarityFit("too_few", inliers=np.zeros(n, dtype=bool))

    if opts.method == "ransac":
        best, drawn, t2 = _search_ransac(z, w, rng, opts)
    else:
        best, drawn, t2 = _search_lmeds(z, w, rng, opts)
    if best is None:
        return SimilarityFit("degenerate", inliers=np.zeros(n, dtype=bool), iterations=drawn)

    a, b = best
    r2 = np.abs(w - a * z - b) ** 2
    mask = r2 < t2
    for _ in range(opts.refine_iterations):
        if np.count_nonzero(mask) < 2:
            break
        a, b = fit_least_squares(z[mask], w[mask])
        r2 = np.abs(w - a * z - b) ** 2
        new_mask = r2 < t2
        if np.array_equal(new_mask, mask):
            break
        mask = new_mask
    else:
        if np.count_nonzero(mask) >= 2:
            a, b = fit_least_squares(z[mask], w[mask])
            r2 = np.abs(w - a * z - b) ** 2

    full_mask = np.zeros(n, dtype=bool)
    full_mask[np.flatnonzero(finite)[mask]] = True
    k = int(np.count_nonzero(mask))
    fit = SimilarityFit("ok", inliers=full_mask, n_inliers=k, iterations=drawn)
    if k < max(opts.min_inliers, 3):
        fit.status = "too_few"
        return fit
    zi = z[mask]
    dz = zi - zi.sum() / k
    # the smaller eigenvalue of the inliers' 2x2 covariance, in closed form: their spread along the weakest axis
    cxx, cyy, cxy = float((dz.real**2).sum() / k), float((dz.imag**2).sum() / k), float((dz.real * dz.imag).sum() / k)
    weakest = 0.5 * (cxx + cyy) - math.hypot(0.5 * (cxx - cyy), cxy)
    if math.sqrt(max(weakest, 0.0)) < opts.min_spread:
        fit.status = "degenerate"
        return fit

    ssr = float(r2[mask].sum())
    fit.residual_rms = math.sqrt(ssr / k)
    fit.sigma = max(math.sqrt(ssr / max(2 * k - 4, 1)), opts.min_sigma)
    fit.matrix = _to_matrix(a, b)
    fit.params = _to_params(a, b)
    fit.covariance = similarity_covariance(zi, a, fit.sigma)
    if prior is not None:
        pm = np.asarray(prior, dtype=np.float64)
        pa, pb = complex(pm[0, 0], pm[1, 0]), complex(pm[0, 2], pm[1, 2])
        fit.prior_deviation = float(np.max(np.abs((a - pa) * zi + (b - pb))))
    return fit


def judge_fit(fit: SimilarityFit, n_candidates: int, min_inlier_ratio: float, max_abs_log_scale: float,
              n_refined: int | None = None) -> tuple[MotionStatus, str]:
    """Whether a frontend accepts ``fit``: its status and, when rejected, the reason.

    A fit is rejected when the estimator found too few inliers or a degenerate set, when fewer than
    ``min_inlier_ratio * n_candidates`` correspondences are inliers, when a refinement kept fewer than
    half of the ``n_refined`` inliers it started from, or when ``|log s| > max_abs_log_scale``.
    """
    if fit.status == "too_few":
        return MotionStatus.TOO_FEW_FEATURES, "too few inliers"
    if fit.status == "degenerate":
        return MotionStatus.DEGENERATE, "inliers clustered or collinear"
    if fit.n_inliers < min_inlier_ratio * n_candidates:
        return MotionStatus.REJECTED, f"inlier ratio {fit.n_inliers}/{n_candidates} too low"
    if n_refined is not None and fit.n_inliers < 0.5 * n_refined:
        return MotionStatus.REJECTED, f"refinement kept {fit.n_inliers}/{n_refined} inliers"
    if abs(fit.params[3]) > max_abs_log_scale:
        return MotionStatus.REJECTED, f"implausible scale {math.exp(fit.params[3]):.3f}"
    return MotionStatus.OK, ""


def scale_motion(matrix: np.ndarray, k: float) -> np.ndarray:
    """The similarity ``M^k``: the same motion continued for ``k`` times as long.

    With ``w = a z + b``, ``M^k`` is ``w = a^k z + b (a^k - 1) / (a - 1)`` (``b k`` when ``a = 1``),
    the constant-velocity prediction of a motion measured over one interval onto ``k`` intervals.
    """
    m = np.asarray(matrix, dtype=np.float64)
    a, b = complex(m[0, 0], m[1, 0]), complex(m[0, 2], m[1, 2])
    if abs(a) <= 0.0:
        return np.eye(2, 3)
    ak = complex(np.exp(k * np.log(a)))
    bk = b * k if abs(a - 1.0) < 1e-9 else b * (ak - 1.0) / (a - 1.0)
    return _to_matrix(ak, bk)


def apply_similarity(matrix: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Apply a 2x3 similarity to ``N x 2`` points."""
    m = np.asarray(matrix, dtype=np.float64)
    return np.asarray(pts, dtype=np.float64) @ m[:, :2].T + m[:, 2]
