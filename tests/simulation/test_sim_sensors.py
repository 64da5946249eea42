"""Wheel encoders and gyro of a generated recording against its ground truth."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from fusion_vo.simulation.sensors import wrap_int32

EXACT_WHEELS = {"radius_error_left": 0.0, "radius_error_right": 0.0, "base_error": 0.0, "slip": 0.0}
QUIET_IMU = {"gyro_noise_density": 0.0, "gyro_random_walk": 0.0, "accel_noise_density": 0.0,
             "accel_random_walk": 0.0}


def read_csv(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Integer timestamps [ns] and the float columns of a data.csv file."""
    t = np.loadtxt(path, delimiter=",", comments="#", dtype=np.int64, usecols=0)
    values = np.loadtxt(path, delimiter=",", comments="#", dtype=np.float64, ndmin=2)[:, 1:]
    return t, values


def ground_truth(root: Path) -> tuple[np.ndarray, np.ndarray]:
    """GT timestamps [ns] and poses (x, y, yaw) with continuous yaw."""
    t, v = read_csv(root / "state_groundtruth_estimate0/data.csv")
    yaw = np.unwrap(2.0 * np.arctan2(v[:, 6], v[:, 3]))
    return t, np.column_stack([v[:, 0], v[:, 1], yaw])


def dead_reckoning(left: np.ndarray, right: np.ndarray, sensor: dict) -> np.ndarray:
    """Poses from encoder counts with the geometry of wheel0/sensor.yaml (arc per interval)."""
    k = 2 * math.pi / sensor["ticks_per_revolution"]
    d_l = wrap_int32(np.diff(left)) * k * sensor["wheel_radius_left"]
    d_r = wrap_int32(np.diff(right)) * k * sensor["wheel_radius_right"]
    pose = np.zeros((len(left), 3))
    for i, (dl, dr) in enumerate(zip(d_l, d_r)):
        x, y, yaw = pose[i]
        ds, dyaw = (dr + dl) / 2, (dr - dl) / sensor["wheel_base"]
        chord = ds * (math.sin(dyaw / 2) / (dyaw / 2) if abs(dyaw) > 1e-12 else 1.0)
        pose[i + 1] = x + chord * math.cos(yaw + dyaw / 2), y + chord * math.sin(yaw + dyaw / 2), yaw + dyaw
    return pose


def wheel_error(root: Path) -> tuple[float, float]:
    t_w, counts = read_csv(root / "wheel0/data.csv")
    sensor = yaml.safe_load((root / "wheel0/sensor.yaml").read_text())
    odo = dead_reckoning(counts[:, 0].astype(np.int64), counts[:, 1].astype(np.int64), sensor)
    t_gt, gt = ground_truth(root)
    idx = np.searchsorted(t_gt, t_w)
    assert np.array_equal(t_gt[idx], t_w)  # the wheel samples fall on ground-truth samples
    gt = gt[idx] - gt[idx[0]]
    return float(np.max(np.hypot(*(odo[:, :2] - gt[:, :2]).T))), float(np.max(np.abs(odo[:, 2] - gt[:, 2])))


def test_wheel_ticks_reproduce_ground_truth_without_calibration_error(generate):
    root = generate("exact_wheels", seed=3, duration=12.0, **EXACT_WHEELS)
    t_gt, gt = ground_truth(root)
    assert np.sum(np.hypot(*np.diff(gt[:, :2], axis=0).T)) > 1.0  # a real drive, with turns
    assert np.ptp(gt[:, 2]) > 0.5
    position, heading = wheel_error(root)
    # one tick is 0.077 mm of travel and 0.5 mrad of heading at most
    assert position < 1e-3
    assert heading < 1e-3


def test_wheel_calibration_error_shows_in_dead_reckoning(generate):
    root = generate("biased_wheels", seed=3, duration=12.0, **{**EXACT_WHEELS, "base_error": 0.02})
    position, heading = wheel_error(root)
    assert heading > 5e-3


def test_gyro_integrates_to_heading_change_plus_bias(generate):
    bias = 0.004
    root = generate("quiet_imu", seed=4, duration=10.0, gyro_bias=[0.001, -0.002, bias], **QUIET_IMU)
    t, imu = read_csv(root / "imu0/data.csv")
    seconds = (t - t[0]) * 1e-9
    turned = float(np.sum(np.diff(seconds) * (imu[1:, 2] + imu[:-1, 2]) / 2))
    t_gt, gt = ground_truth(root)
    true_turn = gt[np.searchsorted(t_gt, t[-1]), 2] - gt[np.searchsorted(t_gt, t[0]), 2]
    assert abs(true_turn) > 0.3
    assert abs(turned - (true_turn + bias * seconds[-1])) < 2e-4
    assert np.allclose(imu[:, 0:2], [0.001, -0.002], rtol=0, atol=1e-12)  # a planar robot: only the bias
    assert np.allclose(imu[:, 5], 9.81 + 0.03, rtol=0, atol=1e-9)  # gravity plus the default bias


def test_gyro_follows_the_heading_in_time():
    """Integrated over camera intervals, a noise-free gyro gives the poses' heading changes without a time
    offset: its error is not proportional to the change of the turn rate (interpolating the held commands
    from the start of their step made it lead by 0.5 ms: rms 1.9e-5 rad per interval, correlated over turns)."""
    from fusion_vo.simulation.robot import Limits, make_motion
    from fusion_vo.simulation.sensors import ImuNoise, imu_samples

    rng = np.random.default_rng(3)
    motion = make_motion("random", Limits(max_speed=0.3, max_turn_rate=0.9), rng, duration=20.0)
    times = np.arange(0.0, motion.t[-1], 1 / 200)
    gyro, _, _ = imu_samples(motion, times, ImuNoise(0.0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), rng)
    w = gyro[:, 2]
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(times))])
    nodes = np.arange(0.0, motion.t[-1] - 0.1, 0.05)
    error = np.diff(np.interp(nodes, times, angle)) - np.diff(np.interp(nodes, motion.t, motion.xyyaw[:, 2]))
    rate_change = np.diff(np.interp(nodes, motion.t, motion.w))
    assert np.ptp(motion.w) > 1.0  # it turns
    lead = np.sum(error * rate_change) / np.sum(rate_change**2)
    assert abs(lead) < 5e-5  # [s]
    assert np.sqrt(np.mean(error**2)) < 3e-6
