"""The streams as cumulative quantities, compared over common intervals by the checks.

A gyro axis's angle, a wheel's travel, an odometry twist's distance and turn are integrals of what the
stream measures; each is kept as its running sum ``C(t)`` at the stream's own sample times (trapezoidal for
the IMU's rates, zero-order hold for a twist held between its samples, the counts themselves for encoder
ticks). Over any interval ``[t_0, t_1]`` the stream then measured ``C(t_1) - C(t_0)`` (linear
interpolation between samples, exact at constant rate whatever the sampling), so streams of any rates
compare over the same intervals: the camera's frame increments when there is a camera, else a regular
grid. An interval is usable for a stream when it lies within the stream's span and no gap longer than
``max_gap`` or unusable sample (non-finite, an impossible jump) falls inside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion_vo.measurements import ImuData, TwistData, VisualIncrement, WheelData
from fusion_vo.sensors.wheel import ticks_to_travel

#: the grid step [s] of the intervals compared when there is no camera
GRID_STEP = 0.1


@dataclass
class Cumulative:
    """Running sums ``values`` (N, m) of a stream at its sample times ``t`` (N,); ``bad`` (N-1,) marks the
    sample intervals that must not be used."""

    t: np.ndarray
    values: np.ndarray
    bad: np.ndarray

    @property
    def period(self) -> float:
        """Median sample period [s] (inf with fewer than two samples)."""
        return float(np.median(np.diff(self.t))) if len(self.t) > 1 else math.inf

    def between(self, t0, t1, max_gap: float) -> tuple[np.ndarray, np.ndarray]:
        """What the stream measured over each interval ``[t0, t1]``: ``(M, m)`` and where usable ``(M,)``."""
        t0 = np.asarray(t0, dtype=np.float64)
        t1 = np.asarray(t1, dtype=np.float64)
        m = self.values.shape[1]
        if len(self.t) < 2:
            return np.zeros((len(t0), m)), np.zeros(len(t0), bool)
        diff = np.stack([np.interp(t1, self.t, self.values[:, j]) - np.interp(t0, self.t, self.values[:, j])
                         for j in range(m)], axis=1)
        bad = self.bad | (np.diff(self.t) > max_gap)
        cum = np.concatenate([[0], np.cumsum(bad)])
        lo = np.clip(np.searchsorted(self.t, t0, side="right") - 1, 0, len(self.t) - 2)
        hi = np.clip(np.searchsorted(self.t, t1, side="left") - 1, 0, len(self.t) - 2)
        inside = (t0 >= self.t[0]) & (t1 <= self.t[-1]) & (t1 > t0)
        return diff, inside & (cum[hi + 1] - cum[lo] == 0)

    def rates(self, column: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Mean rate of one column over each usable sample interval, at the intervals' middles."""
        dt = np.diff(self.t)
        ok = ~self.bad & (dt > 0)
        rate = np.diff(self.values[:, column])[ok] / dt[ok]
        return 0.5 * (self.t[:-1] + self.t[1:])[ok], rate


def _ordered(t: np.ndarray, *columns: np.ndarray) -> tuple[np.ndarray, ...]:
    """Samples in time order, without exact duplicates and rows that are not finite."""
    t = np.asarray(t, dtype=np.float64)
    cols = [np.asarray(c, dtype=np.float64).reshape(len(t), -1) for c in columns]
    ok = np.isfinite(t) & np.all([np.isfinite(c).all(axis=1) for c in cols], axis=0)
    order = np.argsort(t[ok], kind="stable")
    ts = t[ok][order]
    keep = np.concatenate([[True], np.diff(ts) > 0]) if len(ts) else np.zeros(0, bool)
    return (ts[keep],) + tuple(c[ok][order][keep] for c in cols)


def _trapezoid(t: np.ndarray, rate: np.ndarray) -> np.ndarray:
    if len(t) == 0:
        return np.zeros((0, rate.shape[1]))
    seg = 0.5 * (rate[1:] + rate[:-1]) * np.diff(t)[:, None]
    return np.concatenate([np.zeros((1, rate.shape[1])), np.cumsum(seg, axis=0)])


def imu_axes(imu: ImuData, accel: bool = False, max_rate: float = 10.0) -> Cumulative:
    """The gyro's angle about each of its three axes [rad] (or, ``accel``, the accelerometer's velocity change
    along them [m/s]), in the IMU's own frame; gyro samples above ``max_rate`` [rad/s] are unusable."""
    t, values = _ordered(imu.t, imu.accel if accel else imu.gyro)
    bad_sample = np.zeros(len(t), bool) if accel else np.abs(values).max(axis=1) > max_rate if len(t) else np.zeros(0, bool)
    bad = bad_sample[:-1] | bad_sample[1:] if len(t) > 1 else np.zeros(0, bool)
    return Cumulative(t, _trapezoid(t, values), bad)


def body_turn(imu: ImuData) -> Cumulative:
    """The gyro's angle about the body's up axis (the third row of ``T_BS``'s rotation) [rad]."""
    axes = imu_axes(imu)
    z = np.asarray(imu.T_BS, dtype=np.float64)[2, :3]
    return Cumulative(axes.t, axes.values @ z[:, None], axes.bad)


def wheel_travel(wheel: WheelData, left_sign: int = 1, right_sign: int = 1, noise=None) -> Cumulative:
    """Encoder ticks as ``(distance, turn)`` [m, rad] since the first sample: ``((d_r + d_l)/2, (d_r - d_l)/b)``
    with the configured radii and base, each wheel's counts taken with the sign given."""
    data = WheelData(wheel.t, left_sign * np.asarray(wheel.left, dtype=np.int64),
                     right_sign * np.asarray(wheel.right, dtype=np.int64), wheel.config)
    t, left, right = _ordered(data.t, data.left, data.right)
    if len(t) < 2:
        return Cumulative(t, np.zeros((len(t), 2)), np.zeros(max(len(t) - 1, 0), bool))
    travel = ticks_to_travel(WheelData(t, left[:, 0].astype(np.int64), right[:, 0].astype(np.int64), wheel.config),
                             noise)
    values = np.stack([0.5 * (travel.right + travel.left), (travel.right - travel.left) / travel.wheel_base], axis=1)
    return Cumulative(t, values, ~travel.valid)


def twist_travel(odom: TwistData) -> Cumulative:
    """An odometry twist as ``(forward, lateral, turn)`` [m, m, rad] since the first sample (each sample held
    until the next)."""
    t, v = _ordered(odom.t, np.column_stack([odom.vx, odom.vy, odom.wz]))
    if len(t) < 2:
        return Cumulative(t, np.zeros((len(t), 3)), np.zeros(max(len(t) - 1, 0), bool))
    seg = v[:-1] * np.diff(t)[:, None]
    return Cumulative(t, np.concatenate([np.zeros((1, 3)), np.cumsum(seg, axis=0)]), np.zeros(len(t) - 1, bool))


@dataclass
class Steps:
    """Intervals ``[t0, t1]`` (M,) and the body motion ``(dx, dy, dyaw)`` (M, 3) a stream measured over them."""

    t0: np.ndarray
    t1: np.ndarray
    delta: np.ndarray

    @property
    def dt(self) -> np.ndarray:
        return self.t1 - self.t0

    def __len__(self) -> int:
        return len(self.t0)

    def rates(self, column: int = 2) -> tuple[np.ndarray, np.ndarray]:
        """Mean rate of one column over each interval, at the intervals' middles."""
        return 0.5 * (self.t0 + self.t1), self.delta[:, column] / self.dt


def camera_steps(visual: list[VisualIncrement] | None) -> Steps | None:
    """The camera's usable increments (status ok, finite, forward in time), or None without any."""
    rows = [(v.t0, v.t1, *np.asarray(v.delta, dtype=np.float64)[:3]) for v in visual or () if v.ok]
    a = np.array(rows, dtype=np.float64).reshape(-1, 5)
    a = a[np.isfinite(a).all(axis=1) & (a[:, 1] > a[:, 0])]
    if not len(a):
        return None
    a = a[np.argsort(a[:, 1], kind="stable")]
    return Steps(a[:, 0], a[:, 1], a[:, 2:5])


def grid(spans: list[tuple[float, float]], step: float = GRID_STEP) -> tuple[np.ndarray, np.ndarray]:
    """Regular intervals of ``step`` seconds over the common span of ``spans``: ``(t0, t1)``."""
    lo = max(s[0] for s in spans)
    hi = min(s[1] for s in spans)
    if not hi - lo > step:
        return np.zeros(0), np.zeros(0)
    edges = np.arange(lo, hi, step)
    return edges[:-1], edges[1:]


def span(c: Cumulative) -> tuple[float, float]:
    return (float(c.t[0]), float(c.t[-1])) if len(c.t) else (0.0, 0.0)


def robust_lstsq(X: np.ndarray, y: np.ndarray, passes: int = 2, k: float = 4.0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least squares ``y ≈ X b`` with the rows whose residual exceeds ``k`` robust standard deviations
    (1.4826 times the median absolute residual) left out, refitted ``passes`` times.

    Returns ``(b, covariance of b, rows used)``; the covariance is ``s² (XᵀX)⁻¹`` with ``s²`` the residual
    variance of the rows used.
    """
    use = np.ones(len(y), bool)
    b = np.zeros(X.shape[1])
    for _ in range(passes + 1):
        b, *_ = np.linalg.lstsq(X[use], y[use], rcond=None)
        res = y - X @ b
        scale = 1.4826 * float(np.median(np.abs(res[use])))
        if not scale > 0:
            break
        new = np.abs(res) <= k * scale
        if new.sum() < X.shape[1] + 2 or np.array_equal(new, use):
            break
        use = new
    res = (y - X @ b)[use]
    dof = max(int(use.sum()) - X.shape[1], 1)
    s2 = float(res @ res) / dof
    try:
        cov = s2 * np.linalg.inv(X[use].T @ X[use])
    except np.linalg.LinAlgError:
        cov = np.full((X.shape[1], X.shape[1]), np.inf)
    return b, cov, use


def explained(y: np.ndarray, fitted: np.ndarray, base: np.ndarray) -> float:
    """Fraction of the variance of ``y`` about ``base`` (a fit without the signal) that ``fitted`` explains."""
    total = float(np.sum((y - base) ** 2))
    return 1.0 - float(np.sum((y - fitted) ** 2)) / total if total > 0 else 0.0


@dataclass
class Motion:
    """A reference motion over intervals: ``turn`` [rad] and forward ``distance`` [m] (M,) over ``[t0, t1]``,
    measured by ``name`` (``camera``, ``wheels``, ``odometry``), whose samples live in ``file``."""

    name: str
    file: str
    t0: np.ndarray
    t1: np.ndarray
    turn: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return len(self.t0)

    @property
    def dt(self) -> np.ndarray:
        return self.t1 - self.t0

    def shifted(self, delay: float) -> "Motion":
        """The same motion with its intervals moved ``delay`` seconds earlier."""
        return Motion(self.name, self.file, self.t0 - delay, self.t1 - delay, self.turn, self.distance)

    def subset(self, keep: np.ndarray) -> "Motion":
        return Motion(self.name, self.file, self.t0[keep], self.t1[keep], self.turn[keep], self.distance[keep])


def motion_reference(streams, max_gap: float) -> Motion | None:
    """The turn and distance of the robot from the camera when it has usable increments, else the wheels'
    encoders, else the odometry twist; None without any."""
    steps = camera_steps(streams.visual)
    if steps is not None and len(steps) >= 3:
        return Motion("camera", "cam0", steps.t0, steps.t1, steps.delta[:, 2],
                      np.hypot(steps.delta[:, 0], steps.delta[:, 1]) * np.sign(steps.delta[:, 0]))
    for name, file, data, build in (("wheels", "wheel0", streams.wheel, wheel_travel),
                                    ("odometry", "odom0", streams.odom, twist_travel)):
        if data is None or len(data) < 3:
            continue
        cum = build(data)
        t0, t1 = grid([span(cum)])
        values, ok = cum.between(t0, t1, max_gap)
        if np.count_nonzero(ok) < 3:
            continue
        return Motion(name, file, t0[ok], t1[ok], values[ok, -1], values[ok, 0])
    return None
