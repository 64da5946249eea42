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


def test_the_curvature_bias_is_not_estimated_by_default(streams):
    assert "wheel_curvature" not in fuse(streams, "ekf").calibration["ekf"]
