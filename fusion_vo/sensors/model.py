"""What every sensor's measurement model provides, and the pieces the models share.

A measurement model predicts a sensor's reading ``h`` from the states it touches and gives the
Jacobian of that prediction with respect to each of them. Both backends use the same model:

* the EKF (:mod:`fusion_vo.backends.ekf`) reads the arguments from its state vector, puts each
  Jacobian into the columns of that state and gates the innovation ``z - h`` (:class:`Gate`);
* the factor graph (:mod:`fusion_vo.backends.graph`) reads them from its variables and builds, from the
  same prediction and Jacobians, GTSAM's linear factors (relinearised at every iteration of its
  solver) or a :class:`gtsam.CustomFactor` (:func:`fusion_vo.backends.factors.custom_factor`).

Arguments
---------
A model names its arguments; the backends know how to supply each name:

``motion``             (3,) the body motion over the measurement's interval, ``(d_x, d_y, d_ψ)``: the
                       relative pose ``X_i⁻¹ X_j`` in the graph; the EKF's twist state ``(v_x, v_y, ω)``,
                       which is the interval's motion per unit time (its interval models are evaluated
                       per unit time: readings and noise divided by the interval, ``dt = 1``);
``heading``            (1,) the pose's heading ``ψ`` at the measurement's time;
``pose``               (3,) the pose ``(x, y, ψ)`` at the measurement's time (world frame);
a state's name         (1,) a scalar state a sensor declares (:class:`fusion_vo.sensors.registry.State`), e.g.
                       ``gyro_bias`` ``b_g`` [rad/s] and ``ahrs_offset`` ``o_ψ`` [rad] (:mod:`~fusion_vo.sensors.imu`),
                       ``visual_scale`` ``k_v = h_configured / h_true`` (:mod:`~fusion_vo.sensors.visual`),
                       ``wheel_scale`` ``k_r = r_configured / r_true`` and ``wheel_base_factor``
                       ``k_b = b_true / b_configured`` (:mod:`~fusion_vo.sensors.wheel`).

Every function is vectorised over leading axes (one row per measurement), so the EKF evaluates a
model on one interval and the graph on all of its factors of one kind at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fusion_vo.geometry.se2 import wrap_angle

#: sizes of the arguments every backend supplies; every other argument is a sensor's scalar state
ARGUMENT_SIZES = {"motion": 3, "heading": 1, "pose": 3}


@dataclass(frozen=True)
class MeasurementModel:
    """Base of the sensor models: a name, the arguments, the measurement's size and its angle rows.

    ``linear`` says the prediction is linear in the arguments (the graph then linearises it once:
    a pose's heading is additive in GTSAM's Pose2 chart, so a factor on headings and scalars is exact
    as a linear factor);
    ``angle_rows`` are absolute angles (wrapped to [-π, π) wherever they are compared);
    ``turn_rows`` are heading changes over the measurement's interval, wrapped where the interval's
    motion is an increment (the graph) and not where it is a rate (the EKF evaluates per unit time);
    ``increment`` says an interval's reading is a relative pose ``(d_x, d_y, d_ψ)`` (the EKF reads its
    logarithm, the interval's exact twist, :mod:`fusion_vo.backends.ekf_adapter`);
    ``uses_dt``: the model's parameter ``dt`` is the length of the reading's interval (the graph passes it;
    the EKF, per unit time, leaves it at 1);
    ``guess_rank``: ``(translation, heading)`` ranks of the model's :meth:`guess` of an interval's motion
    (lower is trusted first; None: it gives none), the factor graph's initial value of a new pose.
    Subclasses implement :meth:`evaluate`; :meth:`identity`, :meth:`guess` and :meth:`state_prior` are optional.
    """

    name: str = ""
    args: tuple = ()
    dim: int = 0
    angle_rows: tuple = ()
    turn_rows: tuple = ()
    linear: bool = False
    increment: bool = False
    uses_dt: bool = False
    guess_rank: tuple = (None, None)

    def evaluate(self, **args) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Prediction ``h`` (..., dim) and Jacobians ``{arg: (..., dim, size)}`` at the given arguments."""
        raise NotImplementedError

    def identity(self, fixed: dict) -> bool:
        """Whether ``h`` is its ``motion`` or ``heading`` argument itself when the arguments ``fixed`` hold these
        values (a scale at 1, an offset at 0): the factor graph then uses GTSAM's own factor of the poses."""
        return False

    def guess(self, z, estimate: dict, dt: float) -> tuple[np.ndarray | None, float | None]:
        """An interval's translation ``(d_x, d_y)`` and heading change implied by reading ``z`` at the running
        ``estimate`` of the states (name -> value): the factor graph's initial guess (:attr:`guess_rank`)."""
        return None, None

    def state_prior(self, z, variance: float, params: dict) -> tuple[str, float, float] | None:
        """A node reading of one scalar state solved for it: ``(state, value, sigma)`` (first order), which the
        factor graph uses as a linear prior on that state; None when the model is not one."""
        return None

    def residual(self, z, **args) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """``h(args) - z`` over an interval (angle and turn rows wrapped), and the Jacobians of ``h``."""
        h, jac = self.evaluate(**args)
        r = h - np.asarray(z, dtype=np.float64)
        for row in self.angle_rows + self.turn_rows:
            r[..., row] = wrap_angle(r[..., row])
        return r, jac


def _first(v) -> float:
    """The value of a one-element argument (array or number)."""
    return float(v) if isinstance(v, (int, float)) else float(v[0])


def scaled_motion(motion, k_xy, k_yaw) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(k_xy d_x, k_xy d_y, k_yaw d_ψ)`` and its Jacobians with respect to the motion, ``k_xy`` and ``k_yaw``.

    The prediction of a sensor that sees the body motion up to a scale of its translation (camera: the
    height; wheels: the radius) and of its turn (wheels: the wheel base).
    """
    d = np.asarray(motion, dtype=np.float64)
    if d.ndim == 1:  # one measurement (the EKF, an incremental solver): without array overhead
        dx, dy, dpsi = float(d[0]), float(d[1]), float(d[2])
        kx, ky = _first(k_xy), _first(k_yaw)
        return (np.array([kx * dx, kx * dy, ky * dpsi]), np.array([[kx, 0.0, 0.0], [0.0, kx, 0.0], [0.0, 0.0, ky]]),
                np.array([[dx], [dy], [0.0]]), np.array([[0.0], [0.0], [dpsi]]))
    kx = np.asarray(k_xy, dtype=np.float64)[..., 0]
    ky = np.asarray(k_yaw, dtype=np.float64)[..., 0]
    shape = d.shape[:-1]
    h = np.empty(shape + (3,))
    h[..., 0] = kx * d[..., 0]
    h[..., 1] = kx * d[..., 1]
    h[..., 2] = ky * d[..., 2]
    j_d = np.zeros(shape + (3, 3))
    j_d[..., 0, 0] = j_d[..., 1, 1] = kx
    j_d[..., 2, 2] = ky
    j_kx = np.zeros(shape + (3, 1))
    j_kx[..., 0, 0], j_kx[..., 1, 0] = d[..., 0], d[..., 1]
    j_ky = np.zeros(shape + (3, 1))
    j_ky[..., 2, 0] = d[..., 2]
    return h, j_d, j_kx, j_ky


# --------------------------------------------------------------------------- gate
@dataclass
class Gate:
    """Chi-square gate of an innovation, with the EKF's bounded influence beyond it.

    A measurement whose squared Mahalanobis distance ``d² = yᵀ S⁻¹ y`` exceeds the chi-square quantile of
    ``probability`` (for its number of rows) is down-weighted so that it sits on the gate (the bounded
    influence of the graph's robust kernel), and beyond ``reject_factor`` times the quantile rejected.

    Parameters
    ----------
    probability : float
        Gate probability (1: no gate).
    reject_factor : float
        Beyond this many times the quantile a measurement is rejected outright.
    """

    probability: float = 0.999
    reject_factor: float = 25.0
    _thresholds: dict = field(default_factory=dict, repr=False)

    def threshold(self, dim: int) -> float:
        """The chi-square quantile of ``probability`` with ``dim`` degrees of freedom."""
        t = self._thresholds.get(dim)
        if t is None:
            from scipy.stats import chi2  # on first use: a camera-only run does not load scipy.stats

            t = float(chi2.ppf(self.probability, dim)) if self.probability < 1 else math.inf
            self._thresholds[dim] = t
        return t

    def inflation(self, d2: float, dim: int) -> float | None:
        """``None``: reject; ``1``: use as is; ``f > 1``: use with its innovation covariance scaled by ``f``."""
        threshold = self.threshold(dim)
        if not math.isfinite(d2) or d2 > self.reject_factor * threshold:
            return None
        return d2 / threshold if d2 > threshold else 1.0
