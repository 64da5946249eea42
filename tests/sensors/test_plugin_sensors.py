"""A new sensor is one module and its registration, with no backend code: ranges to known beacons
(beacon_sensor.py: readings of the pose) and a second robot base's odometry with a scale of its own
(second_odometry.py: readings of the motion and a state), both written beside this file, are fused by the EKF
and the factor graph through their one adapter each."""

from __future__ import annotations

import numpy as np
import pytest

from beacon_sensor import BEACON_SENSOR, BeaconData
from second_odometry import SECOND_ODOMETRY, TwistData

from fusion_vo.backends import SensorStreams, fuse
from fusion_vo.sensors import registry
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

BEACONS = [[3.0, -1.0], [-2.0, 4.0], [6.0, 5.0]]
TRACKS = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")


@pytest.fixture(scope="module")
def drive():
    """40 s of wheels and gyro on a robot whose wheel base is 5 % larger than configured (its heading drifts)."""
    return synthetic_streams(SyntheticOptions(duration=40.0, wheel_base_factor=1.05), seed=11)


def _position_rms(track, truth) -> float:
    xy = np.column_stack([np.interp(track.t, truth.t, truth.xyyaw[:, i]) for i in range(2)])
    return float(np.sqrt(np.mean(np.sum((track.xyyaw[:, :2] - xy) ** 2, axis=1))))


def test_ranges_to_beacons_defined_in_one_module_bound_the_drift_in_both_backends(drive):
    s = drive
    rng = np.random.default_rng(5)
    t = np.arange(s.truth.t[0] + 0.05, s.truth.t[-1] - 0.05, 0.1)
    which = np.arange(len(t)) % len(BEACONS)
    p = np.column_stack([np.interp(t, s.truth.t, s.truth.xyyaw[:, i]) for i in range(2)])
    distance = np.linalg.norm(p - np.asarray(BEACONS)[which], axis=1) + rng.normal(0.0, 0.05, len(t))
    config = {"graph": {"fixed_lag": 0.0}}
    base = SensorStreams(wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)
    without = fuse(base.select(["wheel", "imu"]), "all", config)
    config["beacon"] = {"sigma": 0.05, "positions": BEACONS}  # its section exists once it is registered
    with registry.registered(BEACON_SENSOR):
        streams = SensorStreams(wheel=s.wheel, imu=s.imu, camera_height=s.camera_height,
                                extra={"beacon": BeaconData(t, which, distance)})
        result = fuse(streams.select(["wheel", "imu", "beacon"]), "all", config)
    for name in TRACKS:
        free, ranged = _position_rms(without.trajectories[name], s.truth), _position_rms(result.trajectories[name],
                                                                                          s.truth)
        assert free > 0.15, name  # the wheels' heading drifts decimetres away
        assert ranged < 0.25 * free, (name, ranged, free)  # three beacons at 5 cm hold it to centimetres
    assert result.counts["ekf"]["beacon"].used > 0.9 * len(t)


def test_a_second_base_with_its_own_scale_state_is_calibrated_by_both_backends(drive):
    s = drive
    rng = np.random.default_rng(6)
    t = np.arange(s.truth.t[0], s.truth.t[-1], 0.02)
    yaw = np.unwrap(s.truth.xyyaw[:, 2])
    dt = np.gradient(s.truth.t)
    v_true = np.hypot(np.gradient(s.truth.xyyaw[:, 0]), np.gradient(s.truth.xyyaw[:, 1])) / dt
    w_true = np.gradient(yaw) / dt
    v = 1.03 * np.interp(t, s.truth.t, v_true) + rng.normal(0.0, 0.005, len(t))  # 3 % too long
    w = np.interp(t, s.truth.t, w_true) + rng.normal(0.0, 0.005, len(t))
    with registry.registered(SECOND_ODOMETRY):
        streams = SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height,
                                extra={"second_base": TwistData(t, v, w)})
        result = fuse(streams.select(["camera", "wheel", "imu", "second_base"]), "all", {"graph": {"fixed_lag": 0.0}})
    for name in TRACKS:
        scale = result.calibration[name]["second_base_scale"]
        assert scale == pytest.approx(1.03, abs=0.004), (name, scale)
    assert result.counts["gtsam"]["second_base"].used > 0.9 * len(result.trajectories["gtsam"].t)
