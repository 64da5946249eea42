"""The delay of one yaw-rate stream behind another (fusion_vo.sensors.sync) is measured where both have samples."""

import numpy as np

from fusion_vo.sensors.sync import rate_correlation, rate_delay


def turning(t: np.ndarray) -> np.ndarray:
    """A yaw rate [rad/s] that turns left and right irregularly."""
    return 0.4 * np.sin(0.9 * t) + 0.25 * np.sin(2.3 * t + 1.0) + 0.1 * np.sin(5.1 * t)


def test_a_pause_in_one_stream_is_left_out_and_the_delay_found():
    # the gyro at 100 Hz for 80 s; the odometry at 50 Hz, 0.2 s late, with 30 s missing in the middle
    t_b = np.arange(0.0, 80.0, 0.01)
    t_a = np.arange(0.0, 80.0, 0.02)
    t_a = t_a[(t_a < 25.0) | (t_a > 55.0)]
    rate_a = turning(t_a - 0.2)
    d = rate_delay(t_a, rate_a, t_b, turning(t_b))
    # (interpolated across the pause, the odometry's rate is a straight line where the gyro turns: no delay found)
    assert d is not None and abs(d - 0.2) < 0.005
    # the same with the pause in the other stream
    d = rate_delay(t_b, turning(t_b - 0.2), t_a, turning(t_a))
    assert d is not None and abs(d - 0.2) < 0.005
    c0, cd = rate_correlation(t_a, rate_a, t_b, turning(t_b), (0.0, 0.2), margin=1.0)
    assert cd > 0.999 and c0 < 0.99


def test_an_hour_long_pause_in_both_streams_changes_nothing():
    t_b = np.arange(0.0, 40.0, 0.01)
    t_a = np.arange(0.0, 40.0, 0.02)
    d = rate_delay(t_a, turning(t_a - 0.15), t_b, turning(t_b))
    # both streams stop for an hour after 20 s and resume (the robot parked); the turns after it are new ones
    later = lambda t: np.where(t < 20.0, t, t + 3600.0)  # noqa: E731
    paused = rate_delay(later(t_a), turning(t_a - 0.15), later(t_b), turning(t_b))
    assert d is not None and abs(d - 0.15) < 0.005
    assert paused is not None and abs(paused - d) < 0.002
