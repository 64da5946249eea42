"""Simulated sensors: wheel encoders, IMU, range finder, robot odometry, GPS.

Wheel encoders
--------------
The true wheels (radii ``r_l, r_r``, base ``b``, which differ from the nominal values written to
``wheel0/sensor.yaml`` by the configured calibration errors) turn by::

    d_r = (v + w b / 2) dt,   d_l = (v - w b / 2) dt,   angle = d / r

Slip adds white noise to each wheel's travel with standard deviation ``slip · sqrt(|d|)``. Counts are
``floor(angle / 2π · ticks_per_revolution)`` plus a start offset, stored as signed 32-bit integers (they
wrap around when the offset is near 2³¹).

IMU (at the body origin, axes of the body)
-----------------------------------------
``gyro = (0, 0, w) + b_g + n_g``, with ``b_g`` a constant bias plus a random walk and ``n_g`` white noise
of density ``σ_g`` (discrete ``σ_g · sqrt(rate)``). Specific force ``accel = (dv/dt, v w, g) + b_a + n_a``.

GPS
---
The antenna's position in East-North-Up with white noise, outages and multipath jumps
(:func:`gps_fixes`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion_vo.simulation.robot import Motion

GRAVITY = 9.81


@dataclass
class WheelTruth:
    """True and nominal wheel geometry."""

    radius_left: float
    radius_right: float
    wheel_base: float
    nominal_radius: float
    nominal_base: float
    ticks_per_revolution: int


def sample_times(t0: float, t1: float, rate: float, jitter: float, rng: np.random.Generator) -> np.ndarray:
    """Sample times at ``rate`` Hz with uniform jitter of ``jitter`` seconds (kept increasing)."""
    n = int(math.floor((t1 - t0) * rate)) + 1
    t = t0 + np.arange(n) / rate
    if jitter > 0:
        t = t + rng.uniform(-jitter, jitter, size=n)
        t = np.clip(t, t0, t1)
        t = np.maximum.accumulate(t)
        t[1:] = np.maximum(t[1:], t[:-1] + 1e-6)
    return t[t <= t1]


def wheel_ticks(motion: Motion, truth: WheelTruth, times: np.ndarray, slip: float, start_count: int,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative left/right counts (int64 values of signed 32-bit counters) at ``times``."""
    dt = motion.dt
    d_r = (motion.v + motion.w * truth.wheel_base / 2) * dt
    d_l = (motion.v - motion.w * truth.wheel_base / 2) * dt
    if slip > 0:
        d_r = d_r + slip * np.sqrt(np.abs(d_r)) * rng.standard_normal(len(d_r))
        d_l = d_l + slip * np.sqrt(np.abs(d_l)) * rng.standard_normal(len(d_l))
    # cumulative travel at the start of each fine step, then at the sample times
    cum_r = np.concatenate([[0.0], np.cumsum(d_r[:-1])])
    cum_l = np.concatenate([[0.0], np.cumsum(d_l[:-1])])
    travel_r = np.interp(times, motion.t, cum_r)
    travel_l = np.interp(times, motion.t, cum_l)
    tpr = truth.ticks_per_revolution
    count_r = np.floor(travel_r / (2 * math.pi * truth.radius_right) * tpr).astype(np.int64) + start_count
    count_l = np.floor(travel_l / (2 * math.pi * truth.radius_left) * tpr).astype(np.int64) + start_count
    return wrap_int32(count_l), wrap_int32(count_r)


def wrap_int32(x: np.ndarray) -> np.ndarray:
    """Values of signed 32-bit counters holding ``x``."""
    return ((np.asarray(x, dtype=np.int64) + 2**31) % 2**32) - 2**31


@dataclass
class ImuNoise:
    """IMU noise: densities (EuRoC units) and constant biases."""

    gyro_noise_density: float = 1.7e-4  # rad/s/sqrt(Hz)
    gyro_random_walk: float = 2.0e-5  # rad/s^2/sqrt(Hz)
    accel_noise_density: float = 2.0e-3  # m/s^2/sqrt(Hz)
    accel_random_walk: float = 3.0e-3  # m/s^3/sqrt(Hz)
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)


def imu_samples(motion: Motion, times: np.ndarray, noise: ImuNoise, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gyro (N, 3), accelerometer (N, 3) and the true gyro bias (N, 3) at ``times``.

    The poses integrate each command held over its fine step, so the smooth rate they follow passes
    through each command at the *middle* of its step; that is where the rates are interpolated. Taken at
    the start of the step, the gyro would lead the true heading by half a step (0.5 ms): an error of the
    turn rate's change times 0.5 ms, correlated over every turn, about half the gyro's white noise over a
    camera interval (rms 1.9e-5 rad per 50 ms on a 30 s random drive, against 9e-7 at the middle).
    """
    n = len(times)
    rate = 1.0 / np.median(np.diff(times)) if n > 1 else 200.0
    middle = motion.t + 0.5 * motion.dt
    v = np.interp(times, middle, motion.v)
    w = np.interp(times, middle, motion.w)
    dvdt = np.gradient(motion.v, motion.t)
    a_fwd = np.interp(times, motion.t, dvdt)
    walk_g = np.cumsum(rng.standard_normal((n, 3)), axis=0) * noise.gyro_random_walk / math.sqrt(rate)
    walk_a = np.cumsum(rng.standard_normal((n, 3)), axis=0) * noise.accel_random_walk / math.sqrt(rate)
    bias_g = np.asarray(noise.gyro_bias)[None, :] + walk_g
    bias_a = np.asarray(noise.accel_bias)[None, :] + walk_a
    gyro = np.column_stack([np.zeros(n), np.zeros(n), w]) + bias_g
    gyro += rng.standard_normal((n, 3)) * noise.gyro_noise_density * math.sqrt(rate)
    accel = np.column_stack([a_fwd, v * w, np.full(n, GRAVITY)]) + bias_a
    accel += rng.standard_normal((n, 3)) * noise.accel_noise_density * math.sqrt(rate)
    return gyro, accel, bias_g


def odometry_twist(times: np.ndarray, left: np.ndarray, right: np.ndarray, truth: WheelTruth) -> np.ndarray:
    """A robot's own odometry (``v_x, v_y, w_z``) from its encoder counts and *nominal* geometry."""
    dl = np.diff(left.astype(np.int64))
    dr = np.diff(right.astype(np.int64))
    dl = wrap_int32(dl)
    dr = wrap_int32(dr)
    k = 2 * math.pi * truth.nominal_radius / truth.ticks_per_revolution
    dt = np.diff(times)
    v = (dl + dr) * k / 2 / dt
    w = (dr - dl) * k / truth.nominal_base / dt
    out = np.zeros((len(times), 3))
    out[1:, 0] = v
    out[1:, 2] = w
    return out


@dataclass
class GpsSimulation:
    """A GNSS receiver: rate [Hz], horizontal noise [m], antenna lever arm in the body (x, y, z) [m],
    outages ``[[t0, t1], ...]`` [s] without fixes, multipath jumps ``[[t0, t1, de, dn], ...]`` (fixes in
    ``[t0, t1]`` offset by ``(de, dn)`` metres), and the world frame's place in ENU: heading [rad] of the
    world x axis counter-clockwise from east, and the ENU position [m] of the world origin."""

    rate: float = 5.0
    noise: float = 0.05
    lever_arm: tuple = (-0.10, 0.0, 0.40)
    outages: list = None
    jumps: list = None
    heading: float = 0.0
    origin: tuple = (0.0, 0.0)


def gps_fixes(motion: Motion, gps: GpsSimulation, t_end: float, rng: np.random.Generator
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times (N,), measured ENU antenna positions (N, 3) and the jump flag (N,) of simulated fixes.

    The true antenna position is ``p + R(yaw) l`` in the world, carried to ENU by the rotation
    ``heading`` and the offset ``origin``; the fixes add white noise of ``noise`` per horizontal axis
    (twice that vertically), drop out during the outages and jump during the jumps.
    """
    t = sample_times(0.0, t_end, gps.rate, 0.0, rng)
    for t0, t1 in gps.outages or []:
        t = t[(t < t0) | (t > t1)]
    p = motion.pose_at(t)
    lx, ly, lz = (float(v) for v in gps.lever_arm)
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    world = np.column_stack([p[:, 0] + c * lx - s * ly, p[:, 1] + s * lx + c * ly])
    ch, sh = math.cos(gps.heading), math.sin(gps.heading)
    enu = np.column_stack([ch * world[:, 0] - sh * world[:, 1] + gps.origin[0],
                           sh * world[:, 0] + ch * world[:, 1] + gps.origin[1], np.full(len(t), lz)])
    enu += rng.standard_normal((len(t), 3)) * (gps.noise * np.array([1.0, 1.0, 2.0]))
    jumped = np.zeros(len(t), dtype=bool)
    for t0, t1, de, dn in gps.jumps or []:
        m = (t >= t0) & (t <= t1)
        enu[m, 0] += de
        enu[m, 1] += dn
        jumped |= m
    return t, enu, jumped
