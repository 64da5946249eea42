"""The world frame when GPS is fused: East-North-Up at the datum, with an estimated first heading.

Without GPS the world frame W is the first pose (``FusionConfig.initial_pose``). With GPS it is ENU at
the datum of ``gps0/sensor.yaml``, and nothing tells the backends which way the robot first faced:

1. a GPS-free pass of the EKF (and its RTS smoother) over the same intervals gives a dead-reckoned
   track in the start frame;
2. :func:`~fusion_vo.sensors.gps.align_to_fixes` fits the rigid planar transform (heading, offset)
   that carries that track's antenna positions onto the first fixes (robust to multipath jumps); the
   window grows from 2 s of fixes, doubling, until the fitted heading's standard deviation
   (from the fixes' noise) is below :data:`TARGET_YAW_SIGMA`, or the whole recording is used;
3. absolute headings (the AHRS's), aligned to the configured initial heading, are turned by the same
   rotation (each sensor's ``turn``, :func:`turn_world`);
4. both backends then start at the aligned first pose, with a prior of three times the fit's
   standard deviations (heading at least :data:`MIN_YAW_SIGMA`), and the fixes themselves refine it;
5. with ``fusion.gps.estimate_sigma``, the fit's residuals measure the fixes' actual scatter about the
   GPS-free track (its own drift over the fitted span, from its covariance, taken out); when that is
   significantly larger than the receiver's stated sigma (:func:`~fusion_vo.sensors.gps.scatter_floor`),
   ``GpsGrid.min_sigma`` raises the fixes' sigma floor to it for both backends, and a note says so.

While the robot has not moved a few fix sigmas the heading is unobservable; the configured initial
heading is then kept, the first pose is put under the first fix, and a note says so.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math

import numpy as np

from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.timeline import Intervals
from fusion_vo.sensors.gps import align_to_fixes, fixes_in, gps_grid, predict, scatter_floor
from fusion_vo.sensors import registry
from fusion_vo.backends.ekf import run_ekf

logger = logging.getLogger(__name__)

TARGET_YAW_SIGMA = 0.01  # [rad]
MIN_YAW_SIGMA = 0.02  # [rad]
MAX_YAW_SIGMA = 0.5  # [rad]


def prior_from_alignment(fit, pose0: np.ndarray, fix_sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """First pose in ENU and its prior standard deviations from an :class:`~fusion_vo.sensors.gps.Alignment`."""
    pose = fit.apply(np.asarray(pose0, dtype=np.float64))[0]
    sxy = 3.0 * max(fit.rms, fix_sigma)
    syaw = float(np.clip(3.0 * fit.yaw_sigma, MIN_YAW_SIGMA, MAX_YAW_SIGMA))
    return pose, np.array([sxy, sxy, syaw])


def fallback_prior(iv: Intervals, config: FusionConfig, fix_sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """First pose under the first fix with the configured heading (heading not observable)."""
    grid = gps_grid(iv)
    k = int(np.argmax(grid.ok))
    yaw = float(config.initial_pose[2])
    lever = grid.fixes.lever_arm
    antenna = predict(np.array([0.0, 0.0, yaw]), lever)
    pose = np.array([*(grid.enu[k] - antenna), yaw])
    return pose, np.array([3.0 * fix_sigma, 3.0 * fix_sigma, 1e-3])


def turn_world(iv: Intervals, yaw: float) -> None:
    """The measurements of ``iv`` and the values its build carries re-expressed in the world frame turned by
    ``yaw`` (each sensor's :attr:`~fusion_vo.sensors.registry.Sensor.turn` and
    :attr:`~fusion_vo.sensors.registry.Carry.turn`: the AHRS's headings, aligned to the configured initial heading
    the alignment turned)."""
    for sensor in registry.sensors():
        if sensor.turn is not None and sensor.name in iv.sensors:
            sensor.turn(iv, yaw)
    iv.carry = registry.turned(iv.carry, yaw)


def align_world(iv: Intervals, config: FusionConfig) -> None:
    """Set ``iv.initial_pose`` / ``iv.initial_sigma`` in ENU from the fixes (module docstring); adds a note."""
    grid = gps_grid(iv)
    if grid is None or not grid.ok.any():
        return

    # the same measurements without the fixes (each sensor's own copy: nothing the run sets reaches iv)
    others = {name: copy.copy(m) for name, m in iv.sensors.items() if name != "gps"}
    free = dataclasses.replace(iv, sensors=others, notes=[], initial_pose=None, initial_sigma=None)
    track = run_ekf(free, config)
    traj = track.trajectories.get("ekf_smoothed") or track.trajectories["ekf"]
    gps = grid.fixes
    fix_sigma = math.sqrt(float(np.median(np.trace(gps.covariance, axis1=1, axis2=2))) / 2.0)
    t_first = float(iv.t[np.argmax(grid.ok)])
    fit = None
    window = 2.0
    while True:
        t_end = t_first + window
        candidate = align_to_fixes(traj.t, traj.xyyaw, gps, t_end=t_end)
        if candidate is not None:
            fit = candidate
            if fit.yaw_sigma <= TARGET_YAW_SIGMA:
                break
        if t_end >= traj.t[-1]:
            break
        window *= 2.0
    if fit is None:
        iv.initial_pose, iv.initial_sigma = fallback_prior(iv, config, fix_sigma)
        iv.notes.append("gps: the antenna never moved enough to estimate the first heading from the fixes; the "
                        f"configured initial heading {math.degrees(config.initial_pose[2]):.1f} deg is assumed")
        return
    iv.initial_pose, iv.initial_sigma = prior_from_alignment(fit, traj.xyyaw[0], fix_sigma)
    turn_world(iv, fit.yaw)
    iv.notes.append(f"gps: world frame is ENU at the datum {tuple(round(v, 7) for v in gps.datum)}; first heading "
                    f"{math.degrees(iv.initial_pose[2]):.2f} deg (east = 0, counter-clockwise) estimated from the "
                    f"fixes of the first {min(window, traj.t[-1] - t_first):.0f} s (± {math.degrees(fit.yaw_sigma):.2f} deg, "
                    f"fit residual {fit.rms:.3f} m, {fit.n_outliers} of {fit.n} fixes ignored as outliers)")
    logger.info("%s", iv.notes[-1])
    if config.gps.estimate_sigma:
        floor_from_scatter(iv, config, fit, track, traj, t_first + window, fix_sigma)


def track_drift_var(track, traj, gps, t_end: float) -> float:
    """Mean per-axis variance [m²] the GPS-free track gained since the first fitted fix, over the fitted fixes
    (from its own covariance; 0 when it has none)."""
    name = "ekf_smoothed" if "ekf_smoothed" in track.trajectories else "ekf"
    cov = track.covariances.get(name)
    if cov is None or len(cov) != len(traj.t):
        return 0.0
    idx = fixes_in(gps, traj.t[0], min(t_end, traj.t[-1]))
    if not len(idx):
        return 0.0
    var = np.interp(gps.t[idx], traj.t, 0.5 * (cov[:, 0, 0] + cov[:, 1, 1]))
    return float(np.mean(np.maximum(var - var[0], 0.0)))


def floor_from_scatter(iv: Intervals, config: FusionConfig, fit, track, traj, t_end: float, fix_sigma: float) -> None:
    """Raise the fixes' sigma floor to their measured scatter when it is significantly above the stated sigma."""
    grid = gps_grid(iv)
    est = scatter_floor(fit, fix_sigma, track_drift_var(track, traj, grid.fixes, t_end))
    if not est.significant or not est.sigma > max(config.gps.min_sigma, fix_sigma):
        return
    grid.min_sigma = est.sigma
    # the heading's sigma came from the stated sigma: scaled to the measured one (position sigma is the fit's rms)
    iv.initial_sigma[2] = float(np.clip(iv.initial_sigma[2] * est.sigma / max(fix_sigma, 1e-12), MIN_YAW_SIGMA,
                                        MAX_YAW_SIGMA))
    iv.notes.append(f"gps: fixes scatter {est.sigma:.2f} m per axis about the GPS-free track ({est.n} fixes of the "
                    f"alignment, its own drift {est.drift:.2f} m taken out), stated {est.stated:.2f} m: {est.sigma:.2f} m "
                    "used (fusion.gps.min_sigma); set fusion.gps.estimate_sigma: false to keep the stated")
    logger.info("%s", iv.notes[-1])
