"""IMU model: body yaw rate through T_BS, spike gating, AHRS heading and slope factors, range gating."""

import math

import numpy as np

from fusion_vo.measurements import ImuData, RangeData
from fusion_vo.sensors.imu import (ImuNoise, ahrs_heading, cumulative_angle, discrete_sigma, gyro_yaw, rest_noise_density,
                                  tilt_from_accel)
from fusion_vo.sensors.range import camera_height


def _imu(rate_z, T_BS=np.eye(4), orientation=None, hz=200.0):
    t = np.arange(len(rate_z)) / hz
    gyro = np.zeros((len(t), 3))
    gyro[:, 2] = rate_z
    return ImuData(t, gyro, np.tile([0, 0, 9.81], (len(t), 1)), orientation, T_BS, hz)


def test_discrete_sigma_from_noise_density():
    assert math.isclose(discrete_sigma(1.7e-4, 200.0), 1.7e-4 * math.sqrt(200.0))


def test_upside_down_imu_flips_the_yaw_rate():
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    g = gyro_yaw(_imu(np.full(50, 0.3), T_BS=T))
    np.testing.assert_allclose(g.rate, -0.3)


def test_spike_and_nan_are_gated_and_the_integral_is_unaffected():
    rate = np.full(400, 0.2)
    rate[100] = 25.0
    rate[250] = np.nan
    g = gyro_yaw(_imu(rate), ImuNoise())
    assert g.n_gated == 2 and g.gated[100] and g.gated[250]
    np.testing.assert_allclose(cumulative_angle(g)[-1], 0.2 * 399 / 200.0, rtol=1e-12)


def test_ahrs_heading_and_slope_factor():
    yaw, pitch = 0.7, 0.2
    # q = yaw about z, then pitch about y
    qz = np.array([math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)])
    qy = np.array([math.cos(pitch / 2), 0, math.sin(pitch / 2), 0])
    w1, x1, y1, z1 = qz
    w2, x2, y2, z2 = qy
    q = np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                  w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])
    h = ahrs_heading(_imu(np.zeros(3), orientation=np.tile(q, (3, 1))))
    np.testing.assert_allclose(h.yaw, yaw, atol=1e-12)
    np.testing.assert_allclose(h.cx, math.cos(pitch), atol=1e-12)
    np.testing.assert_allclose(h.cy, 1.0, atol=1e-12)


def test_tilt_from_gravity():
    roll, pitch = tilt_from_accel(np.array([[-9.81 * math.sin(0.1), 0.0, 9.81 * math.cos(0.1)]]))
    np.testing.assert_allclose([roll[0], pitch[0]], [0.0, 0.1], atol=1e-12)


def test_range_outliers_are_gated():
    d = np.full(20, 0.1)
    d[5], d[9], d[12] = 0.5, np.nan, -1.0
    h = camera_height(RangeData(np.arange(20) * 0.1, d))
    assert h.n_gated == 3
    np.testing.assert_allclose(h.height[h.valid], 0.1)


def test_rest_noise_density_is_measured_about_each_standstills_own_bias():
    rng = np.random.default_rng(0)
    hz, density = 30.0, 5e-4
    rate = np.concatenate([np.full(300, 0.002), np.full(150, 0.5), np.full(300, -0.001)])
    rate = rate + density * np.sqrt(hz) * rng.standard_normal(len(rate))
    at_rest = np.ones(len(rate), bool)
    at_rest[300:450] = False
    g = gyro_yaw(_imu(rate, hz=hz))
    measured = rest_noise_density(g, at_rest)
    assert abs(measured / density - 1.0) < 0.12, measured
    # one median over both standstills would add their 3 mrad/s bias difference to the scatter
    assert rest_noise_density(g, at_rest, min_samples=10) == measured
    assert rest_noise_density(g, np.arange(len(rate)) < 40) is None  # 1.3 s at rest: too few samples
