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
``d`` with width ``k`` (the weight multiplies the information ``Σ⁻¹``; a filter divides ``Σ`` by it;
:func:`fusion_vo.robust.robust_weight`, every robust reading's):

* Huber:  ``w(d) = 1`` for ``d ≤ k``, else ``k / d``
* Cauchy: ``w(d) = k² / (k² + d²) = 1 / (1 + (d / k)²)``

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
from typing import Literal

import numpy as np
from pydantic import Field

from fusion_vo.config.base import Positive, Section, Sigma
from fusion_vo.geometry import se2
from fusion_vo.measurements import GpsData, GpsFix
from fusion_vo.measurements import SensorCount
from fusion_vo.measurements.grid import time_order
from fusion_vo.recording.gps import read_gps
from fusion_vo.robust import ROBUST_KERNELS, robust_weight
from fusion_vo.sensors.model import MeasurementModel
from fusion_vo.sensors.readings import ORDER, Absolute, Readings
from fusion_vo.sensors.registry import Live, Sensor, Step, register

log = logging.getLogger(__name__)

#: a fix closer than this to an existing node [s] is applied at that node
GPS_SNAP = 1e-3
OUTAGE_NOTE_S = 2.0  # [s] a gap between GPS fixes at least this long is reported with its drift

#: 99.9 % point of the chi-square distribution with 2 degrees of freedom
CHI2_2DOF_999 = 13.815510557964274


# ---------------------------------------------------------------------- configuration
class GpsNoise(Section):
    """Gating and robust weighting of GPS fixes (the fixes carry their own covariance)."""

    gate_chi2: Positive = Field(CHI2_2DOF_999, description=(
        "Squared Mahalanobis distance above which a fix is rejected (default: 99.9 % of χ²(2))."))
    kernel: Literal[ROBUST_KERNELS] = Field("cauchy", description="Robust kernel: ``huber``, ``cauchy`` or ``none``.")
    kernel_width: Positive = Field(2.0, description="``k`` of the kernel, in units of the Mahalanobis distance.")
    min_sigma: Sigma = Field(0.01, description=(
        "Floor on the horizontal standard deviation [m] so that an optimistic receiver cannot pin the estimate."))
    estimate_sigma: bool = Field(False, description=(
        "Measure the fixes' scatter about the GPS-free track in the world-frame alignment and, when it is "
        "significantly larger than the receiver's stated sigma, raise ``min_sigma`` to it for the run "
        "(:func:`scatter_floor`; batch backends only, ``StreamingFusion`` keeps the stated sigma). Off by default: "
        "fix errors correlated over tens of seconds fit no sigma for independent fixes, and on a real log the "
        "measured one gave no consistent gain (docs/decisions/0027-gps-not-fused-by-default.md; ``python "
        "benchmarks/gps.py --set fusion.gps.estimate_sigma=true``)."))


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

    def predict(self, pose) -> np.ndarray:
        """The antenna's predicted position at ``pose`` (:func:`predict`)."""
        return predict(pose, self.lever_arm)

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

    Iteratively reweighted least squares (:func:`fusion_vo.geometry.se2.fit_rigid_2d` each step) with the
    Cauchy weight ``1 / (1 + (r / (width · s))²)`` of each residual distance ``r``, where ``s`` is the
    robust scale ``1.4826 · median(r)`` of the current residuals (:func:`fusion_vo.robust.robust_weight` of
    unit width on ``r / (width · s)``).

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
        rw = robust_weight(r / (width * scale), "cauchy", 1.0)
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
    (:attr:`GpsGrid.min_sigma`, set by the world-frame alignment): both backends fuse with the same sigma."""
    grid = gps_grid(iv)
    floor = None if grid is None else grid.min_sigma
    if floor is None or not floor > config.gps.min_sigma:
        return config.gps
    return config.gps.model_copy(update={"min_sigma": float(floor)})


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


@dataclass
class GpsGrid:
    """The fixes on the node grid (``Intervals.sensors["gps"]``, :func:`gps_grid`).

    ``ok, enu, cov`` (K+1,), (K+1, 2), (K+1, 2, 2): the fix at each node that has one (east, north [m] in ENU
    at the datum, and its covariance [m²]); ``fixes``: the :class:`~fusion_vo.measurements.GpsData` (lever arm,
    datum, skip counts); ``min_sigma``: the fixes' sigma floor [m] the world-frame alignment measured when they
    scatter significantly more than the receiver states (``fusion.gps.estimate_sigma``, :func:`scatter_floor`),
    else None (``fusion.gps.min_sigma``).
    """

    ok: np.ndarray
    enu: np.ndarray
    cov: np.ndarray
    fixes: GpsData
    min_sigma: float | None = None


def gps_grid(iv) -> GpsGrid | None:
    """The fixes on the node grid ``iv`` (an :class:`~fusion_vo.backends.timeline.Intervals`); None without GPS."""
    return iv.sensors.get("gps")


def add_intervals(iv, streams, config, counts) -> None:
    """Each fix at the node of its time (:data:`GPS_SNAP`); fixes outside the node span are counted missing
    (:class:`GpsGrid`)."""

    gps = streams.gps
    count = counts.setdefault("gps", SensorCount())
    T = iv.t
    grid = iv.sensors["gps"] = GpsGrid(np.zeros(len(T), bool), np.zeros((len(T), 2)), np.tile(np.eye(2), (len(T), 1, 1)),
                                       gps)
    idx, n_re, n_dup = time_order(gps.t)
    count.reordered += n_re
    count.gated += n_dup
    for i in idx:
        k = int(np.clip(np.searchsorted(T, gps.t[i]), 0, len(T) - 1))
        k = min((j for j in (k - 1, k) if 0 <= j < len(T)), key=lambda j: abs(T[j] - gps.t[i]))
        if abs(T[k] - gps.t[i]) > GPS_SNAP or grid.ok[k]:
            count.missing += 1
            continue
        grid.ok[k] = True
        grid.enu[k] = gps.enu[i, :2]
        grid.cov[k] = gps.covariance[i]


@dataclass(frozen=True)
class AntennaModel(MeasurementModel):
    """A fix as a measurement of the pose (module docstring): ``h(x) = [x, y] + R(ψ) l`` with its world-frame
    Jacobian ``∂h/∂(x, y, ψ)``; argument ``pose``, parameter ``lever_arm`` (the antenna in the body frame [m])."""

    name: str = "gps"
    args: tuple = ("pose",)
    dim: int = 2

    def evaluate(self, pose, lever_arm):
        p = np.asarray(pose, dtype=np.float64)
        lever = np.asarray(lever_arm, dtype=np.float64)
        lx, ly = lever[..., 0], lever[..., 1]  # one lever arm, or one per pose
        c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
        h = np.stack([p[..., 0] + c * lx - s * ly, p[..., 1] + s * lx + c * ly], axis=-1)
        J = np.zeros(p.shape[:-1] + (2, 3))
        J[..., 0, 0] = J[..., 1, 1] = 1.0
        J[..., 0, 2] = -s * lx - c * ly
        J[..., 1, 2] = c * lx - s * ly
        return h, {"pose": J}


ANTENNA = AntennaModel()


def readings(iv, config) -> list[Readings]:
    """The fixes at their nodes, absolute readings of the pose (:class:`~fusion_vo.sensors.readings.Absolute`): each
    gated against the prediction of its node, inside the GPS kernel, with the sigma floor of ``fusion.gps`` (raised
    to the scatter the world-frame alignment measured, :func:`gps_noise`), re-acquired after ``gps_reacquire``
    seconds of rejections."""
    grid = gps_grid(iv)
    if grid is None or not grid.ok.any():
        return []
    n = np.flatnonzero(grid.ok)
    policy = Absolute(gps_noise(iv, config), float(config.gps_reacquire), dict(grid.fixes.skipped or {}))
    return [Readings("gps", ANTENNA, n, n, grid.enu[n], grid.cov[n], params={"lever_arm": grid.fixes.lever_arm[:2]},
                     absolute=policy, order=ORDER["gps"])]


def _keyframes(iv):
    """A fix's node is always a keyframe."""
    grid = gps_grid(iv)
    return np.flatnonzero(grid.ok) if grid is not None else None


def _live_sample(fix) -> tuple:
    """A live :class:`~fusion_vo.measurements.GpsFix`: its time and itself."""
    return fix.t, fix


def _live_values(fix) -> list:
    """The numbers of a fix that must be finite."""
    return [fix.enu, fix.covariance]


def _live_take(fusion, fix) -> None:
    """Streaming: a fix is applied at its node (:meth:`~fusion_vo.backends.streaming.StreamingFusion.take_fix`)."""
    fusion.take_fix(fix)


def _live_samples(data: GpsData) -> list:
    """Recorded usable fixes as live samples (their East-North position and its covariance)."""
    return [(t, GpsFix(t, enu[:2], cov)) for t, enu, cov in zip(data.t, data.enu, data.covariance)]


# --------------------------------------------------------------------------- its stream in a recording
def read_fixes(recording, folder: str = "gps0") -> GpsData:
    """``gps0/`` of a recording: the fixes in local ENU at the datum, unusable fixes skipped and counted
    (:func:`fusion_vo.recording.gps.read_gps`, the one reader of the GPS layout)."""
    recording.data_file(folder, "GPS")
    return read_gps(recording.path / folder)


def has_fixes(recording, folder: str = "gps0") -> bool:
    """Whether ``gps0/`` is present. GPS is fused only when asked for, and scores a run only without ground truth,
    so a ``gps0/`` whose ``data.csv`` is missing (or a broken link, a link loop, a folder) would be left out without
    a word: that is an :class:`~fusion_vo.errors.InputError` naming the file."""
    if not recording.has(folder):
        return False
    recording.data_file(folder, "GPS")
    return True


register(Sensor(
    name="gps", where="gps0/ (usable fixes)", field="gps", folder="gps0", read=read_fixes, has=has_fixes,
    default=False, config=("gps", GpsNoise), absolute_position=True, heading_reference=True, node_times=node_times,
    absolute_distance=True,
    intervals=Step(50, add_intervals),
    readings=readings, graph_keyframes=_keyframes,
    live=Live(_live_sample, values=_live_values, take=_live_take, samples=_live_samples, order=4),
))
