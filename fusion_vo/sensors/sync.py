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
Only the grid points where each stream has samples around them (no gap longer than :data:`MAX_GAP` between the
two that bracket the point) count: a rate is not interpolated across a pause of the recording, and a pause of
an hour costs nothing. The estimate is only returned when the peak correlation exceeds ``min_correlation`` (0.8): a
recording without turns has nothing to align, and a twist whose yaw rate has little to do with the
gyro's (a skid-steered base's reported turn rate can be off by a large factor and shape) would
give a delay that is only noise; moving its timestamps by it would shift every speed sample.

:func:`odometry_delay` is the one rule both uses apply: the delay of an odometry twist behind the
gyro, kept only when it exceeds the twist's sample period (the resolution of a twist held between
samples). Batch use (:func:`fusion_vo.sensors.wheel.synchronise_twist`) applies it to the whole
recording; streaming use (:class:`fusion_vo.backends.streaming.StreamingFusion`) keeps a
:class:`TwistDelay`, which applies it to the samples seen so far (the first ``min_span`` seconds, then
again every ``refresh`` seconds over the last ``span`` seconds) and moves each later twist sample back
by the current estimate.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
from fusion_vo.sensors.gyro import gated_yaw_rate

logger = logging.getLogger(__name__)

#: a grid point between two samples of a stream more than this [s] apart is in a pause of that stream: not compared
MAX_GAP = 1.0


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
    grid, a, pauses = _resampled(t_a, rate_a, t_b, lo, hi, step)
    if len(grid) < 3:
        return None
    shifts = np.arange(-int(round(max_delay / step)), int(round(max_delay / step)) + 1)
    corr = np.array([_correlation(grid, a, t_b, rate_b, s * step, pauses) for s in shifts])
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


def _resampled(t_a, rate_a, t_b, lo: float, hi: float, step: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """The grid ``lo, lo + step, ... < hi`` where stream a has samples (:func:`covered`), its rates there, and whether
    stream b has a pause (then :func:`_correlation` checks its coverage at each shift)."""
    grid = np.arange(lo, hi, step)
    grid = grid[covered(grid, t_a)]
    return grid, np.interp(grid, t_a, rate_a), bool(np.max(np.diff(t_b)) > MAX_GAP)


def covered(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Whether each point of ``x`` lies between two samples of ``t`` (sorted) at most :data:`MAX_GAP` apart, or on one."""
    i = np.clip(np.searchsorted(t, x), 1, len(t) - 1)
    return ((t[i] - t[i - 1] <= MAX_GAP) & (x >= t[0]) & (x <= t[-1])) | (x == t[i - 1]) | (x == t[i])


def _correlation(grid: np.ndarray, a: np.ndarray, t_b: np.ndarray, rate_b: np.ndarray, shift: float,
                 pauses: bool = True) -> float:
    """Normalised correlation of stream a's rates ``a`` at ``grid`` with stream b ``shift`` seconds earlier, over the
    points where stream b has samples (:func:`covered`; all of them when b has no ``pauses``), each with its mean there
    removed."""
    x = grid - shift
    ok = covered(x, t_b) if pauses else None
    if ok is not None and not ok.all():
        if ok.sum() < 3:
            return 0.0
        a, x = a[ok], x[ok]
    a = a - a.mean()
    b = np.interp(x, t_b, rate_b)
    b = b - b.mean()
    # elementwise sums, not np.dot: OpenBLAS threads its dot product on long vectors, which on a
    # loaded machine cost 70 times the CPU time (measured: 4.8 s instead of 0.07 s for 110 s of data)
    denom = np.sqrt(float((a * a).sum()) * float((b * b).sum()))
    return float((a * b).sum()) / denom if denom > 0 else 0.0


def rate_correlation(t_a, rate_a, t_b, rate_b, delays, margin: float, step: float = 0.01) -> list[float]:
    """The normalised correlation of stream ``a`` with stream ``b`` delayed by each of ``delays`` [s] (as in
    :func:`rate_delay`, over their common span less ``margin`` seconds at each end); NaN without overlap."""
    t_a, rate_a = _finite(t_a, rate_a)
    t_b, rate_b = _finite(t_b, rate_b)
    if len(t_a) < 3 or len(t_b) < 3:
        return [math.nan for _ in delays]
    lo, hi = max(t_a[0], t_b[0]) + margin, min(t_a[-1], t_b[-1]) - margin
    grid, a, pauses = _resampled(t_a, rate_a, t_b, lo, hi, step)
    if len(grid) < 3:
        return [math.nan for _ in delays]
    return [_correlation(grid, a, t_b, rate_b, d, pauses) for d in delays]


def _finite(t, r) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(t, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(r)
    return t[ok], r[ok]


def odometry_delay(t_odom, wz, t_gyro, gyro_rate, max_delay: float = 1.0) -> float | None:
    """Delay [s] of an odometry twist's yaw rate ``wz`` behind the gyro's body yaw rate, or None.

    None when :func:`rate_delay` finds none, or when it is shorter than the twist's median sample
    period (below the resolution of a twist held over its sample period).
    """
    t_odom = np.asarray(t_odom, dtype=np.float64)
    if len(t_odom) < 3 or len(t_gyro) < 3:
        return None
    delay = rate_delay(t_odom, wz, t_gyro, gyro_rate, max_delay=max_delay)
    period = float(np.median(np.diff(t_odom)))
    if delay is None or abs(delay) < period:
        return None
    return delay


@dataclass
class TwistDelay:
    """Causal :func:`odometry_delay`: the twist's delay behind the gyro from the samples seen so far.

    Feed every twist sample (``twist``, which returns its time on the gyro's clock) and every gyro
    yaw rate (``gyro``). Once both streams cover ``min_span`` seconds the delay is estimated, every
    ``retry`` seconds of new data until two successive estimates agree within the twist's sample period
    (a short window of gentle curves can give a spurious peak), then again after every ``refresh`` seconds,
    over the last ``span`` seconds (a bounded cost: about 20 ms of CPU for 120 s of
    a 10 Hz twist and a 30 Hz gyro). Until the first estimate, and whenever an estimate finds no delay,
    twist times are taken as they come. The sooner the better: a filter that fused a late twist's turns
    and stops for a while keeps the gyro bias it learned from them
    (``docs/decisions/0035-twist-delay-from-the-yaw-rates.md``). ``history`` lists
    ``(time, delay)`` of every change, for the run's notes.

    Parameters
    ----------
    max_delay : float
        Largest delay searched [s] (``FusionConfig.max_odom_delay``).
    noise : ImuNoise, optional
        Spike gating of the gyro rates, as in batch use.
    """

    max_delay: float = 1.0
    noise: object = None
    min_span: float = 15.0
    retry: float = 5.0
    refresh: float = 30.0
    span: float = 120.0
    delay: float = 0.0
    history: list = field(default_factory=list)
    _odom: list = field(default_factory=list)
    _gyro: list = field(default_factory=list)
    _next: float | None = None
    _candidate: float | None = None  # the last estimate before the first accepted one

    def twist(self, t: float, wz: float) -> float:
        """Record one twist sample; its time corrected by the current delay."""
        self._odom.append((float(t), float(wz)))
        self._update(float(t))
        return float(t) - self.delay

    def gyro(self, t: float, rate: float) -> None:
        """Record one gyro body yaw rate [rad/s]."""
        self._gyro.append((float(t), float(rate)))
        if not self._odom and t - self._gyro[0][0] > 2.0 * self.span:  # no twist yet: keep the last span only
            self._gyro = [s for s in self._gyro if s[0] >= t - self.span]

    def replace_gyro(self, t, rates) -> None:
        """Replace the gyro's yaw rates held so far (the IMU's mounting was corrected: they were read about
        the wrong axis)."""
        self._gyro = [(float(a), float(b)) for a, b in zip(t, rates)]

    def lag(self) -> float:
        """How long [s] after the other streams a twist sample arrives: the delay when positive, else 0."""
        return max(self.delay, 0.0)

    def _update(self, t: float) -> None:
        if not self._gyro:
            return
        start = max(self._odom[0][0], self._gyro[0][0])
        if self._next is None:
            self._next = start + self.min_span
        if t < self._next:
            return
        lo = t - self.span
        self._odom = [s for s in self._odom if s[0] >= lo]
        self._gyro = [s for s in self._gyro if s[0] >= lo]

        o = np.array(self._odom)
        g = np.array(self._gyro)
        order = np.argsort(g[:, 0], kind="stable")
        gyro = gated_yaw_rate(g[order, 0], g[order, 1], self.noise)
        order = np.argsort(o[:, 0], kind="stable")
        found = odometry_delay(o[order, 0], o[order, 1], gyro.t, gyro.rate, self.max_delay)
        if not self.history:  # not yet confirmed: two successive estimates must agree
            period = float(np.median(np.diff(o[order, 0])))
            confirmed = (found is not None and self._candidate is not None
                         and abs(found - self._candidate) <= period)
            self._candidate = found
            if not confirmed:
                self._next = t + self.retry
                return
        self._next = t + self.refresh
        delay = 0.0 if found is None else found
        if delay != self.delay:
            logger.info("odometry twist %.3f s behind the gyro (from t=%.3f on)", delay, t)
            self.history.append((t, delay))
            self.delay = delay


class TwistClock:
    """The odometry twist's clock in a live run: its samples' times moved back by the :class:`TwistDelay` estimate,
    which the gyro's samples feed (the odometry sensor's ``Live.clock``, :mod:`fusion_vo.sensors.registry`).

    Parameters
    ----------
    config : FusionConfig
        ``max_odom_delay`` and the gyro's spike gating (``imu``).
    imu_T_BS : callable
        ``imu_T_BS() -> (4, 4)``: the IMU's mounting as the engine reads it now (corrected mid-stream when the data
        contradict the stated one); a gyro sample's body yaw rate is ``(R_BS ω_S)_z``.
    """

    #: the stream whose times it corrects
    stream = "odom"

    def __init__(self, config, imu_T_BS):
        self.tracker = TwistDelay(config.max_odom_delay, config.imu)
        self._imu_T_BS = imu_T_BS

    @property
    def offset(self) -> float:
        """The current delay [s], removed from every twist time from now on."""
        return self.tracker.delay

    def correct(self, t, payload):
        """A twist sample's time on the gyro's clock (``t`` unchanged when the sample cannot be read: the engine
        counts it as gated)."""
        try:
            t_f, wz = float(t), float(payload[2])
        except (TypeError, ValueError, IndexError):
            return t
        if not (math.isfinite(t_f) and math.isfinite(wz)):
            return t
        return self.tracker.twist(t_f, wz)

    def observe(self, stream: str, t, payload) -> None:
        """A sample of another stream: a gyro sample (``imu``) feeds the estimate with its body yaw rate."""
        if stream != "imu":
            return
        try:
            t_f = float(t)
            rate = float(self._imu_T_BS()[2, :3] @ np.asarray(payload[0], dtype=np.float64).reshape(3))
        except (TypeError, ValueError, IndexError):
            return
        if math.isfinite(rate) and math.isfinite(t_f):
            self.tracker.gyro(t_f, rate)

    def remounted(self, t, rates) -> None:
        """The IMU's mounting was corrected: the gyro's body yaw rates so far, read about the right axes."""
        self.tracker.replace_gyro(t, rates)

    def lag(self) -> float:
        """How long [s] after the other streams a twist sample arrives (:meth:`TwistDelay.lag`)."""
        return self.tracker.lag()

    def note(self, t_first: float) -> str | None:
        """The run's note on the delay (None when it never changed); ``t_first`` the first node's time."""
        if not self.tracker.history:
            return None
        (t, d), *later = self.tracker.history
        text = f"odometry twist {d * 1e3:.0f} ms behind the gyro: its timestamps corrected from t={t:.2f} " \
               f"({t - t_first:.1f} s in)"
        if later:
            ms = [x[1] * 1e3 for x in later]
            text += f", re-estimated {len(ms)} times ({min(ms):.0f}-{max(ms):.0f} ms, last {ms[-1]:.0f} ms)"
        return text


__all__ = ["rate_delay", "rate_correlation", "odometry_delay", "TwistDelay", "TwistClock"]
