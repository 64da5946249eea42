"""GPS (GNSS) fix as a measurement of the antenna's position in a local East-North-Up frame.

Model
-----
The state is the planar pose ``x = (x, y, ψ)`` of the body B in the world W. When GPS is fused, W is
East-North-Up at the datum of ``gps0/sensor.yaml`` (x east, y north). The antenna sits at the lever arm
``l = (l_x, l_y)`` in the body frame (the translation of ``T_BS``; its height plays no part in a
planar model). A fix measures the antenna's horizontal position::

    z = h(x) + n,      h(x) = [x, y]ᵀ + R(ψ) l,      n ~ N(0, Σ)

    R(ψ) = [[cos ψ, -sin ψ],
            [sin ψ,  cos ψ]]

``Σ`` is the fix's own 2x2 horizontal covariance (NavSatFix ``position_covariance``, east-north block),
or ``σ² I`` with the default ``horizontal_sigma_m`` when the fix carries none.

Jacobian with respect to ``(x, y, ψ)`` (world-frame perturbations, as the EKF uses)::

    H = ∂h/∂x = [[1, 0, -sin ψ · l_x - cos ψ · l_y],
                 [0, 1,  cos ψ · l_x - sin ψ · l_y]]

GTSAM perturbs a ``Pose2`` on the right, ``x ⊕ δ = x · Exp(δ)`` with ``δ`` in the body frame; the
Jacobian with respect to ``δ = (δx, δy, δψ)`` is ``[R(ψ) | R(ψ) [-l_y, l_x]ᵀ]`` (:func:`gps_factor`).

Outliers
--------
With the innovation ``r = z - h(x)`` and its covariance ``S`` (``S = H P Hᵀ + Σ`` in a filter with state
covariance ``P``; ``S = Σ`` against a fixed estimate), the squared Mahalanobis distance is
``d² = rᵀ S⁻¹ r``. A fix with ``d² > gate_chi2`` (default 13.82, the 99.9 % point of χ² with 2 degrees
of freedom) is rejected and counted. Accepted fixes are further down-weighted by a robust kernel of
``d`` with width ``k`` (the weight multiplies the information ``Σ⁻¹``; a filter divides ``Σ`` by it):

* Huber:  ``w(d) = 1`` for ``d ≤ k``, else ``k / d``
* Cauchy: ``w(d) = 1 / (1 + (d / k)²)``

In the factor graph the same kernel is GTSAM's ``mEstimator`` wrapped round the fix's Gaussian noise, so
a 20 m multipath jump against decimetre noise pulls on the solution with a force that vanishes (Cauchy)
or stays bounded (Huber); :meth:`GpsModel.check` gates it out before it is added at all.

World alignment
---------------
Before GPS is fused the estimate lives in a frame anchored at the first pose. :func:`align_to_fixes`
estimates the rigid planar transform (heading and offset) that carries a dead-reckoned track onto the
first fixes, so that a backend can start in ENU with an estimated, not assumed, initial heading.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from fusion_vo.geometry import se2
from fusion_vo.measurements import GpsData
from fusion_vo.sensors.registry import Live, Sensor, Step, register
from fusion_vo.measurements import SensorCount
from fusion_vo.measurements.grid import time_order

log = logging.getLogger(__name__)

#: a fix closer than this to an existing node [s] is applied at that node
GPS_SNAP = 1e-3
OUTAGE_NOTE_S = 2.0  # [s] a gap between GPS fixes at least this long is reported with its drift

#: 99.9 % point of the chi-square distribution with 2 degrees of freedom
CHI2_2DOF_999 = 13.815510557964274
ROBUST_KERNELS = ("huber", "cauchy", "none")


# ---------------------------------------------------------------------- configuration
@dataclass
class GpsNoise:
    """Gating and robust weighting of GPS fixes.

    Attributes
    ----------
    gate_chi2 : float
        Squared Mahalanobis distance above which a fix is rejected (default: 99.9 % of χ²(2)).
    kernel : str
        ``"huber"``, ``"cauchy"`` or ``"none"``.
    kernel_width : float
        ``k`` of the kernel, in units of the Mahalanobis distance (default 2.0).
    min_sigma : float
        Floor on the horizontal standard deviation [m] so that an optimistic receiver cannot pin the
        estimate (default 0.01).
    estimate_sigma : bool
        Measure the fixes' scatter about the GPS-free track in the world-frame alignment and, when it is
        significantly larger than the receiver's stated sigma, raise ``min_sigma`` to it for the run
        (:func:`scatter_floor`; batch backends only, ``StreamingFusion`` keeps the stated sigma). Default
        False, as measured by ``python benchmarks/gps_fusion.py``: on the Husky bag (stated 0.80 m) it
        measures 1.51 m, the gate then rejects no fix of the first half (EKF 39, graph 209 with the stated
        sigma), yet the withheld second half gets worse in every backend (RMS EKF 4.69 -> 4.86 m, EKF + RTS
        4.61 -> 4.82, GTSAM batch 4.52 -> 4.97, iSAM2 4.19 -> 4.69); with the first third or two thirds
        fused (``--husky-split 0.33 / 0.67``) the EKF gains (5.10 -> 4.47, 8.14 -> 6.69 m) and the graph
        loses once and gains once (4.36 -> 4.63, 7.53 -> 7.34 m): no consistent gain. On ``gps_outage``
        (honest 5 cm) the test does not fire and nothing changes.
    """

    gate_chi2: float = CHI2_2DOF_999
    kernel: str = "cauchy"
    kernel_width: float = 2.0
    min_sigma: float = 0.01
    estimate_sigma: bool = False

    def __post_init__(self) -> None:
        if self.kernel not in ROBUST_KERNELS:
            raise ValueError(f"GPS kernel must be one of {', '.join(ROBUST_KERNELS)}, not {self.kernel!r}")
        if not self.gate_chi2 > 0 or not self.kernel_width > 0 or not self.min_sigma >= 0:
            raise ValueError("GPS gate_chi2 and kernel_width must be positive, min_sigma not negative")


# ---------------------------------------------------------------------- model
def predict(pose, lever_arm) -> np.ndarray:
    """Predicted antenna position ``h(x) = [x, y] + R(ψ) l`` (module docstring).

    Parameters
    ----------
    pose : array_like, shape (3,) or (N, 3)
        ``(x, y, ψ)`` of B in W.
    lever_arm : array_like, shape (2,) or (3,)
        Antenna position in the body frame [m]; only ``x, y`` are used.
    """
    p = np.asarray(pose, dtype=np.float64)
    lx, ly = float(lever_arm[0]), float(lever_arm[1])
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    return np.stack([p[..., 0] + c * lx - s * ly, p[..., 1] + s * lx + c * ly], axis=-1)


def jacobian(pose, lever_arm) -> np.ndarray:
    """``∂h/∂(x, y, ψ)``, shape (2, 3), for world-frame perturbations (module docstring)."""
    th = float(pose[2])
    lx, ly = float(lever_arm[0]), float(lever_arm[1])
    c, s = math.cos(th), math.sin(th)
    return np.array([[1.0, 0.0, -s * lx - c * ly], [0.0, 1.0, c * lx - s * ly]])


def body_jacobian(pose, lever_arm) -> np.ndarray:
    """``∂h/∂δ`` for GTSAM's right perturbation ``x · Exp(δ)``, shape (2, 3)."""
    th = float(pose[2])
    lx, ly = float(lever_arm[0]), float(lever_arm[1])
    c, s = math.cos(th), math.sin(th)
    R = np.array([[c, -s], [s, c]])
    return np.column_stack([R, R @ np.array([-ly, lx])])


def mahalanobis2(residual, covariance) -> float:
    """``rᵀ S⁻¹ r`` of a 2-vector residual and its 2x2 covariance."""
    r = np.asarray(residual, dtype=np.float64)
    return float(r @ np.linalg.solve(np.asarray(covariance, dtype=np.float64), r))


def robust_weight(distance: float, kernel: str = "cauchy", width: float = 2.0) -> float:
    """Weight in ``(0, 1]`` of the information of a fix at Mahalanobis distance ``distance``."""
    d = abs(float(distance))
    if kernel == "huber":
        return 1.0 if d <= width else width / d
    if kernel == "cauchy":
        return 1.0 / (1.0 + (d / width) ** 2)
    if kernel == "none":
        return 1.0
    raise ValueError(f"unknown robust kernel {kernel!r}")


@dataclass
class GpsCheck:
    """One fix checked against a predicted pose.

    Attributes
    ----------
    residual : ndarray (2,)
        ``z - h(x)`` [m].
    H : ndarray (2, 3)
        ``∂h/∂(x, y, ψ)``.
    R : ndarray (2, 2)
        Noise covariance to use: the fix's covariance divided by the robust weight.
    d2 : float
        Squared Mahalanobis distance of the innovation.
    weight : float
        Robust weight (0 when rejected).
    accepted : bool
        Whether the fix passed the gate.
    """

    residual: np.ndarray
    H: np.ndarray
    R: np.ndarray
    d2: float
    weight: float
    accepted: bool


@dataclass
class GpsModel:
    """The GPS measurement model with its lever arm, noise settings and counters.

    Parameters
    ----------
    lever_arm : array_like
        Antenna in the body frame [m] (``x, y`` used).
    noise : GpsNoise, optional

    Attributes
    ----------
    n_used, n_rejected : int
        Fixes accepted and rejected by the gate so far (:meth:`check` counts them).
    rejected_t : list of float
        Times of the rejected fixes, when :meth:`check` was given them.
    """

    lever_arm: np.ndarray
    noise: GpsNoise = field(default_factory=GpsNoise)
    n_used: int = 0
    n_rejected: int = 0
    rejected_t: list = field(default_factory=list)

    def __post_init__(self) -> None:
        self.lever_arm = np.asarray(self.lever_arm, dtype=np.float64).ravel()[:2]

    def covariance(self, fix_covariance) -> np.ndarray:
        """The fix's 2x2 covariance with the ``min_sigma`` floor applied."""
        cov = 0.5 * (np.asarray(fix_covariance, dtype=np.float64) + np.asarray(fix_covariance).T)
        return cov + np.eye(2) * max(0.0, self.noise.min_sigma ** 2 - float(np.min(np.linalg.eigvalsh(cov))))

    def check(self, pose, fix_enu, fix_covariance, pose_covariance=None, t: float | None = None) -> GpsCheck:
        """Residual, Jacobian, gate and robust weight of one fix (module docstring).

        Parameters
        ----------
        pose : array_like (3,)
            Predicted ``(x, y, ψ)`` in ENU.
        fix_enu : array_like (2,) or (3,)
            The fix's east, north [m].
        fix_covariance : array_like (2, 2)
            Its horizontal covariance [m²].
        pose_covariance : array_like (3, 3), optional
            Covariance of ``pose``; the gate then uses ``S = H P Hᵀ + Σ``.
        t : float, optional
            Time of the fix, kept in :attr:`rejected_t` when it is rejected.
        """
        z = np.asarray(fix_enu, dtype=np.float64).ravel()[:2]
        r = z - predict(pose, self.lever_arm)
        H = jacobian(pose, self.lever_arm)
        R = self.covariance(fix_covariance)
        S = R if pose_covariance is None else H @ np.asarray(pose_covariance, dtype=np.float64) @ H.T + R
        d2 = mahalanobis2(r, S)
        if not d2 <= self.noise.gate_chi2:
            self.n_rejected += 1
            if t is not None:
                self.rejected_t.append(float(t))
            log.debug("GPS fix%s rejected: Mahalanobis distance %.1f", "" if t is None else f" at {t:.2f} s",
                      math.sqrt(d2) if math.isfinite(d2) else d2)
            return GpsCheck(r, H, R, d2, 0.0, False)
        self.n_used += 1
        w = robust_weight(math.sqrt(d2), self.noise.kernel, self.noise.kernel_width)
        return GpsCheck(r, H, R / w, d2, w, True)


# ---------------------------------------------------------------------- GTSAM
def gps_factor(key: int, fix_enu, lever_arm, noise_model):
    """A ``gtsam.CustomFactor`` on one ``Pose2``: error ``h(x) - z`` with the body-frame Jacobian.

    GTSAM's own ``GPSFactor`` constrains a ``Pose3`` (and ``PoseTranslationPrior2D`` a ``Pose2``
    without lever arm), so the planar antenna model with a lever arm is written here once.

    Parameters
    ----------
    key : int
        Key of the ``Pose2`` variable.
    fix_enu : array_like (2,)
        The fix's east, north [m].
    lever_arm : array_like (2,)
        Antenna in the body frame [m].
    noise_model : gtsam.noiseModel.Base
        For example the fix's covariance inside its robust kernel (:meth:`GraphBuilder.robust_noise
        <fusion_vo.backends.graph.GraphBuilder.robust_noise>`).
    """
    import gtsam

    z = np.asarray(fix_enu, dtype=np.float64).ravel()[:2].copy()
    lever = np.asarray(lever_arm, dtype=np.float64).ravel()[:2].copy()

    def error(this, values, jacobians):
        pose = values.atPose2(this.keys()[0])
        p = np.array([pose.x(), pose.y(), pose.theta()])
        if jacobians is not None:
            jacobians[0] = body_jacobian(p, lever)
        return predict(p, lever) - z

    return gtsam.CustomFactor(noise_model, [key], error)


# ---------------------------------------------------------------------- fixes in time
def fixes_in(gps: GpsData, t0: float, t1: float) -> np.ndarray:
    """Indices of the fixes with ``t0 <= t <= t1``."""
    return np.flatnonzero((gps.t >= t0) & (gps.t <= t1))


def interpolate_poses(t: np.ndarray, xyyaw: np.ndarray, t_query: np.ndarray) -> np.ndarray:
    """Poses at ``t_query`` by linear interpolation (yaw unwrapped); ``t_query`` must lie in ``t``'s span."""
    yaw = np.unwrap(xyyaw[:, 2])
    return np.column_stack([np.interp(t_query, t, xyyaw[:, 0]), np.interp(t_query, t, xyyaw[:, 1]),
                            se2.wrap_angle(np.interp(t_query, t, yaw))])


def robust_fit_rigid_2d(source: np.ndarray, target: np.ndarray, weights: np.ndarray, width: float = 3.0,
                        iterations: int = 10) -> tuple[float, np.ndarray, np.ndarray]:
    """Rigid planar fit ``target ≈ R(yaw) source + t`` that ignores outliers such as multipath jumps.

    Iteratively reweighted least squares (:func:`fusion_vo.geometry.se2.fit_rigid_2d` each step) with a
    Cauchy weight ``1 / (1 + (r / (width · s))²)`` of each residual distance ``r``, where ``s`` is the
    robust scale ``1.4826 · median(r)`` of the current residuals.

    Returns
    -------
    yaw, translation, final robust weights (N,)
    """
    w = np.asarray(weights, dtype=np.float64)
    rw = np.ones(len(w))
    yaw, offset = se2.fit_rigid_2d(source, target, w)
    for _ in range(iterations):
        c, s = math.cos(yaw), math.sin(yaw)
        r = np.linalg.norm(source @ np.array([[c, s], [-s, c]]) + offset - target, axis=1)
        scale = 1.4826 * float(np.median(r))
        if scale <= 1e-12:
            break
        rw = 1.0 / (1.0 + (r / (width * scale)) ** 2)
        yaw, offset = se2.fit_rigid_2d(source, target, w * rw)
    return yaw, offset, rw


@dataclass
class Alignment:
    """Planar rigid transform from a track's frame to ENU, fitted to fixes.

    ``yaw`` [rad] and ``offset`` (2,) [m] map a position ``p`` of the track to ``R(yaw) p + offset``;
    ``rms`` [m] is the residual of the fitted fixes that the robust fit kept (weight ≥ 0.5), ``n`` the
    number of fixes, ``n_outliers`` those it discarded, ``yaw_sigma`` [rad] the standard deviation of
    ``yaw`` from the fixes' noise alone: ``1 / sqrt(Σ |a_i - ā|² / σ_i²)``.
    """

    yaw: float
    offset: np.ndarray
    rms: float
    n: int
    yaw_sigma: float = float("nan")
    n_outliers: int = 0

    def apply(self, xyyaw: np.ndarray) -> np.ndarray:
        """Poses of the track expressed in ENU."""
        p = np.asarray(xyyaw, dtype=np.float64).reshape(-1, 3)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.column_stack([c * p[:, 0] - s * p[:, 1] + self.offset[0],
                                s * p[:, 0] + c * p[:, 1] + self.offset[1],
                                se2.wrap_angle(p[:, 2] + self.yaw)])


def align_to_fixes(t: np.ndarray, xyyaw: np.ndarray, gps: GpsData, t_end: float | None = None,
                   min_spread: float = 3.0) -> Alignment | None:
    """Heading and offset of ENU relative to a dead-reckoned track, from the fixes up to ``t_end``.

    The antenna positions of the track at the fix times, ``a_i = h(x(t_i))``, are fitted to the fixes
    ``z_i`` by the weighted least-squares rigid transform ``z ≈ R(yaw) a + o`` (weights: inverse trace of
    each fix's covariance), robust to multipath jumps (:func:`robust_fit_rigid_2d`). The heading is only observable once the antenna has moved: ``None`` is
    returned while the fitted positions spread less than ``min_spread`` standard deviations of the
    fixes' noise (a robot standing still, or too few fixes).

    Parameters
    ----------
    t, xyyaw : ndarray
        The track's times (N,) and poses (N, 3) in its own frame.
    gps : GpsData
        Fixes (ENU at the datum) and the lever arm.
    t_end : float, optional
        Use only fixes up to this time (default: every fix within the track).
    min_spread : float
        Required RMS spread of the antenna positions, in units of the fixes' standard deviation.
    """
    t = np.asarray(t, dtype=np.float64)
    hi = t[-1] if t_end is None else min(float(t_end), t[-1])
    idx = fixes_in(gps, t[0], hi)
    if len(idx) < 3:
        return None
    a = predict(interpolate_poses(t, np.asarray(xyyaw, dtype=np.float64), gps.t[idx]), gps.lever_arm)
    z = gps.enu[idx, :2]
    var = np.trace(gps.covariance[idx], axis1=1, axis2=2) / 2.0
    w = 1.0 / np.maximum(var, 1e-12)
    yaw, offset, kept = robust_fit_rigid_2d(a, z, w)
    sigma = math.sqrt(float(np.median(var)))
    moment = np.sum((a - np.average(a, axis=0, weights=w)) ** 2, axis=1)
    spread = math.sqrt(float(np.average(moment, weights=w)))
    if spread < min_spread * sigma:
        return None
    c, s = math.cos(yaw), math.sin(yaw)
    fitted = a @ np.array([[c, s], [-s, c]]) + offset
    inlier = kept >= 0.5
    rms = math.sqrt(float(np.mean(np.sum((fitted[inlier] - z[inlier]) ** 2, axis=1))))
    return Alignment(float(yaw), offset, rms, len(idx), 1.0 / math.sqrt(float(np.sum(w * moment))),
                     int(np.count_nonzero(~inlier)))


@dataclass
class Scatter:
    """The fixes' scatter about a GPS-free track, measured by :func:`scatter_floor`.

    ``sigma`` [m] is the estimated standard deviation per axis of the fixes (the track's own drift
    removed), ``stated`` [m] the receiver's (median of the fixes' covariances), ``drift`` [m] the track's
    own standard deviation per axis over the fitted fixes (from its covariance), ``n`` the fixes, and
    ``significant`` whether the residuals are too large for ``stated`` and ``drift`` at the 99.9 % level.
    """

    sigma: float
    stated: float
    drift: float
    n: int
    significant: bool


def scatter_floor(fit: Alignment, stated_sigma: float, drift_var: float = 0.0) -> Scatter:
    """Whether the fixes scatter significantly more than their stated sigma, and by how much.

    The rigid fit of :func:`align_to_fixes` leaves the residuals ``r_i`` of the ``m`` fixes it kept. With
    fixes of the stated standard deviation ``σ`` per axis and a track whose own error has variance
    ``δ²`` per axis, ``Σ |r_i|² / (σ² + δ²)`` is χ² with ``2m - 3`` degrees of freedom (the fit spends
    three: heading and offset). The fixes are declared noisier than stated when it exceeds the χ² 99.9 %
    point (a 1-in-1000 false alarm for an honest receiver); the estimate is then
    ``σ̂² = Σ |r_i|² / (2m - 3) - δ²``: the residual variance with the track's own drift taken out, so
    that a drifting track can only lower, not raise, the figure (``δ²`` from the GPS-free filter's own
    covariance is an upper bound on the drift a rigid fit leaves).

    The fixes' errors are treated as independent; a receiver whose errors are correlated over tens of
    seconds (multipath, atmosphere) is the case this exists for: its stated sigma describes its
    short-term jitter, while the estimate measures its error about the track over the fitted span.
    """
    from scipy.stats import chi2

    m = max(int(fit.n - fit.n_outliers), 0)
    dof = 2 * m - 3
    sum_sq = m * fit.rms ** 2
    var0 = stated_sigma ** 2 + max(drift_var, 0.0)
    if dof < 1 or not var0 > 0 or not math.isfinite(sum_sq):
        return Scatter(stated_sigma, stated_sigma, math.sqrt(max(drift_var, 0.0)), m, False)
    sigma = math.sqrt(max(sum_sq / dof - max(drift_var, 0.0), 0.0))
    significant = bool(sum_sq / var0 > chi2.ppf(0.999, dof))
    return Scatter(sigma, stated_sigma, math.sqrt(max(drift_var, 0.0)), m, significant)


def gps_noise(iv, config) -> GpsNoise:
    """``config.gps`` with the run's measured scatter as ``min_sigma`` when :func:`scatter_floor` raised it
    (``Intervals.gps_min_sigma``, set by the world-frame alignment): both backends fuse with the same sigma."""
    floor = getattr(iv, "gps_min_sigma", None)
    if floor is None or not floor > config.gps.min_sigma:
        return config.gps
    import dataclasses

    return dataclasses.replace(config.gps, min_sigma=float(floor))


# ---------------------------------------------------------------------- registration
def node_times(gps: GpsData, nodes: np.ndarray, config) -> np.ndarray:
    """Every fix time is a node, unless one is within :data:`GPS_SNAP` of it."""
    if not len(gps.t):
        return nodes
    fixes = np.asarray(gps.t, dtype=np.float64)
    fixes = fixes[np.isfinite(fixes)]
    j = np.clip(np.searchsorted(nodes, fixes), 1, len(nodes) - 1)
    near = np.minimum(np.abs(nodes[j] - fixes), np.abs(nodes[j - 1] - fixes)) <= GPS_SNAP
    return np.unique(np.concatenate([nodes, fixes[~near]]))


def add_intervals(iv, streams, config, counts) -> None:
    """Each fix at the node of its time (:data:`GPS_SNAP`); fixes outside the node span are counted missing
    (``Intervals.gps_ok, gps_enu, gps_cov, gps``)."""

    gps = streams.gps
    count = counts.setdefault("gps", SensorCount())
    T = iv.t
    iv.gps = gps
    iv.gps_ok = np.zeros(len(T), bool)
    iv.gps_enu = np.zeros((len(T), 2))
    iv.gps_cov = np.tile(np.eye(2), (len(T), 1, 1))
    idx, n_re, n_dup = time_order(gps.t)
    count.reordered += n_re
    count.gated += n_dup
    for i in idx:
        k = int(np.clip(np.searchsorted(T, gps.t[i]), 0, len(T) - 1))
        k = min((j for j in (k - 1, k) if 0 <= j < len(T)), key=lambda j: abs(T[j] - gps.t[i]))
        if abs(T[k] - gps.t[i]) > GPS_SNAP or iv.gps_ok[k]:
            count.missing += 1
            continue
        iv.gps_ok[k] = True
        iv.gps_enu[k] = gps.enu[i, :2]
        iv.gps_cov[k] = gps.covariance[i]


def ekf_update(ekf, model: GpsModel, fix, covariance, t: float | None = None) -> bool:
    """Apply one fix to the EKF through ``model`` (gate, robust weight); returns whether it was accepted."""
    chk = model.check(ekf.x[:3], fix, covariance, ekf.P[:3, :3], t)
    ekf.record("gps", chk.d2, 2, "rejected" if not chk.accepted else "down-weighted" if chk.weight < 1.0 else "used")
    if not chk.accepted:
        return False
    ekf.update_pose(chk.residual, chk.H, chk.R)
    return True


def ekf_reacquire(ekf, model: GpsModel, fix, covariance, t: float | None = None) -> bool:
    """Apply a fix that failed the gate after widening the EKF's position covariance by the squared
    innovation (``FusionConfig.gps_reacquire``); the rejection just counted becomes a use."""
    model.n_rejected -= 1
    if model.rejected_t:
        model.rejected_t.pop()
    r = np.asarray(fix, dtype=np.float64)[:2] - predict(ekf.x[:3], model.lever_arm)
    ekf.P[:2, :2] += np.eye(2) * float(r @ r)
    return ekf_update(ekf, model, fix, covariance, t)


class GpsReacquire:
    """Fixes through the gate, and after ``after`` seconds of rejections one applied anyway
    (``FusionConfig.gps_reacquire``); ``times`` holds when that happened."""

    def __init__(self, after: float):
        self.after = after
        self.last_ok: float | None = None
        self.times: list[float] = []

    def __call__(self, ekf, model: GpsModel, iv, k: int) -> bool:
        t = float(iv.t[k])
        if ekf_update(ekf, model, iv.gps_enu[k], iv.gps_cov[k], t):
            self.last_ok = t
            return True
        if self.last_ok is None:
            self.last_ok = t
        if t - self.last_ok < self.after:
            return False
        self.times.append(t)
        self.last_ok = t
        return ekf_reacquire(ekf, model, iv.gps_enu[k], iv.gps_cov[k], t)

    def due(self, t: float, accepted: bool) -> bool:
        """For a backend that gates itself: whether a rejected fix at ``t`` is to be applied anyway."""
        if accepted or self.last_ok is None:
            self.last_ok = t
            return False
        if t - self.last_ok < self.after:
            return False
        self.times.append(t)
        self.last_ok = t
        return True


def gps_note(backend: str, model: GpsModel, iv, reacquired: list | None = None) -> str:
    """``"<backend>: gps N fixes used, M rejected by the gate (at ...)"`` plus the fixes skipped on reading."""
    text = f"{backend}: gps {model.n_used} fixes used, {model.n_rejected} rejected by the gate"
    if model.rejected_t:
        when = sorted(model.rejected_t)
        text += f" (t={when[0]:.2f} to {when[-1]:.2f}, {when[0] - iv.t[0]:.2f} to {when[-1] - iv.t[0]:.2f} s in)"
    if reacquired:
        text += (f"; {len(reacquired)} times a fix was applied anyway after rejections for gps_reacquire seconds "
                 f"(the estimate re-acquired the fixes; first at {reacquired[0] - iv.t[0]:.2f} s in)")
    skipped = sum((iv.gps.skipped or {}).values()) if iv.gps is not None else 0
    if skipped:
        text += f"; {skipped} skipped on reading ({', '.join(f'{n} {k}' for k, n in iv.gps.skipped.items() if n)})"
    return text


class EkfFixes:
    """The fixes applied by the EKF at their nodes after each step's update (gate, robust weight, re-acquisition
    after ``gps_reacquire`` seconds of rejections); an outage of :data:`OUTAGE_NOTE_S` or more is reported with the
    drift the first fix after it measures."""

    def __init__(self, iv, config):
        self.iv = iv
        self.model = GpsModel(iv.gps.lever_arm, gps_noise(iv, config))
        self.reacquire = GpsReacquire(config.gps_reacquire)
        self.notes: list[str] = []
        self.last_fix: float | None = None

    def node(self, ekf, k: int) -> None:
        iv = self.iv
        if not iv.gps_ok[k]:
            return
        if k > 0 and self.last_fix is not None and iv.t[k] - self.last_fix >= OUTAGE_NOTE_S:
            # the first fix after an outage measures how far the estimate drifted without GPS
            drift = float(np.linalg.norm(iv.gps_enu[k] - predict(ekf.x[:3], self.model.lever_arm)))
            sigma = float(np.sqrt(np.trace(ekf.P[:2, :2])))
            self.notes.append(f"ekf: gps outage from {self.last_fix - iv.t[0]:.2f} to {iv.t[k] - iv.t[0]:.2f} s in: "
                              f"drift {drift:.3f} m at its end (position sigma {sigma:.3f} m)")
        self.last_fix = float(iv.t[k])
        self.reacquire(ekf, self.model, iv, k)

    def finish(self, ekf, result) -> None:

        ekf.counts["gps"] = SensorCount(used=self.model.n_used, gated=self.model.n_rejected)
        result.notes.append(gps_note("ekf", self.model, self.iv, self.reacquire.times))
        result.notes.extend(self.notes)


def _ekf_run(iv, config):
    return EkfFixes(iv, config) if iv.gps_ok is not None and iv.gps is not None else None


class GraphFixes:
    """The fixes in the factor graph: each gated against its node's predicted pose (and the online marginal
    covariance of the previous node when iSAM2 runs) and added as :func:`gps_factor` inside the robust kernel."""

    def __init__(self, builder):
        self.builder = builder
        self.iv = builder.iv
        self.model = GpsModel(self.iv.gps.lever_arm, gps_noise(self.iv, builder.config))
        self.reacquire = GpsReacquire(builder.config.gps_reacquire)

    def add(self, nf, n: int, pose_cov) -> None:
        """Gate the fix at node ``n`` against its predicted pose; add the robust factor when accepted."""

        iv, model, builder = self.iv, self.model, self.builder
        g = int(builder.grid[n])
        if not iv.gps_ok[g]:
            return
        key = builder.key(n)
        guess = nf.values[key]
        chk = model.check(np.array([guess.x(), guess.y(), guess.theta()]), iv.gps_enu[g], iv.gps_cov[g], pose_cov,
                          float(iv.t[g]))
        if not chk.accepted and self.reacquire.due(float(iv.t[g]), False):
            model.n_rejected -= 1  # applied after all: a use, not a rejection
            model.rejected_t.pop()
            model.n_used += 1
        elif chk.accepted:
            self.reacquire.due(float(iv.t[g]), True)
        else:
            builder.counts.setdefault("gps", SensorCount()).gated += 1
            return
        noise = builder.robust_noise(model.covariance(iv.gps_cov[g]), model.noise.kernel, model.noise.kernel_width)
        nf.factors.append(gps_factor(key, iv.gps_enu[g], model.lever_arm, noise))
        nf.sensors.append("gps")

    def finish(self, result) -> None:
        result.notes.append(gps_note("gtsam", self.model, self.iv, self.reacquire.times))


def _graph_run(builder):
    iv = builder.iv
    return GraphFixes(builder) if iv.gps_ok is not None and iv.gps is not None else None


def _keyframes(iv):
    """A fix's node is always a keyframe."""
    return np.flatnonzero(iv.gps_ok) if iv.gps_ok is not None else None


def _live_sample(fix) -> tuple:
    """A live :class:`~fusion_vo.measurements.GpsFix`: its time and itself."""
    return fix.t, fix


def _live_values(fix) -> list:
    """The numbers of a fix that must be finite."""
    return [fix.enu, fix.covariance]


def _live_take(fusion, fix) -> None:
    """Streaming: a fix is applied at its node (:meth:`~fusion_vo.backends.streaming.StreamingFusion.take_fix`)."""
    fusion.take_fix(fix)


register(Sensor(
    name="gps", where="gps0/ (usable fixes)", field="gps", folder="gps0", read=lambda recording: recording.gps(),
    has=lambda recording: recording.has_gps() if hasattr(recording, "has_gps") else False,
    default=False, config=("gps", GpsNoise), absolute_position=True, node_times=node_times, intervals=Step(50, add_intervals),
    ekf_run=_ekf_run, graph_run=_graph_run, graph_keyframes=_keyframes,
    live=Live(_live_sample, values=_live_values, take=_live_take),
))
