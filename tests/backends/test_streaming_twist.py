"""Streaming hooks a live node publishes: the twist of the current estimate, the smoother's pose at a lag."""

import numpy as np
import pytest

from fusion_vo.backends import FusionConfig, StreamingFusion
from fusion_vo.measurements import ImuSample, WheelTicks
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


@pytest.fixture(scope="module")
def drive():
    return synthetic_streams(SyntheticOptions(duration=6.0), seed=5)


def _fed(s, backend):
    fusion = StreamingFusion(backend, FusionConfig(reorder_window=0.05), ["camera", "wheel", "imu"],
                             wheel_config=s.wheel.config, imu_noise=s.imu.noise)
    msgs = [(v.t1, 0, "visual", v) for v in s.visual]
    msgs += [(t, 1, "wheel", WheelTicks(t, lt, rt)) for t, lt, rt in zip(s.wheel.t, s.wheel.left, s.wheel.right)]
    msgs += [(t, 2, "imu", ImuSample(t, g, a)) for t, g, a in zip(s.imu.t, s.imu.gyro, s.imu.accel)]
    msgs.sort(key=lambda m: (m[0], m[1]))
    fusion.feed((t, kind, m) for t, _, kind, m in msgs)
    return fusion


def _true_twist(s, t, dt=0.05):
    tr = s.truth
    yaw = np.unwrap(tr.xyyaw[:, 2])
    a = np.array([np.interp(t - dt, tr.t, tr.xyyaw[:, 0]), np.interp(t - dt, tr.t, tr.xyyaw[:, 1]),
                  np.interp(t - dt, tr.t, yaw)])
    b = np.array([np.interp(t, tr.t, tr.xyyaw[:, 0]), np.interp(t, tr.t, tr.xyyaw[:, 1]), np.interp(t, tr.t, yaw)])
    c, s_ = np.cos(a[2]), np.sin(a[2])
    d = b[:2] - a[:2]
    return np.array([c * d[0] + s_ * d[1], -s_ * d[0] + c * d[1], b[2] - a[2]]) / dt


@pytest.mark.parametrize("backend", ["ekf", "gtsam"])
def test_the_estimate_carries_the_body_twist_and_its_covariance(drive, backend):
    fusion = _fed(drive, backend)
    est = fusion.processed_estimate()
    truth = _true_twist(drive, est.t)
    assert abs(truth[0]) > 0.05  # the drive moves: a zero twist would fail
    # the EKF's twist state; iSAM2's difference of two online node poses 50 ms apart (their mm errors / 50 ms)
    np.testing.assert_allclose(est.twist, truth, atol=0.01 if backend == "ekf" else 0.05)
    assert np.all(np.linalg.eigvalsh(est.twist_covariance) > 0)
    ahead = fusion.current_estimate(est.t + 0.5)
    np.testing.assert_allclose(ahead.twist, est.twist, atol=1e-9)  # constant twist
    assert np.all(np.diag(ahead.twist_covariance) > np.diag(est.twist_covariance))  # grown by the prediction
    older = fusion.current_estimate(est.t - 1.0)
    assert older.twist is None and older.twist_covariance is None


def test_the_smoothed_estimate_is_the_smoother_pose_of_that_node(drive):
    fusion = _fed(drive, "gtsam")
    t_last = fusion.processed_estimate().t
    lagged = fusion.smoothed_estimate(t_last - 1.0)
    whole = fusion.smoothed()
    i = int(np.searchsorted(whole.t, lagged.t))
    assert whole.t[i] == pytest.approx(lagged.t) and t_last - 1.1 < lagged.t <= t_last - 1.0 + 1e-9
    np.testing.assert_allclose(lagged.pose, whole.xyyaw[i], atol=1e-9)
    assert np.all(np.linalg.eigvalsh(lagged.covariance) > 0)
    assert fusion.smoothed_estimate(whole.t[0] - 1.0) is None
    assert _fed(drive, "ekf").smoothed_estimate(t_last) is None
