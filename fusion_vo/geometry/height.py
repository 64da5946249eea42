"""The camera height at every frame from a range finder's readings and the images' own change of scale.

A downward camera that rises by a fraction ``ε`` sees the floor shrink by the same fraction: the scale
``s`` of the frame-to-frame similarity measures the height ratio ``h_k / h_{k-1} = 1 / s_k`` very
precisely (on the generated ``tilted`` recording to 1.8e-5 per frame, against a range finder's 0.5 %),
but only as a ratio. A range finder measures the height itself, with its noise in every reading. Taken
together, in the logarithm ``x = log h`` at the frame times ``t_k``, they are a linear least-squares
problem:

.. math::

    x_k - x_{k-1} &= -\\log s_k + w_k, \\qquad w_k \\sim N(0,\\ \\varphi\\,(\\sigma_{s,k}^2 + \\sigma_{\\min}^2
                     + q^2 \\Delta t_k))\\\\
    \\log r_i &= (1 - a_i)\\, x_k + a_i\\, x_{k+1} + v_i, \\qquad v_i \\sim N(0,\\ (\\sigma_r / r_i)^2)

where ``σ_s`` is the frontend's standard deviation of ``log s``, ``σ_min`` a floor for what it does not
see (a floor that is not flat, a lens model that is not exact), ``q`` a random walk of the height
between frames, ``r_i`` a reading at ``t_i = (1 - a_i) t_k + a_i t_{k+1}`` and ``σ_r`` the readings'
standard deviation, measured from the readings themselves
(:func:`fusion_vo.sensors.range.reading_sigma`). Where a frame has no similarity (a failed frame, a
restart) only the random walk ``q_gap`` links its neighbours. The information matrix is tridiagonal: the
estimate is one banded Cholesky solve, and the standard deviation of every ``x_k`` comes from the
factor by the backward recurrence of Takahashi et al. (for ``A = L Lᵀ`` with ``L`` lower bidiagonal,
``Σ_kk = 1 / l_k² + (m_k / l_k)² Σ_{k+1,k+1}``), both in O(N).

Readings and ratios whose normalised residual exceeds ``huber`` are down-weighted (iteratively
reweighted least squares with Huber weights ``w(|r|) = min(1, huber / |r|)``,
:func:`fusion_vo.robust.robust_weight`), so that a spike the range gate let through, or a frame whose scale
the frontend got wrong, moves the heights around it by little.

The factor ``φ ≥ 1`` is estimated from the data (variance-component estimation): each ratio's squared
normalised residual is compared with its redundancy ``1 - (Σ_kk + Σ_{k-1,k-1} - 2 Σ_{k-1,k}) / var_k``
(the share of its variance the fit does not absorb), and ``φ`` is multiplied by their ratio until it
settles. On ``tilted`` it stays 1; on the independent renders (rocking, a lens model that is not exact)
it comes to 50-80, and the stated heights' errors then cover the actual ones.

Each frame's height then carries the noise of about ``σ_r / √n`` for the ``n`` readings within the span
over which the ratios stay precise, instead of one reading's ``σ_r``
(``docs/decisions/0020-camera-height-from-all-range-readings.md``). The smoothed errors are correlated
from frame to frame over that span; each increment's covariance takes its frame's standard deviation
(:meth:`fusion_vo.geometry.ground.GroundGeometry.body_increment`).

This uses every reading, also those after the frame: it is for offline runs
(:func:`fusion_vo.odometry.run_visual_odometry`, ``odometry: {range_smoothing: true}``, the default).
Live, :class:`HeightFilter` does the same causally, frame by frame (give it to
:class:`fusion_vo.odometry.VisualOdometry` with ``height_filter=`` and feed it the readings); streaming
fusion (:class:`fusion_vo.backends.streaming.StreamingFusion`) can instead take the readings as
measurements of the visual scale (:mod:`fusion_vo.sensors.range`), but not both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cholesky_banded, cho_solve_banded

from fusion_vo.robust import robust_weight


@dataclass
class HeightSmoothing:
    """Noise of the images' scale change, for :func:`smooth_heights`.

    Attributes
    ----------
    min_sigma : float
        Floor on the standard deviation of one frame's ``log s`` (default 3e-5; on ``tilted`` the KLT
        frontend states a median of 1.6e-5, and its errors against the truth are 1.8e-5 RMS).
    random_walk : float
        Random walk of the camera's log height between two frames with a similarity [1/√s] (default 1e-4).
    gap_random_walk : float
        Random walk across an interval without a similarity [1/√s] (default 0.3: a height known to a
        few per cent after a tenth of a second).
    huber : float
        Normalised residual beyond which a reading or a ratio is down-weighted (default 3).
    iterations : int
        Largest number of reweighting and variance-factor iterations (default 10).
    """

    min_sigma: float = 3e-5
    random_walk: float = 1e-4
    gap_random_walk: float = 0.3
    huber: float = 3.0
    iterations: int = 10


@dataclass
class SmoothedHeights:
    """``height`` [m] and ``sigma`` [m] at each frame time; how many readings and ratios were used and
    down-weighted; ``ratio_factor``: the factor the ratios' stated variances were multiplied by."""

    height: np.ndarray
    sigma: np.ndarray
    n_readings: int
    n_ratios: int
    n_downweighted: int
    ratio_factor: float = 1.0


def smooth_heights(frame_t: np.ndarray, log_ratio: np.ndarray, log_ratio_sigma: np.ndarray,
                   reading_t: np.ndarray, reading: np.ndarray, reading_sigma: float,
                   options: HeightSmoothing | None = None) -> SmoothedHeights | None:
    """Camera height at ``frame_t`` from range readings and the frames' height ratios (module docstring).

    Parameters
    ----------
    frame_t : (N,) array
        Frame times [s], increasing.
    log_ratio : (N,) array
        ``log(h_k / h_{k-1})`` measured between frame ``k - 1`` and frame ``k`` (``-log s`` of the
        similarity); NaN where there is none (``log_ratio[0]`` is not used).
    log_ratio_sigma : (N,) array
        Its standard deviation (the frontend's), NaN or inf where there is none.
    reading_t, reading : (M,) arrays
        Valid range readings: times [s] and distances [m] (the range gate already applied).
    reading_sigma : float
        Standard deviation of one reading [m].
    options : HeightSmoothing, optional

    Returns
    -------
    SmoothedHeights, or None when fewer than two readings fall within the frames' time span.
    """
    o = options or HeightSmoothing()
    t = np.asarray(frame_t, dtype=np.float64)
    n = len(t)
    rt = np.asarray(reading_t, dtype=np.float64)
    r = np.asarray(reading, dtype=np.float64)
    inside = np.isfinite(r) & (r > 0) & (rt >= t[0]) & (rt <= t[-1]) if n else np.zeros(0, bool)
    if n < 2 or np.count_nonzero(inside) < 2 or not reading_sigma > 0:
        return None
    rt, r = rt[inside], r[inside]
    # each reading as an interpolation between the frames around it
    j = np.clip(np.searchsorted(t, rt, side="right") - 1, 0, n - 2)
    a = np.clip((rt - t[j]) / np.maximum(t[j + 1] - t[j], 1e-12), 0.0, 1.0)
    z_r = np.log(r)
    var_r = (reading_sigma / r) ** 2
    # the frame-to-frame ratios
    dt = np.diff(t)
    lr = np.asarray(log_ratio, dtype=np.float64)[1:]
    ls = np.asarray(log_ratio_sigma, dtype=np.float64)[1:]
    have = np.isfinite(lr) & np.isfinite(ls)
    var_p = _step_variance(np.where(have, ls, np.nan), dt, o)
    z_p = np.where(have, lr, 0.0)

    w_r = np.ones(len(rt))
    w_p = np.ones(n - 1)
    factor = 1.0  # the ratios' variance factor, estimated from the data (module docstring)
    c0, c1 = 1.0 - a, a
    for _ in range(o.iterations):
        var = np.where(have, factor * var_p, var_p)
        upper, x = _solve(n, w_p / var, z_p, w_r / var_r, z_r, j, c0, c1)
        res_p = (np.diff(x) - z_p) / np.sqrt(var)
        res_r = (z_r - (c0 * x[j] + c1 * x[j + 1])) / np.sqrt(var_r)
        w_p = np.where(have, robust_weight(res_p, "huber", o.huber), 1.0)
        w_r = robust_weight(res_r, "huber", o.huber)
        # how much of each ratio's residual variance is redundancy (its own share not taken by the fit)
        d, e = _inverse_bands(upper)
        redundancy = 1.0 - w_p * (d[1:] + d[:-1] - 2.0 * e) / var
        dof = float(np.sum(redundancy[have]))
        if dof < 1.0:
            break
        ratio = float(np.sum((w_p * res_p**2)[have])) / dof
        new = max(factor * ratio, 1.0)  # never more precise than the frontend and the floor say
        if abs(new / factor - 1.0) < 0.02:
            factor = new
            break
        factor = new
    var = np.where(have, factor * var_p, var_p)
    upper, x = _solve(n, w_p / var, z_p, w_r / var_r, z_r, j, c0, c1)
    var_x, _ = _inverse_bands(upper)
    height = np.exp(x)
    n_down = int(np.count_nonzero(w_r < 1.0) + np.count_nonzero(have & (w_p < 1.0)))
    return SmoothedHeights(height, height * np.sqrt(var_x), int(len(rt)), int(np.count_nonzero(have)), n_down,
                           float(factor))


def _step_variance(ratio_sigma, dt, o: HeightSmoothing):
    """Variance of ``x_k - x_{k-1}`` about the measured ratio before the factor ``φ``:
    ``σ_s² + σ_min² + q² Δt``, or the gap's random walk where ``ratio_sigma`` is NaN (no ratio)."""
    ratio_sigma = np.asarray(ratio_sigma, dtype=np.float64)
    dt = np.asarray(dt, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        measured = ratio_sigma**2 + o.min_sigma**2 + o.random_walk**2 * dt
    return np.where(np.isfinite(ratio_sigma), measured, o.gap_random_walk**2 * np.maximum(dt, 1e-6))


def _solve(n, ip, z_p, ir, z_r, j, c0, c1):
    """Banded Cholesky factor (upper) and solution of the normal equations of the two kinds of measurement.

    ``ip``, ``ir``: weights (inverse variances) of the ratios ``x_k - x_{k-1} = z_p`` and of the readings
    ``c0 x_j + c1 x_{j+1} = z_r``.
    """
    diag = np.zeros(n)
    off = np.zeros(n - 1)
    b = np.zeros(n)
    diag[1:] += ip
    diag[:-1] += ip
    off -= ip
    b[1:] += ip * z_p
    b[:-1] -= ip * z_p
    np.add.at(diag, j, ir * c0 * c0)
    np.add.at(diag, j + 1, ir * c1 * c1)
    np.add.at(off, j, ir * c0 * c1)
    np.add.at(b, j, ir * c0 * z_r)
    np.add.at(b, j + 1, ir * c1 * z_r)
    ab = np.zeros((2, n))
    ab[0, 1:] = off
    ab[1] = diag
    upper = cholesky_banded(ab, lower=False)
    return upper, cho_solve_banded((upper, False), b)


def _inverse_bands(upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Diagonal and first off-diagonal of ``A⁻¹`` from the upper banded Cholesky factor ``U`` of a
    tridiagonal ``A = Uᵀ U``.

    With ``L = Uᵀ`` (diagonal ``l_k``, subdiagonal ``m_k``): ``Σ_NN = 1 / l_N²``,
    ``Σ_{k,k+1} = -(m_k / l_k) Σ_{k+1,k+1}`` and ``Σ_kk = 1 / l_k² + (m_k / l_k)² Σ_{k+1,k+1}``.
    """
    l = upper[1]
    m = upper[0, 1:]
    n = len(l)
    d = np.empty(n)
    d[-1] = 1.0 / l[-1] ** 2
    g = m / l[:-1]
    for k in range(n - 2, -1, -1):
        d[k] = 1.0 / l[k] ** 2 + g[k] ** 2 * d[k + 1]
    return d, -g * d[1:]


class HeightFilter:
    """The causal counterpart of :func:`smooth_heights`, for live use: the height at each new frame from
    the readings received up to it and the frames' height ratios.

    The state is the log height at the last frame. At a new frame the ratio predicts it (the model of the
    module docstring), and each reading taken since the previous frame updates the pair of the two frames'
    log heights it lies between (a reading beyond the new frame waits for the next one). A reading whose
    normalised innovation ``|r|`` exceeds ``huber`` counts with the Huber weight ``huber / |r|`` (its
    innovation variance times ``|r| / huber``), as the smoother's readings do.

    The ratios' variance factor ``φ`` is not estimated here: a reading is 10-100 times noisier than a
    ratio, so the few seconds of readings a live filter has do not tell how good the ratios are
    (docs/decisions/0020-camera-height-from-all-range-readings.md). Give it the factor an offline run of
    the same camera found (``fusion-vo run`` says it in its notes: "the scales' stated variance times
    ..."); 1 trusts the frontend's statement.

    Parameters
    ----------
    reading_sigma : float
        Standard deviation of one reading [m] (the range finder's datasheet, or
        :func:`fusion_vo.sensors.range.reading_sigma` of an earlier recording).
    ratio_factor : float
        ``φ`` (default 1).
    options : HeightSmoothing, optional

    Examples
    --------
    >>> hf = HeightFilter(0.0005)
    >>> hf.add_reading(0.00, 0.100)
    >>> [round(v, 6) for v in hf.frame(0.00)]   # the first frame: from the newest reading so far
    [0.1, 0.0005]
    >>> hf.add_reading(0.03, 0.1004)
    >>> h, sigma = hf.frame(0.05, log_ratio=0.004, log_ratio_sigma=2e-5)
    """

    def __init__(self, reading_sigma: float, ratio_factor: float = 1.0, options: HeightSmoothing | None = None):
        if not reading_sigma > 0 or not ratio_factor >= 1.0:
            raise ValueError("reading_sigma must be positive and ratio_factor at least 1")
        self.reading_sigma = float(reading_sigma)
        self.ratio_factor = float(ratio_factor)
        self.options = options or HeightSmoothing()
        self._pending: list[tuple[float, float]] = []
        self._t: float | None = None
        self._x = 0.0
        self._p = 0.0
        self.n_readings = 0
        self.n_downweighted = 0

    @property
    def last_time(self) -> float | None:
        """Time of the last frame [s] (None before the first)."""
        return self._t

    def add_reading(self, t: float, distance: float) -> None:
        """A range reading [m] at time ``t`` [s]; not finite or not positive: ignored."""
        if math.isfinite(t) and math.isfinite(distance) and distance > 0:
            self._pending.append((float(t), float(distance)))

    def frame(self, t: float, log_ratio: float | None = None,
              log_ratio_sigma: float | None = None) -> tuple[float, float] | None:
        """Height [m] and its standard deviation at the frame at ``t``, whose height ratio to the previous
        frame is ``exp(log_ratio)`` (``-log s`` of the similarity; ``None`` where there is none); ``None``
        before the first reading."""
        o = self.options
        t = float(t)
        if self._t is None:  # the first frame: the newest reading taken by then
            ready = [(ti, r) for ti, r in self._pending if ti <= t]
            if not ready:
                return None
            _, r = max(ready)
            self._pending = [(ti, ri) for ti, ri in self._pending if ti > t]
            self._t, self._x, self._p = t, math.log(r), (self.reading_sigma / r) ** 2
            self.n_readings += 1
            return math.exp(self._x), math.exp(self._x) * math.sqrt(self._p)
        dt = max(t - self._t, 1e-6)
        have = log_ratio is not None and log_ratio_sigma is not None and math.isfinite(log_ratio) \
            and math.isfinite(log_ratio_sigma)
        q = float(_step_variance(log_ratio_sigma if have else np.nan, dt, o))
        step = float(log_ratio) if have else 0.0
        if have:
            q *= self.ratio_factor
        # the two frames' log heights, jointly
        m = np.array([self._x, self._x + step])
        C = np.array([[self._p, self._p], [self._p, self._p + q]])
        keep = []
        for ti, r in sorted(self._pending):
            if ti > t:
                keep.append((ti, r))
                continue
            a = min(max((ti - self._t) / dt, 0.0), 1.0)
            h = np.array([1.0 - a, a])
            R = (self.reading_sigma / r) ** 2
            y = math.log(r) - float(h @ m)
            S = float(h @ C @ h) + R
            d2 = y * y / S
            if d2 > o.huber**2:  # Huber's weight huber/|r| (robust_weight): the innovation variance over it
                R += S * (math.sqrt(d2) / o.huber - 1.0)
                S = float(h @ C @ h) + R
                self.n_downweighted += 1
            k = C @ h / S
            m = m + k * y
            C = C - np.outer(k, h @ C)
            self.n_readings += 1
        self._pending = keep
        self._t, self._x, self._p = t, float(m[1]), float(C[1, 1])
        return math.exp(self._x), math.exp(self._x) * math.sqrt(self._p)
