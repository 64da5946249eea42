"""Wheel-encoder model: counter wrap-around, arc model, covariance growth, gating."""

import math

import numpy as np
import pytest

from fusion_vo.geometry import se2
from fusion_vo.measurements import TwistData, WheelConfig, WheelData
from fusion_vo.sensors.wheel import (
    WheelNoise, arc_covariance, arc_increment, arc_twist, ticks_to_travel, twist_to_travel, unwrap_ticks, wheel_track,
)

CFG = WheelConfig(ticks_per_revolution=1000.0, wheel_radius_left=0.05, wheel_radius_right=0.05, wheel_base=0.4)


def wrap32(n):
    return ((np.asarray(n, dtype=np.int64) + 2**31) % 2**32) - 2**31


@pytest.mark.parametrize("step", [7, -7])
def test_unwrap_crosses_the_signed_32_bit_boundary(step):
    start = 2**31 - 20 if step > 0 else -(2**31) + 20
    true = start + step * np.arange(10)
    recorded = wrap32(true)
    assert np.any(np.diff(recorded) * step < 0)  # the raw counter does wrap
    np.testing.assert_array_equal(unwrap_ticks(recorded), true)


def test_travel_is_continuous_across_a_wrap_and_a_jump_is_gated():
    t = np.arange(20) * 0.02
    ticks = 2**31 - 50 + 10 * np.arange(20)
    left = wrap32(ticks).copy()
    right = wrap32(ticks).copy()
    right[12] += 400_000  # one-sample glitch: two impossible intervals
    travel = ticks_to_travel(WheelData(t, left, right, CFG), WheelNoise(max_speed=5.0))
    per_tick = 2 * math.pi * 0.05 / 1000
    assert travel.n_gated == 2
    assert not travel.valid[11] and not travel.valid[12]
    # the glitch adds nothing: both wheels lose exactly the two gated intervals, the wrap is invisible
    np.testing.assert_allclose(travel.left[-1], 17 * 10 * per_tick)
    np.testing.assert_allclose(travel.right[-1], 17 * 10 * per_tick)


def test_arc_model_straight_turn_and_exponential_agree():
    np.testing.assert_allclose(arc_increment(0.3, 0.3, 0.4)[0], [0.3, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(arc_increment(-0.1, 0.1, 0.4)[0], [0.0, 0.0, 0.5], atol=1e-12)
    dl, dr, b = 0.2, 0.35, 0.4
    d, th = (dl + dr) / 2, (dr - dl) / b
    np.testing.assert_allclose(arc_increment(dl, dr, b)[0], se2.exp([d, 0.0, th]), atol=1e-12)


def test_arc_covariance_is_the_propagated_wheel_variance():
    # the bare model: no floor (outside the configuration's range, so not checked)
    noise = WheelNoise.model_construct(k=0.02, sigma_floor=0.0, k_lateral=0.0, k_yaw=0.0)
    dl, dr, b = 0.3, 0.5, 0.4
    eps = 1e-7
    J = np.stack([(arc_increment(dl + eps, dr, b) - arc_increment(dl - eps, dr, b))[0] / (2 * eps),
                  (arc_increment(dl, dr + eps, b) - arc_increment(dl, dr - eps, b))[0] / (2 * eps)], axis=1)
    expected = J @ np.diag([noise.k**2 * dl, noise.k**2 * dr]) @ J.T
    np.testing.assert_allclose(arc_covariance(dl, dr, b, noise)[0], expected, rtol=1e-6, atol=1e-14)


def test_covariance_grows_with_distance_and_turning():
    noise = WheelNoise()
    short, long_ = arc_covariance([0.5, 1.0], [0.5, 1.0], 0.4, noise)
    assert np.all(np.diag(long_) > np.diag(short))
    straight, turning = arc_covariance([0.5, 0.3], [0.5, 0.7], 0.4, noise)
    assert turning[2, 2] > straight[2, 2]
    assert np.trace(turning) > np.trace(straight)


def test_twist_covariance_matches_the_increment_model_for_small_steps():
    noise = WheelNoise.model_construct(k_lateral=0.0, k_yaw=0.0, sigma_floor=0.0)  # the bare model, as above
    u, R = arc_twist(0.01, 0.012, 0.05, 0.4, noise)
    cov = arc_covariance(0.01, 0.012, 0.4, noise)[0]
    np.testing.assert_allclose(u[0], [0.22, 0.0, 0.1], rtol=1e-12)
    np.testing.assert_allclose(R[0][[0, 2]][:, [0, 2]] * 0.05**2, cov[[0, 2]][:, [0, 2]], rtol=2e-3, atol=1e-12)


def test_constant_twist_drives_a_circle():
    t = np.arange(0, 2 * math.pi / 0.5 + 1e-9, 0.01)
    n = len(t)
    track = wheel_track(twist_to_travel(TwistData(t, np.full(n, 0.5), np.zeros(n), np.full(n, 0.5)), 0.4))
    xy = track.xyyaw[:, :2]
    np.testing.assert_allclose(np.hypot(xy[:, 0], xy[:, 1] - 1.0), 1.0, atol=1e-3)  # radius v/ω = 1 m
    np.testing.assert_allclose(xy[-1], [0.0, 0.0], atol=1e-2)


def test_correlated_skid_variance_is_inflated_against_an_independent_turn():
    """``(s_ψ θ)² τ/Δt`` where a gyro measures the turn; the plain ``(s_ψ θ)²`` for wheels alone."""
    from fusion_vo.sensors.wheel import skid_variance

    noise = WheelNoise(k_yaw=0.0, yaw_scale=0.3, yaw_scale_time=5.0)
    alone = skid_variance(np.array([0.02]), np.array([0.05]), noise)
    np.testing.assert_allclose(alone, (0.3 * 0.02) ** 2)
    fused = skid_variance(np.array([0.02, 0.02]), np.array([0.05, 0.05]), noise, np.array([0.03, np.nan]))
    np.testing.assert_allclose(fused, [(0.3 * 0.03) ** 2 * 100.0, (0.3 * 0.02) ** 2])
    # a turn lasting τ sums to the variance of one sample of the relative error, whatever the rate
    for dt in (0.01, 0.1):
        n = int(round(5.0 / dt))
        total = skid_variance(np.full(n, 0.2 * dt), np.full(n, dt), noise, np.full(n, 0.2 * dt)).sum()
        np.testing.assert_allclose(total, (0.3 * 0.2 * 5.0) ** 2, rtol=1e-9)


def test_standstill_needs_both_wheels_at_rest():
    from fusion_vo.sensors.wheel import standstill

    noise = WheelNoise(standstill_speed=1e-3)
    still = standstill([0.0, 0.0, 1e-5, 0.0], [0.0, 2e-4, 1e-5, 0.0], [0.1, 0.1, 0.1, 0.1], noise)
    assert still.tolist() == [True, False, True, True]
    assert not standstill([0.0], [0.0], [0.1], WheelNoise(standstill_speed=0.0)).any()


@pytest.mark.parametrize("d,theta", [(0.0, 0.05), (0.01, 0.0), (0.01, 0.045), (-0.01, 0.045), (0.015, -0.03)])
def test_curved_model_predicts_what_wheels_of_unequal_radii_report(d, theta):
    # radii 0.6 % too large on the left, 0.4 % too small on the right of what is configured, base 1.5 % wider:
    # the robot drives an arc of length d turning by theta over one camera interval
    from fusion_vo.sensors.wheel import CURVED_WHEEL

    b, b_true = 0.3, 0.3 * 1.015
    s_l, s_r = 1 / 1.006, 1 / 0.996  # reported over rolled travel
    k_r, c = 0.5 * (s_l + s_r), (s_r - s_l) / b
    k_b = k_r * b_true / b
    rolled_l, rolled_r = d - theta * b_true / 2, d + theta * b_true / 2
    motion = arc_increment(rolled_l, rolled_r, b_true)[0]
    reported = arc_increment(s_l * rolled_l, s_r * rolled_r, b)[0]
    h = CURVED_WHEEL.evaluate(motion, [k_r], [k_b], [c], b)[0]
    # turning, the faster wheel's excess reports c b^2 / 4 per radian of forward travel (3.8e-5 m here for a
    # turn in place); what is left is of second order in the interval's turn
    assert abs(reported[0] - h[0]) < 2e-7
    assert abs(reported[2] - h[2]) < 2e-7
