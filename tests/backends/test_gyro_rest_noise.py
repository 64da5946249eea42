"""The gyro's noise density at rest (``imu.gyro_rest_noise_density``) is used for the intervals at rest only."""

import dataclasses

import numpy as np

from fusion_vo.backends import FusionConfig, SensorStreams
from fusion_vo.backends.timeline import build_intervals
from fusion_vo.sensors.imu import gyro_yaw, readings, rest_noise_density
from fusion_vo.sensors.wheel import at_rest

from husky_like import husky_like


def test_rest_density_is_measured_and_used_at_rest_only():
    # a twist with a 10 s stop; the gyro's true density 5e-4, its recording claiming eight times more
    odom, imu, _ = husky_like(duration=40.0, stop=(10.0, 20.0), gyro_noise=5e-4, seed=2)
    streams = SensorStreams(odom=odom, imu=dataclasses.replace(imu, noise={"gyroscope_noise_density": 4e-3}))
    resting = np.interp(imu.t, odom.t, ((odom.vx == 0) & (odom.wz == 0)).astype(float)) == 1.0
    rest = rest_noise_density(gyro_yaw(imu), resting)
    assert 4e-4 < rest < 6e-4, rest
    for configured, expected in ((0.0, 4e-3), (rest, rest), (1e-2, 4e-3)):  # never above the recorded one
        config = FusionConfig.from_dict({"imu": {"gyro_noise_density": 4e-3, "gyro_rest_noise_density": configured}})
        iv = build_intervals(streams, config)
        still = at_rest(iv, config)
        assert 150 < np.count_nonzero(still) < 210  # 10 s of 20 Hz nodes
        gyro = next(r for r in readings(iv, config) if r.sensor == "gyro")  # σ² Δt per interval
        var = np.full(iv.n_steps, np.nan)
        var[gyro.i0] = gyro.cov[:, 0, 0]
        np.testing.assert_allclose(var[still], expected**2 * iv.dt[still])
        np.testing.assert_allclose(var[~still], 4e-3**2 * iv.dt[~still])
