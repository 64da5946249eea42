"""The camera-noise calibration drive: visual odometry on drives with ground truth, their heading errors, the model.

``fusion-vo calibrate camera-noise`` runs :func:`calibrate`; the model it measures and its fit are in
:mod:`fusion_vo.calibration.camera_noise`.
"""

from __future__ import annotations


import numpy as np

from fusion_vo.calibration.camera_noise import CameraNoise, measure
from fusion_vo.errors import InputError
from fusion_vo.geometry import se2
from fusion_vo.odometry import OdometryConfig, run_visual_odometry


def heading_errors(recording, increments) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heading errors [rad] of the usable ``increments`` against ``recording``'s ground truth, their
    measured turns [rad], and whether each starts where the previous one ended."""
    gt = recording.groundtruth()
    yaw = np.unwrap(gt.xyyaw[:, 2])
    used = [inc for inc in increments if inc.ok]
    t0 = np.array([inc.t0 for inc in used])
    t1 = np.array([inc.t1 for inc in used])
    turns = np.array([float(inc.delta[2]) for inc in used])
    inside = (t0 >= gt.t[0]) & (t1 <= gt.t[-1])
    true = np.interp(t1, gt.t, yaw) - np.interp(t0, gt.t, yaw)
    errors = se2.wrap_angle(turns - true)
    chained = np.array([k > 0 and used[k].t0 == used[k - 1].t1 for k in range(len(used))], dtype=bool)
    chained[1:] &= inside[:-1]
    return errors[inside], turns[inside], chained[inside]


def calibrate(recordings: list, config=None) -> CameraNoise:
    """Run visual odometry (``config``: an :class:`~fusion_vo.odometry.OdometryConfig`) on each recording,
    which must have ground truth, and measure the camera's heading noise over all their increments."""
    config = config or OdometryConfig()
    for rec in recordings:  # all of them before any work
        if not rec.has_groundtruth():
            raise InputError("a calibration drive needs ground truth (state_groundtruth_estimate0/)", rec.path)
    errors, turns, chained = [], [], []
    for rec in recordings:
        vo = run_visual_odometry(rec, config.model_copy(update={"camera_noise": False}))
        e, t, c = heading_errors(rec, vo.increments)
        if len(c):
            c[0] = False
        errors.append(e)
        turns.append(t)
        chained.append(c)
    return measure(np.concatenate(errors), np.concatenate(turns), np.concatenate(chained), config.frontend)
