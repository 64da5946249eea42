"""Synthetic sensor streams from a known planar trajectory (for tests and benchmarks).

The robot drives a smooth path with twist ``v(t) = v₀ (1 + 0.3 sin(0.3 t))``,
``ω(t) = ω₀ sin(0.21 t) + 0.5 ω₀ sin(0.67 t + 1)``. From the exact trajectory it produces:

* visual increments at ``camera_hz`` (with timestamp jitter): the true increment with its translation
  scaled by ``visual_scale`` (a camera-height error) plus Gaussian noise of the stated covariance, of which
  the fraction ``visual_frame_error`` is the difference of the two frames' own errors (consecutive
  increments' errors then correlate at ``-visual_frame_error / 2``, :mod:`fusion_vo.sensors.visual`);
* cumulative signed-32-bit encoder counts at ``wheel_hz`` starting near the wrap point, from the true
  wheel travel of a robot whose real wheel base is ``wheel_base * wheel_base_factor`` and whose real
  wheel radius is ``wheel_radius * wheel_radius_factor`` (the configuration states ``wheel_radius``);
* gyro samples at ``imu_hz`` with a constant bias and white noise;
* optional range readings of the true camera height;
* optional AHRS orientations (true heading plus noise of ``ahrs_sigma``, an unknown heading offset).

Faults can be injected: frames whose increment fails (status ``"lost"``), wrong visual matches, a gyro
spike and an encoder jump; and, on the generated streams, a span in which the wheels' counts or the camera's
translations are too long (:func:`wheels_too_long`, :func:`camera_too_long`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from fusion_vo.measurements import ImuData, PoseData, RangeData, VisualIncrement, WheelConfig, WheelData
from fusion_vo.geometry import se2


@dataclass
class SyntheticOptions:
    """Parameters of :func:`synthetic_streams` (see the module docstring)."""

    duration: float = 60.0
    speed: float = 0.4
    turn_rate: float = 0.35
    camera_hz: float = 20.0
    wheel_hz: float = 50.0
    imu_hz: float = 200.0
    jitter: float = 0.002
    visual_sigma_xy: float = 0.0015
    visual_sigma_yaw: float = 0.001
    visual_scale: float = 1.0
    visual_frame_error: float = 0.0
    wheel_base: float = 0.4
    wheel_radius: float = 0.05
    ticks_per_revolution: float = 4096.0
    wheel_base_factor: float = 1.0
    wheel_radius_factor: float = 1.0
    wheel_slip: float = 0.01
    gyro_bias: float = 0.01
    gyro_noise_density: float = 2e-3
    camera_height: float = 0.1
    range_hz: float = 0.0
    ahrs_sigma: float | None = None
    lost_frames: list = field(default_factory=list)
    wrong_matches: list = field(default_factory=list)
    gyro_spike_at: float | None = None
    tick_jump_at: float | None = None
    camera_stops_at: float | None = None


@dataclass
class SyntheticStreams:
    """Generated measurements and the truth: ``visual``, ``wheel``, ``imu``, ``range``, ``truth``."""

    visual: list
    wheel: WheelData
    imu: ImuData
    range: RangeData | None
    truth: PoseData
    camera_height: float


def _twist(t: np.ndarray, o: SyntheticOptions) -> tuple[np.ndarray, np.ndarray]:
    v = o.speed * (1.0 + 0.3 * np.sin(0.3 * t))
    w = o.turn_rate * np.sin(0.21 * t) + 0.5 * o.turn_rate * np.sin(0.67 * t + 1.0)
    return v, w


def synthetic_streams(options: SyntheticOptions | None = None, seed: int = 0) -> SyntheticStreams:
    """Generate the streams described in the module docstring."""
    o = options or SyntheticOptions()
    rng = np.random.default_rng(seed)
    dt_fine = 1e-3
    tf = np.arange(0.0, o.duration + 0.5, dt_fine)
    v, w = _twist(tf, o)
    yaw = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * dt_fine)])
    ym = 0.5 * (yaw[1:] + yaw[:-1])
    vm = 0.5 * (v[1:] + v[:-1])
    x = np.concatenate([[0.0], np.cumsum(vm * np.cos(ym) * dt_fine)])
    y = np.concatenate([[0.0], np.cumsum(vm * np.sin(ym) * dt_fine)])
    s_dist = np.concatenate([[0.0], np.cumsum(vm * dt_fine)])

    def pose_at(t):
        return np.stack([np.interp(t, tf, x), np.interp(t, tf, y), np.interp(t, tf, yaw)], axis=-1)

    # camera
    tc = np.arange(0.0, o.duration, 1.0 / o.camera_hz)
    tc = np.sort(tc + rng.uniform(-o.jitter, o.jitter, len(tc)) * (np.arange(len(tc)) > 0))
    if o.camera_stops_at is not None:
        tc = tc[tc <= o.camera_stops_at]
    pc = pose_at(tc)
    cov = np.diag([o.visual_sigma_xy**2, o.visual_sigma_xy**2, o.visual_sigma_yaw**2])
    visual = []
    # each frame's own error (visual_frame_error): from a generator of its own, so that the other draws stay
    frame = np.random.default_rng([seed, 1]).multivariate_normal(np.zeros(3), 0.5 * o.visual_frame_error * cov,
                                                                  len(tc))
    for i in range(1, len(tc)):
        d = se2.between(pc[i - 1], pc[i])
        d[:2] *= o.visual_scale
        d = d + np.sqrt(1.0 - o.visual_frame_error) * rng.multivariate_normal(np.zeros(3), cov)
        d = d + frame[i] - frame[i - 1]
        status = "ok"
        if any(a <= tc[i] <= b for a, b in o.lost_frames):
            status = "lost"
        if any(abs(tc[i] - t) < 0.5 / o.camera_hz for t in o.wrong_matches):
            d = d + np.array([0.08, -0.05, 0.2])
        visual.append(VisualIncrement(float(tc[i - 1]), float(tc[i]), d, cov.copy(), 1.0, status, 200))

    # wheels: true travel of each wheel with the real base, slip noise, counts near the wrap point
    tw = np.arange(0.0, o.duration, 1.0 / o.wheel_hz)
    tw = np.sort(tw + rng.uniform(-o.jitter, o.jitter, len(tw)) * (np.arange(len(tw)) > 0))
    b_true = o.wheel_base * o.wheel_base_factor
    dist = np.interp(tw, tf, s_dist)
    ang = np.interp(tw, tf, yaw)
    left = dist - ang * b_true / 2
    right = dist + ang * b_true / 2
    def slip(d):
        steps = o.wheel_slip * np.sqrt(np.abs(np.diff(d))) * rng.standard_normal(len(d) - 1)
        return np.concatenate([[0.0], np.cumsum(steps)])

    left, right = left + slip(left), right + slip(right)
    per_tick = 2 * np.pi * o.wheel_radius * o.wheel_radius_factor / o.ticks_per_revolution  # the true radius
    start = 2**31 - 20000
    tl = np.floor(left / per_tick).astype(np.int64) + start
    tr = np.floor(right / per_tick).astype(np.int64) + start
    if o.tick_jump_at is not None:
        j = int(np.searchsorted(tw, o.tick_jump_at))
        tl[j] += 500000  # a one-sample glitch
    def wrap(n):
        return ((n + 2**31) % 2**32) - 2**31

    config = WheelConfig(o.ticks_per_revolution, o.wheel_radius, o.wheel_radius, o.wheel_base)
    wheel = WheelData(tw, wrap(tl), wrap(tr), config)

    # gyro
    ti = np.arange(0.0, o.duration, 1.0 / o.imu_hz)
    ti = np.sort(ti + rng.uniform(-o.jitter / 4, o.jitter / 4, len(ti)) * (np.arange(len(ti)) > 0))
    wz = np.interp(ti, tf, w) + o.gyro_bias + o.gyro_noise_density * np.sqrt(o.imu_hz) * rng.standard_normal(len(ti))
    if o.gyro_spike_at is not None:
        wz[int(np.searchsorted(ti, o.gyro_spike_at))] += 30.0
    gyro = np.zeros((len(ti), 3))
    gyro[:, 2] = wz
    accel = np.tile([0.0, 0.0, 9.81], (len(ti), 1))
    orientation = None
    if o.ahrs_sigma is not None:
        psi = np.interp(ti, tf, yaw) + 1.3 + o.ahrs_sigma * rng.standard_normal(len(ti))
        orientation = np.stack([np.cos(psi / 2), np.zeros_like(psi), np.zeros_like(psi), np.sin(psi / 2)], axis=1)
    imu = ImuData(ti, gyro, accel, orientation, np.eye(4), o.imu_hz,
                  {"gyroscope_noise_density": o.gyro_noise_density, "gyroscope_random_walk": 1e-5})

    rng_data = None
    h_true = o.camera_height / o.visual_scale
    if o.range_hz > 0:
        tr_ = np.arange(0.0, o.duration, 1.0 / o.range_hz)
        rng_data = RangeData(tr_, h_true + 0.002 * rng.standard_normal(len(tr_)))

    truth_t = np.arange(0.0, o.duration, 0.01)
    truth = PoseData(truth_t, pose_at(truth_t))
    return SyntheticStreams(visual, wheel, imu, rng_data, truth, o.camera_height)


def wheels_too_long(wheel: WheelData, t0: float, t1: float, k: float) -> WheelData:
    """Encoder counts whose increments in ``(t0, t1]`` are ``k`` times the recorded ones (both wheels: a wheel that
    slips, or a radius that changed for a while)."""
    dl = np.diff(wheel.left.astype(np.int64))
    dr = np.diff(wheel.right.astype(np.int64))
    inside = (wheel.t[1:] > t0) & (wheel.t[1:] <= t1)
    dl = np.where(inside, np.round(dl * k), dl).astype(np.int64)
    dr = np.where(inside, np.round(dr * k), dr).astype(np.int64)
    left = np.concatenate([[wheel.left[0]], wheel.left[0] + np.cumsum(dl)])
    right = np.concatenate([[wheel.right[0]], wheel.right[0] + np.cumsum(dr)])
    return replace(wheel, left=left, right=right)


def camera_too_long(visual: list, t0: float, t1: float, k: float) -> list:
    """Visual increments whose translation is ``k`` times too long when they end in ``(t0, t1]`` (a camera that lost
    its scale for a while)."""
    out = []
    for inc in visual:
        if t0 < inc.t1 <= t1:
            delta = np.array(inc.delta, dtype=float)
            delta[:2] *= k
            inc = replace(inc, delta=delta)
        out.append(inc)
    return out
