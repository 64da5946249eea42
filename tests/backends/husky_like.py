"""Streams of a skid-steered robot reporting an odometry twist, with a gyro and an optional AHRS.

The robot drives, stops for a long while, and drives again. Its own odometry reports the yaw rate
``yaw_scale`` times the true one (skid steering), the gyro has a constant bias, and the AHRS heading
(when asked for) strays from the truth by up to ``ahrs_drift`` [rad] in the middle of the recording;
with ``ahrs_knots = ((t, offset), ...)`` its offset also follows these knots, linear in between and
constant beyond them (a magnetic disturbance that stays, or goes away).
With ``scale_scatter`` the reported turn rate's scale also wanders, as the effective track width of a
skid-steered base does from turn to turn: ``yaw_scale (1 + scale_scatter g(t))`` with ``g`` a unit
first-order Gauss–Markov process of correlation time ``scatter_time`` [s]. With ``corners`` the
robot drives straight legs joined by quarter turns instead of a wavy path.
"""

import numpy as np

from fusion_vo.measurements import ImuData, PoseData, TwistData


def husky_like(duration=90.0, stop=(30.0, 60.0), yaw_scale=0.75, gyro_bias=0.004, ahrs_drift=None, seed=0,
               scale_scatter=0.0, scatter_time=5.0, corners=False, gyro_noise=0.003, ahrs_knots=None):
    """``(odom, imu, truth)``: twist at 10 Hz, IMU at 30 Hz, truth at 100 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 0.01)
    moving = (t < stop[0]) | (t >= stop[1])
    v = np.where(moving, 0.8, 0.0)
    w = np.where(moving, 0.25 * np.sin(0.15 * t) + 0.1, 0.0)
    if corners:  # straight legs and quarter turns: 4 s at π/8 rad/s every 12 s of driving
        w = np.where(moving & ((t % 12.0) < 4.0), np.pi / 8.0, 0.0)
    yaw = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * 0.01)])
    x = np.concatenate([[0.0], np.cumsum(v[:-1] * np.cos(yaw[:-1] + 0.5 * w[:-1] * 0.01) * 0.01)])
    y = np.concatenate([[0.0], np.cumsum(v[:-1] * np.sin(yaw[:-1] + 0.5 * w[:-1] * 0.01) * 0.01)])
    truth = PoseData(t, np.stack([x, y, yaw], axis=1))
    to = t[::10]
    moving_o = (to < stop[0]) | (to >= stop[1])
    noise_v = np.where(moving_o, 0.01 * rng.standard_normal(len(to)), 0.0)
    noise_w = np.where(moving_o, 0.02 * rng.standard_normal(len(to)), 0.0)
    scale = np.full(len(to), yaw_scale)
    if scale_scatter > 0:
        a = np.exp(-0.1 / scatter_time)
        g = np.zeros(len(to))
        g[0] = rng.standard_normal()
        for k in range(1, len(to)):
            g[k] = a * g[k - 1] + np.sqrt(1 - a * a) * rng.standard_normal()
        scale = yaw_scale * (1.0 + scale_scatter * g)
    odom = TwistData(to, v[::10] + noise_v, np.zeros(len(to)), scale * w[::10] + noise_w)
    ti = np.arange(0.0, duration, 1.0 / 30.0)
    gz = np.interp(ti, t, w) + gyro_bias + gyro_noise * np.sqrt(30.0) * rng.standard_normal(len(ti))
    gyro = np.zeros((len(ti), 3))
    gyro[:, 2] = gz
    accel = np.tile([0.0, 0.0, 9.81], (len(ti), 1))
    orientation = None
    if ahrs_drift is not None:
        heading = np.interp(ti, t, yaw) + ahrs_drift * np.sin(np.pi * ti / duration) ** 2 + 0.01 * rng.standard_normal(len(ti))
        if ahrs_knots is not None:  # ((t, offset), ...): the heading's offset, linear between the knots
            knots = np.asarray(ahrs_knots, dtype=float)
            heading += np.interp(ti, knots[:, 0], knots[:, 1])
        orientation = np.stack([np.cos(heading / 2), 0 * ti, 0 * ti, np.sin(heading / 2)], axis=1)
    imu = ImuData(ti, gyro, accel, orientation, noise={"gyroscope_noise_density": gyro_noise})
    return odom, imu, truth
