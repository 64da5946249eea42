"""The camera's increments against ground truth: their errors, and how honest their stated covariance is.

A visual increment ``z`` from frame time ``t0`` to ``t1`` states the body motion ``(x, y, ψ)`` between the
two poses and its covariance ``Σ``. Against a recording's ground truth (poses ``T(t)`` interpolated, yaw
unwrapped) its error is::

    e = z - T(t0)⁻¹ T(t1),    e_ψ wrapped to (-π, π]

and for a covariance that states the error honestly the normalised innovation squared
``NIS = eᵀ Σ⁻¹ e`` averages 3 (the increment's degrees of freedom), each component's ``e² / σ²`` averages
1, and, when the errors are independent from one increment to the next as both backends assume, the
errors of consecutive increments that share a frame are uncorrelated. A frontend that measures each frame
against the previous one puts that frame's own error into both increments with opposite signs: their
lag-1 correlation is then negative (-0.5 for a frame error alone).

These figures need ground truth (a generated recording); no run can compute them. They are what the
benchmarks print to say which input's error model is wrong, and what the tests of a renderer that the
estimator does not model hold.
"""

from __future__ import annotations

import numpy as np

from fusion_vo.geometry import se2
from fusion_vo.recording import Recording
from fusion_vo.sensors.imu import ImuNoise, gyro_yaw, read_imu


def increment_errors(rec: Recording, increments) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The errors of the usable (``ok``) visual ``increments`` against ``rec``'s ground truth.

    Returns
    -------
    errors : (n, 3) array
        Each increment minus the true body-frame increment over its interval (x, y [m], yaw [rad]).
    covariances : (n, 3, 3) array
        Their stated covariances.
    chained : (n,) bool array
        True where an increment starts at the frame where the previous one (in this list) ends, so that
        the two share a frame (the first is False).
    """
    gt = rec.groundtruth()
    yaw = np.unwrap(gt.xyyaw[:, 2])

    def pose(t):
        return np.array([np.interp(t, gt.t, gt.xyyaw[:, 0]), np.interp(t, gt.t, gt.xyyaw[:, 1]),
                         np.interp(t, gt.t, yaw)])

    used = [inc for inc in increments if inc.ok]
    errors = np.zeros((len(used), 3))
    for k, inc in enumerate(used):
        errors[k] = np.asarray(inc.delta, dtype=float) - se2.between(pose(inc.t0), pose(inc.t1))
        errors[k, 2] = se2.wrap_angle(errors[k, 2])
    covariances = np.array([np.asarray(inc.covariance, dtype=float) for inc in used]).reshape(-1, 3, 3)
    chained = np.array([k > 0 and used[k].t0 == used[k - 1].t1 for k in range(len(used))], dtype=bool)
    return errors, covariances, chained


def noise_statistics(errors: np.ndarray, covariances: np.ndarray, chained: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Second-order statistics of increment errors against their stated covariances.

    Parameters
    ----------
    errors, covariances, chained
        As returned by :func:`increment_errors`.

    Returns
    -------
    ratio : (3,) array
        Per component (x, y, yaw) the mean of ``e² / σ²`` over the drive: the factor by which the stated
        variance would have to be scaled to match the errors' mean square (1 when honest).
    lag1 : (3,) array
        Per component the correlation of the errors of consecutive increments that share a frame
        (``chained``; NaN with fewer than 9 such pairs).
    """
    variances = np.einsum("nii->ni", covariances)
    ratio = np.mean(errors**2 / variances, axis=0)
    pairs = np.flatnonzero(chained)
    lag1 = np.full(3, np.nan)
    if len(pairs) > 8:
        for i in range(3):
            lag1[i] = np.corrcoef(errors[pairs - 1, i], errors[pairs, i])[0, 1]
    return ratio, lag1


def against_truth(rec: Recording, vo) -> dict[str, float]:
    """How honest the inputs' stated noise is on ``rec``: the visual increments of ``vo`` (an
    :class:`~fusion_vo.odometry.OdometryResult`) and the gyro.

    Returns
    -------
    dict
        ``camera rms x [m]``, ``camera rms yaw [rad]``: RMS errors of the increments;
        ``camera median sigma x [m]``, ``camera median sigma yaw [rad]``: the median standard deviations
        their covariances state; ``camera mean NIS (3 if honest)``; the y-yaw correlation the covariances
        state (mean) and that of the errors. With an IMU, ``gyro scatter about the truth [rad/s]`` (the
        standard deviation of its yaw rate about the true one) beside ``gyro scatter stated [rad/s]`` (its
        noise density over the square root of its sampling interval).
    """
    gt = rec.groundtruth()
    yaw = np.unwrap(gt.xyyaw[:, 2])
    errors, covariances, _ = increment_errors(rec, vo.increments)
    nis = np.einsum("ni,ni->n", errors, np.linalg.solve(covariances, errors[..., None])[..., 0])
    sigmas = np.sqrt(np.einsum("nii->ni", covariances))
    rms = np.sqrt(np.mean(np.square(errors), axis=0))
    out = {"camera rms x [m]": float(rms[0]), "camera rms yaw [rad]": float(rms[2]),
           "camera median sigma x [m]": float(np.median(sigmas[:, 0])),
           "camera median sigma yaw [rad]": float(np.median(sigmas[:, 2])),
           "camera mean NIS (3 if honest)": float(np.mean(nis)),
           "camera stated y-yaw correlation (mean)": float(np.mean(covariances[:, 1, 2] / (sigmas[:, 1] * sigmas[:, 2]))),
           "camera y-yaw correlation of the errors": float(np.corrcoef(errors[:, 1], errors[:, 2])[0, 1])}
    if rec.has("imu0"):
        imu = read_imu(rec)
        noise = ImuNoise().with_sensor_keys(imu.noise)
        gyro = gyro_yaw(imu, noise)
        rate = np.interp(gyro.t, gt.t, np.gradient(yaw, gt.t))
        out["gyro scatter about the truth [rad/s]"] = float(np.std(gyro.rate - rate))
        out["gyro scatter stated [rad/s]"] = float(noise.gyro_noise_density * np.sqrt(1.0 / np.median(np.diff(gyro.t))))
    return out
