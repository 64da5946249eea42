"""Wheel radii and wheel base of a differential drive.

Both methods use the wheels' rotation angles ``φ_l, φ_r`` between encoder samples (ticks unwrapped and
glitches gated by :func:`fusion_vo.sensors.wheel.ticks_to_travel`) and the arc model of
:func:`fusion_vo.sensors.wheel.arc_increment` with travels ``d = r φ``.

Ground truth
------------
The ground-truth pose is interpolated at every ``step``-th encoder sample; each interval's increment
``(dx, dy, dyaw)`` in the body frame at its start is compared with the arc model of ``(r_l, r_r, b)``::

    min  Σ_k |arc(r_l φ_l,k, r_r φ_r,k, b) - Δ_k|²       (dyaw weighted by b0 / 2, in metres)

solved by non-linear least squares from the nominal values; the covariance is ``σ² (JᵀJ)^-1``. A
recording that both drives straight and turns (a square) makes all three observable.

UMBmark
-------
Borenstein and Feng (1996) drive a square clockwise and counter-clockwise and measure how far the
robot's true end position is from the one its odometry computed. The two dominant systematic errors
are the ratio of the wheel diameters ``Ed = D_r / D_l`` (a straight leg curves) and the wheel-base
scale ``Eb = b / b0`` (every turn is off). Their effects on the end position have the opposite sign in
the two directions, which separates them. Here the end-position errors of both runs (from the
recording's ground truth) are matched exactly, not to first order: the recorded ticks are dead-reckoned
again with::

    r_l = 2 r̄ / (Ed + 1),   r_r = 2 r̄ Ed / (Ed + 1),   b = Eb b0

and ``(Ed, Eb)`` solved by least squares on the four end-position residuals (Gauss-Newton from
``Ed = Eb = 1``). As in UMBmark the mean radius ``r̄`` keeps its nominal value: a square driven both
ways does not observe the overall scale (measure a straight drive for that).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from fusion_vo.errors import InputError
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData, WheelConfig, WheelData
from fusion_vo.sensors.wheel import arc_increment, ticks_to_travel

logger = logging.getLogger(__name__)


@dataclass
class WheelCalibration:
    """Calibrated wheel geometry.

    Attributes
    ----------
    config : WheelConfig
        Ticks per revolution, radii and base.
    std : dict
        Standard deviations of ``wheel_radius_left``, ``wheel_radius_right``, ``wheel_base`` [m] (and
        ``Ed``, ``Eb`` for UMBmark).
    method : str
    nominal : WheelConfig
        The configuration the recording came with.
    details : dict
        Method-specific figures (``rms``, ``Ed``, ``Eb``, end-position errors ...).
    """

    config: WheelConfig
    std: dict[str, float]
    method: str
    nominal: WheelConfig
    details: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The ``wheel0/sensor.yaml`` mapping."""
        c = self.config
        tpr = int(c.ticks_per_revolution) if float(c.ticks_per_revolution).is_integer() else float(c.ticks_per_revolution)
        return {"ticks_per_revolution": tpr, "wheel_radius_left": float(c.wheel_radius_left),
                "wheel_radius_right": float(c.wheel_radius_right), "wheel_base": float(c.wheel_base)}

    def summary(self) -> str:
        c, n, s = self.config, self.nominal, self.std
        lines = [f"Wheel calibration ({self.method}):"]
        for key, label in (("wheel_radius_left", "Left radius "), ("wheel_radius_right", "Right radius"),
                           ("wheel_base", "Wheel base  ")):
            v, v0 = getattr(c, key), getattr(n, key)
            lines.append(f"  {label}  {v:.6f} +- {s[key]:.6f} m   (nominal {v0:.6f}, {100 * (v / v0 - 1):+.3f} %)")
        d = self.details
        if "Ed" in d:
            lines.append(f"  Ed = D_r/D_l = {d['Ed']:.6f} +- {s['Ed']:.6f},  Eb = b/b0 = {d['Eb']:.6f} +- {s['Eb']:.6f}")
            for run in ("cw", "ccw"):
                e = d[f"end_error_{run}"]
                lines.append(f"  End-position error {run:>3} (true - odometry): x = {e[0]:+.4f} m, y = {e[1]:+.4f} m")
        if "rms" in d:
            lines.append(f"  Residual RMS: {d['rms'] * 1000:.3f} mm over {d['n_intervals']} intervals")
        return "\n".join(lines)


def wheel_angles(wheel: WheelData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times and cumulative rotation angles ``φ_l, φ_r`` [rad] of both wheels."""
    if len(wheel) < 2:
        raise InputError("the wheel stream has fewer than two samples")
    travel = ticks_to_travel(wheel)
    cfg = wheel.config
    return travel.t, travel.left / cfg.wheel_radius_left, travel.right / cfg.wheel_radius_right


def _pose_at(gt: PoseData, t: np.ndarray) -> np.ndarray:
    if len(gt) < 2:
        raise InputError("the ground truth has fewer than two poses")
    yaw = np.unwrap(gt.xyyaw[:, 2])
    return np.column_stack([np.interp(t, gt.t, gt.xyyaw[:, 0]), np.interp(t, gt.t, gt.xyyaw[:, 1]),
                            np.interp(t, gt.t, yaw)])


def _relative(p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """Poses ``p1`` in the frames of ``p0`` (N x 3 each), yaw not wrapped."""
    d = p1[:, :2] - p0[:, :2]
    c, s = np.cos(p0[:, 2]), np.sin(p0[:, 2])
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], p1[:, 2] - p0[:, 2]])


def _covariance(res) -> np.ndarray:
    J = res.jac
    dof = max(1, len(res.fun) - J.shape[1])
    return float(res.fun @ res.fun) / dof * np.linalg.pinv(J.T @ J)


def wheels_from_groundtruth(wheel: WheelData, gt: PoseData, step: int = 5) -> WheelCalibration:
    """Radii and base by least squares of encoder travel against ground-truth increments."""
    t, phl, phr = wheel_angles(wheel)
    inside = (t >= gt.t[0]) & (t <= gt.t[-1])
    idx = np.flatnonzero(inside)[::max(1, int(step))]
    if len(idx) < 10:
        raise InputError("fewer than 10 encoder intervals overlap the ground truth")
    pose = _pose_at(gt, t[idx])
    target = _relative(pose[:-1], pose[1:])
    dphl, dphr = np.diff(phl[idx]), np.diff(phr[idx])
    moving = (np.abs(dphl) + np.abs(dphr)) > 0
    target, dphl, dphr = target[moving], dphl[moving], dphr[moving]
    if len(target) < 10 or np.ptp(dphr - dphl) == 0:
        raise InputError("the recording must both drive and turn to calibrate the wheels")
    nom = wheel.config
    w = nom.wheel_base / 2

    def residuals(x):
        inc = arc_increment(x[0] * dphl, x[1] * dphr, x[2])
        r = inc - target
        r[:, 2] *= w
        return r.ravel()

    x0 = np.array([nom.wheel_radius_left, nom.wheel_radius_right, nom.wheel_base])
    res = least_squares(residuals, x0, x_scale=x0, method="lm", xtol=1e-14, ftol=1e-14)
    cov = _covariance(res)
    names = ("wheel_radius_left", "wheel_radius_right", "wheel_base")
    cfg = WheelConfig(nom.ticks_per_revolution, *map(float, res.x))
    rms = math.sqrt(float(res.fun @ res.fun) / len(res.fun))
    logger.info("wheel calibration on %d intervals, RMS %.3g m", len(target), rms)
    return WheelCalibration(cfg, dict(zip(names, map(float, np.sqrt(np.diag(cov))))), "ground truth", nom,
                            {"rms": rms, "n_intervals": len(target)})


def _end_pose(phl: np.ndarray, phr: np.ndarray, r_l: float, r_r: float, b: float) -> np.ndarray:
    inc = arc_increment(np.diff(phl) * r_l, np.diff(phr) * r_r, b)
    return se2.integrate(inc)[-1]


#: the least true turn [deg] of each UMBmark run, in its direction (a square turns 360 deg)
UMBMARK_MIN_TURN_DEG = 270.0


def umbmark(cw: tuple[WheelData, PoseData], ccw: tuple[WheelData, PoseData],
            sources: tuple = (None, None)) -> WheelCalibration:
    """UMBmark: ``Ed`` and ``Eb`` from the end-position errors of a clockwise and a counter-clockwise square.

    Parameters
    ----------
    cw, ccw : the encoder data and ground truth of each run (the ground truth gives the true end position
        relative to the start).
    sources : the recordings of the two runs, named by the errors.

    Raises
    ------
    InputError
        If a run does not turn at least :data:`UMBMARK_MIN_TURN_DEG` in its direction by its ground truth
        (a straight drive, or the two squares swapped): the fit has nothing to separate ``Ed`` and ``Eb``
        with and its numbers are meaningless.
    """
    runs = []
    for (name, (wheel, gt)), source in zip((("cw", cw), ("ccw", ccw)), sources):
        t, phl, phr = wheel_angles(wheel)
        inside = (t >= gt.t[0]) & (t <= gt.t[-1])
        t, phl, phr = t[inside], phl[inside], phr[inside]
        if len(t) < 2:
            raise InputError(f"the {name} run's encoder samples do not overlap its ground truth", source)
        p = _pose_at(gt, t[[0, -1]])
        turn = math.degrees(p[1, 2] - p[0, 2]) * (-1 if name == "cw" else 1)
        if turn < UMBMARK_MIN_TURN_DEG:
            way = "clockwise" if name == "cw" else "counter-clockwise"
            raise InputError(f"not a {way} square: the {name} run turns {round(turn)} deg {way} by its ground truth "
                             f"(UMBmark needs about 360; at least {UMBMARK_MIN_TURN_DEG:.0f})", source)
        runs.append((name, phl, phr, _relative(p[:1], p[1:])[0]))
    nom = cw[0].config
    r_mean = 0.5 * (nom.wheel_radius_left + nom.wheel_radius_right)
    b0 = nom.wheel_base

    def geometry(x):
        ed, eb = x
        return 2 * r_mean / (ed + 1), 2 * r_mean * ed / (ed + 1), eb * b0

    def residuals(x):
        out = []
        for _, phl, phr, true_end in runs:
            end = _end_pose(phl, phr, *geometry(x))
            out.append(end[:2] - true_end[:2])
        return np.concatenate(out)

    errors = {f"end_error_{name}": (true_end[:2] - _end_pose(phl, phr, nom.wheel_radius_left, nom.wheel_radius_right, b0)[:2])
              for name, phl, phr, true_end in runs}
    res = least_squares(residuals, np.ones(2), method="lm", xtol=1e-14, ftol=1e-14)
    ed, eb = map(float, res.x)
    # four residuals, two unknowns: the scatter left over is the (small) unmodelled error
    cov = _covariance(res)
    r_l, r_r, b = geometry(res.x)
    # propagate to the radii and base
    G = np.array([[-2 * r_mean / (ed + 1) ** 2, 0.0], [2 * r_mean / (ed + 1) ** 2, 0.0], [0.0, b0]])
    cov_g = G @ cov @ G.T
    std = dict(zip(("wheel_radius_left", "wheel_radius_right", "wheel_base"), map(float, np.sqrt(np.diag(cov_g)))))
    std.update(Ed=float(math.sqrt(cov[0, 0])), Eb=float(math.sqrt(cov[1, 1])))
    cfg = WheelConfig(nom.ticks_per_revolution, float(r_l), float(r_r), float(b))
    return WheelCalibration(cfg, std, "UMBmark", nom, {"Ed": ed, "Eb": eb, **errors})
