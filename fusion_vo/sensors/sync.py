"""Time offset between two streams that measure the same yaw rate (an odometry twist and a gyro).

A robot's own odometry is often stamped when its controller publishes it, a fraction of a second
after the wheels turned, while the IMU stamps its samples as it takes them. Fusing the two on one
clock without correcting that delay makes every turn look like a yaw-rate error of the wheels (it
starts and ends late), correlated over the turn. The model is::

    r_a(t) = k · r_b(t - d) + n(t)

with an unknown scale ``k`` (a skid-steered base reports a fraction of its turn) and delay ``d``
(``a`` lags ``b`` by ``d`` seconds). Both rates are resampled on a common grid of step ``h`` and ``d``
is the shift in ``[-d_max, d_max]`` that maximises their normalised cross-correlation (which does not
depend on ``k``), refined to below the grid step by a parabola through the peak and its neighbours.
The estimate is only returned when the peak correlation exceeds ``min_correlation`` (0.8): a
recording without turns has nothing to align, and a twist whose yaw rate has little to do with the
gyro's (a skid-steered base's reported turn rate can be off by a large factor and shape) would
give a delay that is only noise; moving its timestamps by it would shift every speed sample.
"""

from __future__ import annotations

import logging

import numpy as np

logger = logging.getLogger(__name__)


def rate_delay(t_a, rate_a, t_b, rate_b, max_delay: float = 1.0, step: float = 0.01,
               min_correlation: float = 0.8) -> float | None:
    """Delay ``d`` [s] of stream ``a`` behind stream ``b`` (see the module docstring), or None.

    Parameters
    ----------
    t_a, rate_a, t_b, rate_b : array_like
        Sample times [s] and rates of the two streams (non-finite samples are dropped).
    max_delay : float
        Largest delay searched [s].
    step : float
        Resampling step [s].
    min_correlation : float
        Smallest peak correlation accepted.
    """
    t_a, rate_a = _finite(t_a, rate_a)
    t_b, rate_b = _finite(t_b, rate_b)
    if len(t_a) < 3 or len(t_b) < 3:
        return None
    lo, hi = max(t_a[0], t_b[0]) + max_delay, min(t_a[-1], t_b[-1]) - max_delay
    if hi - lo < 10 * max_delay:
        return None
    grid = np.arange(lo, hi, step)
    a = np.interp(grid, t_a, rate_a)
    a = a - a.mean()
    shifts = np.arange(-int(round(max_delay / step)), int(round(max_delay / step)) + 1)
    corr = np.empty(len(shifts))
    for i, s in enumerate(shifts):
        b = np.interp(grid - s * step, t_b, rate_b)
        b = b - b.mean()
        denom = np.sqrt(np.dot(a, a) * np.dot(b, b))
        corr[i] = np.dot(a, b) / denom if denom > 0 else 0.0
    best = int(np.argmax(corr))
    if corr[best] < min_correlation:
        logger.info("sync: no delay estimated (peak correlation %.2f)", corr[best])
        return None
    frac = 0.0
    if 0 < best < len(shifts) - 1:
        c0, c1, c2 = corr[best - 1], corr[best], corr[best + 1]
        curvature = c0 - 2.0 * c1 + c2
        if curvature < 0:
            frac = 0.5 * (c0 - c2) / curvature
    return float((shifts[best] + frac) * step)


def _finite(t, r) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(t, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(r)
    return t[ok], r[ok]


__all__ = ["rate_delay"]
