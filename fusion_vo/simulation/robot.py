"""Differential-drive motion: command profiles and their exact integration.

A profile is a sequence of body speed commands ``v(t)`` [m/s] and ``w(t)`` [rad/s] sampled at a fine
step ``dt`` (1 ms by default). Speeds change at most at the acceleration limits, so the motion is smooth
as a real robot's. The pose follows by exact integration of a constant twist over each step::

    x_{k+1} = x_k ⊕ exp(dt · (v_k, 0, w_k))

Profiles (:data:`PROFILES`):

``square``         four 0.9 m legs with 90 degree turns in place (thesis table 5.2)
``circle``         one full circle, the camera moving tangent to it (thesis 5.2.1)
``random``         a random smooth drive with stops, up to ``max_speed`` and ``max_turn_rate``
``standstill``     the robot does not move
``turn_in_place``  rotation about the axle (lever-arm calibration)
``straight``       a straight drive of known length (height calibration)
``umbmark_cw``, ``umbmark_ccw``   Borenstein's UMBmark square driven clockwise / counter-clockwise
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion_vo.geometry import se2


@dataclass
class Motion:
    """A sampled trajectory: times ``t`` (N,), commands ``v``, ``w`` (N,), poses ``xyyaw`` (N, 3).

    ``xyyaw[k]`` is the pose at ``t[k]``; ``v[k]``, ``w[k]`` act from ``t[k]`` to ``t[k+1]``. Yaw is
    continuous (not wrapped) so that full turns can be counted.
    """

    t: np.ndarray
    v: np.ndarray
    w: np.ndarray
    xyyaw: np.ndarray

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def path_length(self) -> float:
        return float(np.sum(np.abs(self.v[:-1])) * self.dt)

    def pose_at(self, times: np.ndarray) -> np.ndarray:
        """Poses at arbitrary times (linear interpolation of the fine samples; yaw continuous)."""
        times = np.asarray(times, dtype=np.float64)
        return np.column_stack([np.interp(times, self.t, self.xyyaw[:, i]) for i in range(3)])

    def twist_at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Commanded ``(v, w)`` at arbitrary times (sample and hold)."""
        idx = np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, len(self.t) - 1)
        return self.v[idx], self.w[idx]


def integrate(v: np.ndarray, w: np.ndarray, dt: float, start=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Exact constant-twist integration of speed commands; returns ``(N, 3)`` poses, yaw continuous."""
    v = np.asarray(v, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)
    yaw = start[2] + np.concatenate([[0.0], np.cumsum(w[:-1] * dt)])
    th0 = yaw[:-1]
    dth = w[:-1] * dt
    # displacement of an arc in the world: the body-frame arc (v dt) (sin dth/dth, (1 - cos dth)/dth)
    # rotated by the heading at its start
    a, b = se2.sinc_terms(dth)
    step = v[:-1] * dt
    dx = step * (np.cos(th0) * a - np.sin(th0) * b)
    dy = step * (np.sin(th0) * a + np.cos(th0) * b)
    x = start[0] + np.concatenate([[0.0], np.cumsum(dx)])
    y = start[1] + np.concatenate([[0.0], np.cumsum(dy)])
    return np.column_stack([x, y, yaw])


# ---------------------------------------------------------------------------- building blocks
#: the longest drive a recording is generated for [s] (an hour: 72000 frames at 20 Hz)
MAX_DURATION_S = 3600.0


def _ramp_profile(distance: float, v_max: float, a_max: float, dt: float) -> np.ndarray:
    """Speed samples of a trapezoidal (or triangular) profile covering ``|distance|`` exactly."""
    d = abs(distance)
    if d == 0:
        return np.zeros(0)
    v_peak = min(v_max, math.sqrt(d * a_max))
    t_acc = v_peak / a_max
    d_acc = 0.5 * a_max * t_acc**2
    t_flat = (d - 2 * d_acc) / v_peak
    total = 2 * t_acc + t_flat
    if total > MAX_DURATION_S:  # refused before its samples are made (a million per thousand seconds)
        raise ValueError(f"the drive lasts {total:.3g} s or more, longer than the {MAX_DURATION_S:g} s a generated "
                         "recording may last (make it shorter: duration, length, side, radius or angle)")
    n = max(int(math.ceil(total / dt)), 1)
    t = (np.arange(n) + 0.5) * (total / n)
    speed = np.minimum.reduce([a_max * t, np.full(n, v_peak), a_max * (total - t)])
    speed *= d / (np.sum(speed) * dt)  # cover the distance exactly on the sampling grid
    return math.copysign(1.0, distance) * speed


@dataclass
class Limits:
    """Speed and acceleration limits of the robot."""

    max_speed: float = 0.15
    max_turn_rate: float = 0.6
    max_accel: float = 0.5
    max_turn_accel: float = 2.0


def _segments(parts: list[tuple[str, float]], lim: Limits, dt: float, pause: float) -> tuple[np.ndarray, np.ndarray]:
    vs, ws = [np.zeros(int(round(pause / dt)))], [np.zeros(int(round(pause / dt)))]
    for kind, amount in parts:
        if kind == "drive":
            s = _ramp_profile(amount, lim.max_speed, lim.max_accel, dt)
            vs.append(s)
            ws.append(np.zeros_like(s))
        elif kind == "turn":
            s = _ramp_profile(amount, lim.max_turn_rate, lim.max_turn_accel, dt)
            vs.append(np.zeros_like(s))
            ws.append(s)
        elif kind == "wait":
            n = int(round(amount / dt))
            vs.append(np.zeros(n))
            ws.append(np.zeros(n))
        vs.append(np.zeros(int(round(pause / dt))))
        ws.append(np.zeros(int(round(pause / dt))))
    return np.concatenate(vs), np.concatenate(ws)


def _motion(v: np.ndarray, w: np.ndarray, dt: float) -> Motion:
    v = np.append(v, 0.0)
    w = np.append(w, 0.0)
    t = np.arange(len(v)) * dt
    return Motion(t, v, w, integrate(v, w, dt))


# ---------------------------------------------------------------------------- profiles
def square(lim: Limits, dt: float, rng: np.random.Generator, side: float = 0.9, **_) -> Motion:
    """Four legs of ``side`` metres, each followed by a 90 degree turn in place to the left."""
    parts = []
    for _leg in range(4):
        parts += [("drive", side), ("turn", math.pi / 2)]
    return _motion(*_segments(parts, lim, dt, pause=0.5), dt)


def umbmark(lim: Limits, dt: float, rng: np.random.Generator, side: float = 2.0, clockwise: bool = True, **_) -> Motion:
    """Borenstein's UMBmark square: legs of ``side`` metres with 90 degree turns, cw or ccw."""
    turn = -math.pi / 2 if clockwise else math.pi / 2
    parts = []
    for _leg in range(4):
        parts += [("drive", side), ("turn", turn)]
    return _motion(*_segments(parts, lim, dt, pause=0.5), dt)


def circle(lim: Limits, dt: float, rng: np.random.Generator, radius: float = 0.4, **_) -> Motion:
    """One full counter-clockwise circle of ``radius``, at the speed limits, ending where it started."""
    v_max = min(lim.max_speed, lim.max_turn_rate * radius)
    length = 2 * math.pi * radius
    s = _ramp_profile(length, v_max, lim.max_accel, dt)
    pad = np.zeros(int(round(0.5 / dt)))
    v = np.concatenate([pad, s, pad])
    return _motion(v, v / radius, dt)


def standstill(lim: Limits, dt: float, rng: np.random.Generator, duration: float = 5.0, **_) -> Motion:
    n = int(round(duration / dt))
    return _motion(np.zeros(n), np.zeros(n), dt)


def turn_in_place(lim: Limits, dt: float, rng: np.random.Generator, angle: float = 2 * math.pi, **_) -> Motion:
    """Rotation about the axle by ``angle`` [rad] (default one full turn)."""
    return _motion(*_segments([("turn", angle)], lim, dt, pause=0.5), dt)


def straight(lim: Limits, dt: float, rng: np.random.Generator, length: float = 1.0, **_) -> Motion:
    """A straight drive of ``length`` metres."""
    return _motion(*_segments([("drive", length)], lim, dt, pause=0.5), dt)


def random_drive(lim: Limits, dt: float, rng: np.random.Generator, duration: float = 60.0,
                 stop_probability: float = 0.15, **_) -> Motion:
    """A random smooth drive with stops.

    Every 1.5-4 s a new target ``(v, w)`` is drawn (``v`` in [0, max_speed], ``w`` in
    [-max_turn_rate, max_turn_rate]; with ``stop_probability`` a stop of 1-2 s); the commands move
    towards the target at the acceleration limits.
    """
    n = int(round(duration / dt))
    v = np.zeros(n)
    w = np.zeros(n)
    tv = tw = 0.0
    cv = cw = 0.0
    next_change = 0
    dv = lim.max_accel * dt  # largest speed change per step
    dw = lim.max_turn_accel * dt
    for k in range(n):
        if k >= next_change:
            if rng.random() < stop_probability or k == 0:
                tv, tw = 0.0, 0.0
                hold = rng.uniform(1.0, 2.0)
            else:
                tv = rng.uniform(0.3, 1.0) * lim.max_speed
                tw = rng.uniform(-1.0, 1.0) * lim.max_turn_rate
                hold = rng.uniform(1.5, 4.0)
            next_change = k + int(hold / dt)
        if k > n - int(2.0 / dt):  # come to a stop at the end
            tv, tw = 0.0, 0.0
        cv += min(max(tv - cv, -dv), dv)
        cw += min(max(tw - cw, -dw), dw)
        v[k], w[k] = cv, cw
    return _motion(v, w, dt)


#: the shape options each profile takes (the other profiles ignore them)
SHAPE_OPTIONS = {"duration": ("random", "standstill"), "side": ("square", "umbmark_cw", "umbmark_ccw"),
                 "radius": ("circle",), "length": ("straight",), "angle": ("turn_in_place",)}

PROFILES = {
    "square": square,
    "circle": circle,
    "random": random_drive,
    "standstill": standstill,
    "turn_in_place": turn_in_place,
    "straight": straight,
    "umbmark_cw": lambda lim, dt, rng, **kw: umbmark(lim, dt, rng, clockwise=True, **kw),
    "umbmark_ccw": lambda lim, dt, rng, **kw: umbmark(lim, dt, rng, clockwise=False, **kw),
}


def make_motion(profile: str, limits: Limits, rng: np.random.Generator, dt: float = 0.001, **kwargs) -> Motion:
    """The :class:`Motion` of a named profile."""
    if profile not in PROFILES:
        raise ValueError(f"unknown profile '{profile}' (choose one of {', '.join(PROFILES)})")
    return PROFILES[profile](limits, dt, rng, **kwargs)
