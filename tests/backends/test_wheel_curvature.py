"""Unequal left/right wheel radii: both backends estimate the wheels' curvature bias within its covariance."""

import dataclasses
import math

import pytest
from backend_synth import streams_of

from fusion_vo.backends import FusionConfig, fuse
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

ERROR = 0.01  # the left radius stated 1 % too large, the right one 1 % too small
RADIUS_SIGMA = 0.01  # relative, as wheel0/sensor.yaml's radius_sigma / radius


@pytest.fixture(scope="module")
def streams():
    s = synthetic_streams(SyntheticOptions(duration=20.0), seed=21)
    cfg = s.wheel.config
    cfg = dataclasses.replace(cfg, wheel_radius_left=cfg.wheel_radius_left * (1 + ERROR),
                              wheel_radius_right=cfg.wheel_radius_right * (1 - ERROR),
                              radius_sigma=RADIUS_SIGMA * cfg.wheel_radius_left)
    out = streams_of(s).select(["camera", "wheel", "imu"])
    out.wheel = dataclasses.replace(out.wheel, config=cfg)
    return out


@pytest.mark.parametrize("backend", ["ekf", "gtsam"])
def test_a_radius_difference_is_estimated_within_its_covariance(streams, backend):
    base = streams.wheel.config.wheel_base
    # the wheels read d_l (1 + e) and d_r (1 - e): a turn of -2 e / b per metre the body did not make
    truth = -2.0 * ERROR / base
    prior = math.sqrt(2.0) * RADIUS_SIGMA / base
    config = FusionConfig.from_dict({"wheel": {"estimate_curvature": True}})
    cal = fuse(streams, backend, config).calibration[backend]
    c, sigma = cal["wheel_curvature"], cal["wheel_curvature_sigma"]
    assert sigma < 0.5 * prior  # the data, not the prior, decides
    assert abs(c - truth) < 3.0 * sigma
    assert abs(c) > 2.0 * sigma  # no radius difference is not what it finds


def test_the_curvature_bias_is_estimated_by_default_and_can_be_turned_off(streams):
    assert "wheel_curvature" in fuse(streams, "ekf").calibration["ekf"]
    off = FusionConfig.from_dict({"wheel": {"estimate_curvature": False}})
    assert "wheel_curvature" not in fuse(streams, "ekf", off).calibration["ekf"]


def test_a_two_row_factor_of_five_variables_linearises():
    # the translation rows of a wheel factor with its radius factor, wheel-base factor and curvature bias, as
    # whitened for iSAM2 on the generated random60 drive: summed from two-variable Hessian pieces and factored
    # back into rows, GTSAM's Cholesky found this rank-2 quadratic indefinite
    import gtsam
    import numpy as np

    from fusion_vo.backends.factors import ValuesMaker, gaussian_factor

    keys = [gtsam.symbol("x", 1100), gtsam.symbol("x", 1101), gtsam.symbol("r", 55), gtsam.symbol("w", 55),
            gtsam.symbol("a", 55)]
    blocks = [np.array([[-1.7393e+03, 0.0, -1.2248e+00], [0.0, -2.4046e+03, -1.5643e+01]]),
              np.array([[1.7393e+03, -7.9999e-03, 1.2241e+00], [1.1060e-02, 2.4046e+03, 0.0]]),
              np.array([[1.1325e+01], [-1.0007e-03]]), np.array([[5.5539e-06], [0.0]]), np.array([[0.0002], [0.0]])]
    b = np.array([-5.63004652e-06, 9.52181415e-15])
    items = [v for key, a in zip(keys, blocks) for v in (key, a)]
    values = ValuesMaker().make({keys[0]: gtsam.Pose2(), keys[1]: gtsam.Pose2(0.01, 0, 0), keys[2]: 1.0,
                                 keys[3]: 1.0, keys[4]: 0.0})
    factor = gaussian_factor(items, b, gtsam.noiseModel.Unit.Create(2), values)
    A, rhs = factor.jacobian()
    np.testing.assert_allclose(A, np.hstack(blocks), rtol=1e-12)  # the same rows, GTSAM's key order
    np.testing.assert_allclose(rhs, b, rtol=1e-12)


@pytest.fixture(scope="module")
def wheels_and_gyro():
    """A 60 s drive with equal wheel radii fused from the encoder wheels and the gyro alone."""
    s = synthetic_streams(SyntheticOptions(duration=60.0), seed=1)
    return s, streams_of(s).select(["wheel", "imu"])


def test_without_a_heading_reference_the_curvature_is_not_estimated_by_default(wheels_and_gyro):
    from backend_synth import position_errors

    s, streams = wheels_and_gyro
    auto = fuse(streams, "all")
    forced = fuse(streams, "all", FusionConfig.from_dict({"wheel": {"estimate_curvature": True}}))
    assert "wheel_curvature" not in auto.calibration["ekf"] and "wheel_curvature" in forced.calibration["ekf"]
    assert any(n.startswith("wheel curvature bias not estimated") for n in auto.notes)
    assert not any(n.startswith("wheel curvature bias not estimated") for n in forced.notes)
    # with equal radii the state only trades the gyro's bias for a turn the wheels do not make
    for name in ("ekf", "gtsam"):
        _, rms_auto = position_errors(auto.trajectories[name], s.truth)
        _, rms_forced = position_errors(forced.trajectories[name], s.truth)
        assert rms_auto < 0.5 * rms_forced, (name, rms_auto, rms_forced)
        assert auto.calibration[name]["gyro_bias"] == pytest.approx(0.01, abs=0.005), name


def test_an_ahrs_heading_makes_the_curvature_estimated_by_default():
    s = synthetic_streams(SyntheticOptions(duration=5.0, ahrs_sigma=0.02), seed=2)
    result = fuse(streams_of(s).select(["wheel", "imu"]), "ekf")
    assert "wheel_curvature" in result.calibration["ekf"]


@pytest.mark.parametrize("value", ["sometimes", 2])
def test_estimate_curvature_accepts_true_false_or_auto(value):
    for ok in (True, False, "auto"):
        assert FusionConfig.from_dict({"wheel": {"estimate_curvature": ok}}).wheel.estimate_curvature == ok
    with pytest.raises(ValueError, match=r"wheel: estimate_curvature must be true, false or 'auto', not "):
        FusionConfig.from_dict({"wheel": {"estimate_curvature": value}})
