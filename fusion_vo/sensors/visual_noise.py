"""The camera's heading noise from the gyro's, without ground truth (``fusion: {visual_noise: {estimate: true}}``).

The camera and the gyro both measure every node interval's heading change. Their difference

    d_k = c_k - g_k = e_k - n_k - b Δt_k

holds the camera's error ``e_k``, the gyro's white noise ``n_k`` (``Var n_k = σ_g² Δt_k``, the gyro's stated
noise, which is honest per interval: NIS 0.96-1.02 on the generated recordings) and its slowly changing bias
``b``. The bias is removed with the running mean of ``d`` over :data:`WINDOW` intervals (10 s at 20 Hz):
``r_k = d_k - mean_W(d)_k``. The mean takes ``1/W`` of each term's own variance with it, and consecutive
residuals share ``-1/W`` of theirs through it; both are in the variances below. (A running mean, not
differences at a lag of a few intervals: those would remove a constant bias exactly, but also every camera
error that persists over a few frames, most of the realistic renders' errors;
docs/decisions/0018-camera-noise-from-the-gyro-off-by-default.md.) With the camera's true
heading variance ``s σ_c,k²`` (``σ_c,k²`` its stated one) and its errors correlated at ``-f/2`` between
consecutive intervals (the moving-average model of :mod:`fusion_vo.sensors.visual`,
``visual_frame_error = f``)::

    Var r_k = (s σ_c,k² + σ_g,k²) (1 - 1/W)
    Cov(r_k, r_k+1) = -f/2 s σ_c,k σ_c,k+1 - (s σ_c,k² + σ_g,k² + s σ_c,k+1² + σ_g,k+1²) / (2W)

Both are estimated robustly, from medians, each term weighted by its own stated variances:

* ``s`` solves ``median(r_k² / Var r_k(s)) = 0.4549``, the median of a χ² variable of one degree of
  freedom;
* ``f`` solves ``median(u_k² / Var u_k(f)) = median(v_k² / Var v_k(f))`` for the sum and the difference
  of consecutive residuals, ``u_k = r_k + r_k+1``, ``v_k = r_k - r_k+1`` (whose variances differ by
  four times the covariance: Gnanadesikan and Kettenring's robust covariance); the lag-1 correlation of
  the camera's errors is ``-f/2``. A positive correlation (errors that persist, not the moving average)
  gives ``f = 0``; ``f`` is clipped to ``[0, 0.9]``.

Their standard errors are the scatter of the same estimates over :data:`DRAWS` drives simulated from the
estimate (Gaussian errors of the estimated size and correlation on the recording's own intervals, with
their stated variances; a fixed seed). Either is applied only when resolved: ``s`` when its standard error is below
``scale_tolerance`` times it, ``f`` when its standard error is below ``frame_error_tolerance``. The camera
then enters both backends with its heading variance times ``s`` (its heading covariances with the
translation times ``√s``; possibly below the frontend's floor ``odometry.min_sigma_yaw``) and with
``visual_frame_error = f``; the translation is left as stated (camera and wheels are its only sensors,
so their variances cannot be told apart).

How far the data can resolve this is set by the gyro: its white noise is in every ``d_k``. On the
generated 20 Hz recordings the gyro's per-interval σ (38 µrad) is 2.5-3 times the camera's (12-16 µrad),
so the camera's part is about a tenth of ``Var d``; over a 30 s drive (600 intervals) the standard error
of ``f`` is then several tenths, and the estimate is reported but not applied. A third heading sensor
(the wheels, after their calibration) does not help there: their per-interval heading error against the
truth is 0.4-0.8 mrad before the calibration and at least 0.15 mrad after it (one tick over √6 on each
wheel, over the wheel base), 10-50 times the camera's, so the three-cornered hat's
``(Var(c-g) + Var(c-w) - Var(g-w)) / 2`` carries the sampling noise of two variances 100-2500 times the
camera's; it is not used.

Batch only: it runs where the whole recording is put on the node grid
(:func:`fusion_vo.backends.timeline.build_intervals`). Streaming fusion uses the configured noise and
``visual_frame_error`` as they are (a run says so in its notes).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from pydantic import Field

from fusion_vo.config.base import MAX_NUMBER, Int, Positive, Section
from fusion_vo.sensors import registry
from fusion_vo.sensors.gyro import GYRO

logger = logging.getLogger(__name__)

#: running mean [node intervals] whose removal takes out the gyro's slowly changing bias (10 s at 20 Hz)
WINDOW = 201
#: drives simulated from the estimate whose estimates' scatter gives its standard errors
DRAWS = 40
#: median of a χ² variable of one degree of freedom
_CHI2_MEDIAN = 0.45493642311957283
#: range searched for the scale and for the frame error before clipping (lag-1 correlation within ±0.95)
_SCALE_RANGE = (1e-3, 1e3)
_F_RANGE = (-1.9, 1.9)
_MAX_F = 0.9


class VisualNoiseConfig(Section):
    """The camera's heading noise estimated from the gyro's (:mod:`fusion_vo.sensors.visual_noise`)."""

    estimate: bool = Field(False, description=(
        "Estimate the scale of the camera's stated heading variance and its frames' share ``f`` "
        "(``visual_frame_error``) from the camera's and the gyro's heading changes, and use them where resolved. "
        "Needs a camera and a gyro; batch runs only."))
    min_intervals: Int = Field(200, ge=100, le=int(MAX_NUMBER), description=(
        "Fewest node intervals with both a camera increment and a gyro angle to estimate from."))
    scale_tolerance: Positive = Field(0.25, description=(
        "The scale is applied when its standard error is at most this fraction of it."))
    frame_error_tolerance: Positive = Field(0.15, description="``f`` is applied when its standard error is at most "
                                                              "this.")


@dataclass
class VisualNoiseEstimate:
    """What :func:`estimate` found (all None/NaN where it could not estimate).

    Attributes
    ----------
    intervals : int
        Node intervals with both a single-interval camera increment and a gyro angle.
    scale, scale_se : float
        Camera heading variance over its stated one, and its standard error.
    correlation, correlation_se : float
        Lag-1 correlation of the camera's heading errors (``-f/2`` before clipping), and its standard error.
    frame_error : float
        ``f`` from it, clipped to ``[0, 0.9]``.
    scale_applied, frame_error_applied : bool
        Whether each was resolved and used.
    note : str
        One line for the run's notes.
    """

    intervals: int = 0
    scale: float = float("nan")
    scale_se: float = float("nan")
    correlation: float = float("nan")
    correlation_se: float = float("nan")
    frame_error: float = float("nan")
    scale_applied: bool = False
    frame_error_applied: bool = False
    note: str = ""

    def as_dict(self) -> dict:
        """JSON-friendly (NaN as None)."""
        out = {}
        for key, value in self.__dict__.items():
            out[key] = None if isinstance(value, float) and not np.isfinite(value) else value
        return out


def _solve(fun, lo: float, hi: float) -> float:
    """Root of the decreasing ``fun`` in ``[lo, hi]`` (the nearer end when it has none there)."""
    from scipy.optimize import brentq

    a, b = fun(lo), fun(hi)
    if not (np.isfinite(a) and np.isfinite(b)):
        return float("nan")
    if a <= 0:
        return lo
    if b >= 0:
        return hi
    return float(brentq(fun, lo, hi, xtol=1e-6 * max(1.0, abs(hi))))


def _series(d, vc, vg, ok) -> tuple | None:
    """The differences less their running mean over :data:`WINDOW` intervals, and the sums and differences of
    consecutive ones, with their stated variances (module docstring): ``(k, r, a, g, u, v, su, gu, b, 1 - 2/W)``,
    ``k`` the intervals of ``r``; None when the grid is too short."""
    from scipy.ndimage import uniform_filter1d

    K = len(d)
    k = np.flatnonzero(ok)
    if len(k) < 16:
        return None
    w = min(WINDOW, len(k) - 1 + len(k) % 2)  # odd, at most the series
    shrink = 1.0 - 1.0 / w
    r = np.full(K, np.nan)
    r[k] = d[k] - uniform_filter1d(d[k], w, mode="nearest")
    sc = np.sqrt(np.where(ok, vc, np.nan))
    p = k[k + 1 < K]
    p = p[np.isfinite(r[p + 1])]
    # Var(r_k ± r_k+1) = S (1 - 1/W) ± 2 Cov = S (1 - 2/W) - f s b  or  S + f s b, S = s (σ_c,k² + σ_c,k+1²) + ...
    su, gu = vc[p] + vc[p + 1], vg[p] + vg[p + 1]
    return (k, r[k], vc[k] * shrink, vg[k] * shrink, r[p] + r[p + 1], r[p] - r[p + 1], su, gu,
            sc[p] * sc[p + 1], 1.0 - 2.0 / w)


def _fit(series) -> tuple[float, float]:
    """``(s, lag-1 correlation)`` from :func:`_series` (module docstring): ``s`` from the residuals
    (variances ``s a + g``), the correlation ``-f/2`` from the sums and differences of consecutive ones
    (variances ``(s su + gu) (1 - 2/W) - f s b`` and ``s su + gu + f s b``)."""
    _, r, a, g, u, v, su, gu, b, shrink = series
    s = _solve(lambda x: np.median(r**2 / (x * a + g)) - _CHI2_MEDIAN, *_SCALE_RANGE)
    if not np.isfinite(s) or len(u) < 8:
        return s, float("nan")
    total, b_s = s * su + gu, s * b

    def gap(f):  # decreasing in f: the sums' variance falls, the differences' rises
        return np.median(v**2 / (total + f * b_s)) - np.median(u**2 / (total * shrink - f * b_s))

    return s, -0.5 * _solve(gap, *_F_RANGE)


def _simulated_scatter(s: float, correlation: float, vc, vg, ok, draws: int) -> tuple[float, float]:
    """Standard deviations of :func:`_fit`'s two estimates over ``draws`` drives simulated from the estimate
    itself (Gaussian camera errors of variance ``s σ_c²`` with the moving-average share ``f``, gyro errors of
    ``σ_g²``, on the same intervals); a fixed seed, so that a run is repeatable."""
    rng = np.random.default_rng(20_251_202)
    f = float(np.clip(-2.0 * correlation, 0.0, _MAX_F)) if np.isfinite(correlation) else 0.0
    K = len(vc)
    sc = np.sqrt(np.where(ok, s * vc, 0.0))
    sg = np.sqrt(np.where(ok, vg, 0.0))
    frame_sigma = np.sqrt(0.5 * f) * sc
    out = []
    for _ in range(draws):
        frame = rng.standard_normal(K + 1)
        camera = np.sqrt(1.0 - f) * sc * rng.standard_normal(K) + frame_sigma * (frame[1:] - frame[:-1])
        gyro = sg * rng.standard_normal(K)
        out.append(_fit(_series(np.where(ok, camera - gyro, np.nan), vc, vg, ok)))
    est = np.array(out)
    return float(np.nanstd(est[:, 0], ddof=1)), float(np.nanstd(est[:, 1], ddof=1))


def estimate(camera, camera_var, gyro, gyro_var, config: VisualNoiseConfig) -> VisualNoiseEstimate:
    """The camera's heading noise from its and the gyro's heading changes on the node grid (module docstring).

    Parameters
    ----------
    camera, camera_var : ndarray (K,)
        The camera's heading change per node interval [rad] and its stated variance [rad²] (NaN where no
        single-interval increment).
    gyro, gyro_var : ndarray (K,)
        The gyro's integrated angle [rad] and its stated variance ``σ_g² Δt`` [rad²] (NaN where none).
    config : VisualNoiseConfig

    Returns
    -------
    VisualNoiseEstimate
    """
    c, vc = np.asarray(camera, dtype=np.float64), np.asarray(camera_var, dtype=np.float64)
    gy, vg = np.asarray(gyro, dtype=np.float64), np.asarray(gyro_var, dtype=np.float64)
    ok = np.isfinite(c) & np.isfinite(vc) & (vc > 0) & np.isfinite(gy) & np.isfinite(vg) & (vg > 0)
    out = VisualNoiseEstimate(intervals=int(np.count_nonzero(ok)))
    series = _series(np.where(ok, c - gy, np.nan), vc, vg, ok)
    if out.intervals < config.min_intervals or series is None or len(series[0]) < config.min_intervals // 2:
        out.note = (f"camera heading noise not estimated: {out.intervals} intervals with both a camera increment "
                    f"and a gyro angle, fewer than visual_noise.min_intervals ({config.min_intervals})")
        return out
    out.scale, out.correlation = _fit(series)
    out.scale_se, out.correlation_se = _simulated_scatter(out.scale, out.correlation, vc, vg, ok, DRAWS)
    out.frame_error = float(np.clip(-2.0 * out.correlation, 0.0, _MAX_F)) if np.isfinite(out.correlation) else 0.0
    out.scale_applied = bool(np.isfinite(out.scale_se) and out.scale_se <= config.scale_tolerance * out.scale)
    out.frame_error_applied = bool(np.isfinite(out.correlation_se)
                                   and 2.0 * out.correlation_se <= config.frame_error_tolerance)
    used = [w for w, on in (("scale", out.scale_applied), ("frame error", out.frame_error_applied)) if on]
    out.note = (f"camera heading noise from camera minus gyro over {out.intervals} intervals: variance "
                f"{out.scale:.2f} ± {out.scale_se:.2f} times the stated, lag-1 correlation {out.correlation:+.2f} "
                f"± {out.correlation_se:.2f} (frame error f = {out.frame_error:.2f}); "
                + (f"used: {' and '.join(used)}" if used else "not resolved, the stated noise is used"))
    return out


def _at_rest(iv, config) -> np.ndarray:
    """The node intervals in which a heading source says the robot stands still (the wheels',
    :attr:`~fusion_vo.sensors.sources.HeadingSource.at_rest`); none without one."""
    return next((h.at_rest(iv, config) for _, h in registry.heading_sources() if h.at_rest is not None),
                np.zeros(iv.n_steps, bool))


def apply(iv, config) -> VisualNoiseEstimate | None:
    """Estimate the camera's heading noise on the whole recording's grid ``iv`` and put what is resolved into
    it: the increments' heading (co)variances scaled, the camera's frame-error share set
    (:class:`~fusion_vo.sensors.visual.CameraGrid` ``cov``, ``frame_error``). Returns the estimate, also kept as
    the grid's ``noise`` (its note added to ``iv.notes``), or None when ``config.visual_noise.estimate`` is off."""

    # (the camera's and the IMU's grids, :class:`~fusion_vo.sensors.visual.CameraGrid` and
    # :class:`~fusion_vo.sensors.imu.ImuGrid`, read from ``iv``: visual.py imports this module, imu.py visual.py)
    cfg, cam, imu = config.visual_noise, iv.sensors["camera"], iv.sensors["imu"]
    if not cfg.estimate:
        return None
    if not len(cam.i0) or not iv.uses("gyro"):
        out = VisualNoiseEstimate(note="camera heading noise not estimated: it needs the camera and the gyro")
    elif cam.frame_cov is not None:  # a calibrated model is better than this estimate, and would not add up
        out = VisualNoiseEstimate(note="camera heading noise not estimated: the increments state their own "
                                       "(camera_noise of cam0/sensor.yaml)")
    else:
        K = iv.n_steps
        camera, camera_var = np.full(K, np.nan), np.full(K, np.nan)
        single = cam.i1 == cam.i0 + 1
        camera[cam.i0[single]] = cam.delta[single, 2]
        camera_var[cam.i0[single]] = cam.cov[single, 2, 2]
        gyro = np.where(imu.gyro_ok, imu.gyro_angle, np.nan)
        gyro_var = GYRO.variance(config.imu.density(_at_rest(iv, config)), iv.dt) * np.ones(K)
        out = estimate(camera, camera_var, gyro, gyro_var, cfg)
    if out.scale_applied:
        root = np.sqrt(out.scale)
        cam.cov = cam.cov.copy()
        cam.cov[:, 2, :] *= root
        cam.cov[:, :, 2] *= root
    if out.frame_error_applied:
        cam.frame_error = out.frame_error
    cam.noise = out
    iv.notes.append(out.note)
    logger.info("%s", out.note)
    return out
