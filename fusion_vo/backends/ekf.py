"""Extended Kalman filter over the node grid, with a Rauch–Tung–Striebel smoother.

State::

    x = [p_x, p_y, ψ,  v_x, v_y, ω,  s_1 ... s_m]

pose of B in W, the body twist ``u = (v_x, v_y, ω)`` *averaged over the interval that ends at the node*,
and the run's scalar states ``s_i`` (:func:`fusion_vo.backends.states.run_states`, in the registry's order),
each declared by its sensor (:class:`fusion_vo.sensors.registry.State`): the visual scale
``k_v = h_configured / h_true``, the wheel-base factor ``k_b = b_true / b_configured``, the wheels' distance
scale ``k_r = r_configured / r_true`` (their common radius error), the gyro bias ``b_g``, the offset ``o_ψ`` of
the AHRS heading from the true heading, and any a registered sensor adds (a compass offset, a second camera's
scale). Each starts at its prior ``N(initial, σ²)``; one the run does not estimate (``k_v`` and ``k_b`` with
self-calibration off or unobservable) is frozen: variance 10⁻¹², no random walk.

Camera and wheels measure only the ratio ``k_v / k_r``; their common scale is set by the priors on
``k_v`` (``height_sigma`` of ``cam0/sensor.yaml``) and ``k_r`` (``radius_sigma`` of
``wheel0/sensor.yaml``) or by a range finder, so neither sensor owns the scale by construction.

Motion model (constant twist, interval ``Δt = T_{k+1} - T_k``)::

    u_{k+1} = u_k + w_u,                   w_u ~ N(0, diag(σ_a², σ_lat², σ_α²) Δt)
    pose_{k+1} = pose_k ⊕ exp(u_{k+1} Δt)  (SE(2) exponential: exact circular arc)
    s_{k+1} = s_k + w_s,                   w_s ~ N(0, q_s² Δt)   (each state's random walk q_s)

``F = ∂f/∂x`` and ``Q = G diag(...) Gᵀ`` with ``G = ∂f/∂w`` (the twist noise also moves the pose).

Measurements over an interval (all sensors are integrated onto the same interval by
:mod:`fusion_vo.backends.timeline`, so each one constrains the twist of *that* interval). Each is the
sensor's measurement model of :mod:`fusion_vo.sensors` (:meth:`PlanarEkf.block`: the prediction and
Jacobians of the model, whose arguments are read from the state, :attr:`PlanarEkf.columns`), the same one
the factor graph uses; the interval models are evaluated per unit time, on the twist::

    visual   z = log(Δ_vis)/Δt          h = (k_v v_x, k_v v_y, ω)       R = Σ_vis / Δt²
    wheel    z = (d, 0, θ)/Δt (arc)     h = (k_r v_x, k_r v_y, k_b ω)   R = wheel noise model / Δt²
    gyro     z = Θ/Δt (mean rate)       h = ω + b_g                     R = σ_g² / Δt
    AHRS     z = ψ_AHRS (at the node)   h = ψ + o_ψ                     R = σ_ψ²
    range    z = h_range (at the node)  h = h_c / k_v                   R = σ_r²
    still    z = 0 (wheels at rest)     h = ω                           R = σ_still²
    GPS      z = fix (east, north)      h = p + R(ψ) l (antenna)        R = fix covariance / robust weight

The wheels' heading error on a skid-steered base is correlated over a turn; its variance per
interval is inflated by its correlation time (``WheelNoise.yaw_scale_time``, see
:mod:`fusion_vo.sensors.wheel`) and taken proportional to the gyro's turn rather than the
wheels' own reading (which would bias ``k_b`` low), so a long turn does not outweigh the gyro and
drag its bias. An interval in which the wheels report rest is a zero-velocity update of the yaw rate
(``still``); with the gyro's ``ω + b_g`` it measures the bias directly.

Because the twist state *is* the interval's mean twist and the pose at the node is a function of the
previous pose and that twist, an interval measurement is an exact function of the current state — the
same information a delayed-state (cloned pose) relative update would carry, without augmenting the
state. High-rate wheel and gyro samples are therefore integrated over each camera interval before the
update; for a twist that is constant within the interval this is statistically equivalent to applying
every sample. A visual increment spanning ``n`` intervals (after dropped frames) is applied as its mean
twist to each of them with covariance ``n R`` (the same total information).

The prediction linearises the position at the previous interval's twist; after each update the position
also takes the second-order remainder of the exponential at the updated twist (an iterated EKF's second
pass for the mean, :meth:`PlanarEkf._relinearise_pose`), and the RTS smoother uses the prediction
linearised there. A camera fused alone then gives exactly its own track.

The AHRS heading is not trusted as an absolute truth: an AHRS's heading comes from its
magnetometer, which the robot's own motors, steel in the floor and nearby vehicles bend by degrees
to tens of degrees, slowly, as the robot moves. Its offset ``o_ψ`` (zero at the start, where the
AHRS north is aligned) is therefore a random walk of ``ImuNoise.ahrs_offset_walk`` [rad/√s]: the
AHRS corrects the heading's slow drift on time scales where the gyro's bias walk exceeds the
offset's walk, while a heading that strays from the gyro's integral moves ``o_ψ`` instead of the
pose. A sudden jump (a magnetic disturbance) fails the gate and is counted.

Each sensor's block is gated before the update by its squared Mahalanobis distance (its normalised
innovation squared, NIS) ``d² = yᵀ (H P Hᵀ + R)⁻¹ y`` against the chi-square quantile of ``gate_probability``
(:class:`~fusion_vo.sensors.model.Gate`); rejections are counted. A batch run records every block's
``(t, sensor, d², rows, used / down-weighted / rejected)`` (:class:`~fusion_vo.backends.result.Innovations`,
``FusionResult.innovations["ekf"]``; a row the consistency monitor left out, with its vague variance, is not
counted among the rows).
The accepted blocks are stacked into one update with filterpy's
:class:`~filterpy.kalman.ExtendedKalmanFilter` (Joseph-form covariance update).

Each sensor contributes :class:`~fusion_vo.sensors.readings.Readings` (its measurement model, the
readings per interval, their noise); :mod:`fusion_vo.backends.ekf_adapter` turns any of them into the
blocks of a step (:func:`interval_readings`, :meth:`PlanarEkf.step`). Absolute readings (a GPS fix) are
applied at their own node after each step's update (:mod:`fusion_vo.backends.fixes`) with the same model's
residual, Jacobian, Mahalanobis gate ``S = H P Hᵀ + Σ`` and robust weight, through
:meth:`PlanarEkf.update_pose`; rejected fixes (a multipath jump) change nothing and are counted. The
state then lives in ENU at the datum and starts at the pose :mod:`fusion_vo.backends.world` aligned to
the fixes, with that alignment's uncertainty.

When a sensor's readings state their frames' own errors (``Readings.frame_cov``: the camera's with
``visual_frame_error > 0`` or stated frame covariances, :mod:`fusion_vo.sensors.visual`), the state ends with its
errors at the previous and the current frame (:data:`FRAME_ERRORS` each): each prediction moves the current one
into the previous one's place (a linear transition, so the smoother treats them like any state) and
starts the new frame's at zero with its covariance, and a visual increment over one interval is
``h + (e_this - e_prev)/Δt`` with the rest of its noise.

The smoother runs backwards over the stored priors and posteriors::

    C_k = P_k Fᵀ_{k+1} (P⁻_{k+1})⁻¹
    x̂_k = x_k + C_k (x̂_{k+1} - x⁻_{k+1}),   P̂_k = P_k + C_k (P̂_{k+1} - P⁻_{k+1}) C_kᵀ
"""

from __future__ import annotations

import logging
import time

import numpy as np

from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.ekf_adapter import EkfReadings
from fusion_vo.backends.fixes import EkfFixes
from fusion_vo.backends.result import FusionResult, InnovationLog, SensorCount
from fusion_vo.backends.states import calibration, live_context, run_states
from fusion_vo.backends.timeline import Intervals, scale_priors, sensor_readings
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData
from fusion_vo.sensors.model import Gate, MeasurementModel

logger = logging.getLogger(__name__)

PX, PY, YAW, VX, VY, W = range(6)
#: the pose and the twist; the run's scalar states follow
DIM = 6
#: size of a camera frame error (x, y, ψ of a visual increment)
FRAME_ERRORS = 3
#: state columns of the measurement-model arguments every run has (:mod:`fusion_vo.sensors.model`); the
#: interval models are evaluated per unit time, on the twist state. Each scalar state is the column of its name.
STATE_COLUMNS = {"motion": slice(VX, W + 1), "heading": slice(YAW, YAW + 1), "pose": slice(PX, YAW + 1)}
_FROZEN_VAR = 1e-12
_REJECT_FACTOR = 25.0  # a block beyond this many times the gate is rejected outright; between, down-weighted
#: a measurement row with at least this variance carries no information (a component the consistency monitor
#: dropped gets 1e8, :mod:`fusion_vo.sensors.wheel`): it is not counted in the block's recorded rows
_FREE_VAR = 1e6


def filter_libraries():
    """filterpy's ``ExtendedKalmanFilter`` and scipy's ``chi2`` (about 0.6 s to load): loaded on first use, not
    with the module, since a run without fusion (wheel dead reckoning only) needs neither; a live stream loads
    them when it is built (:class:`~fusion_vo.backends.streaming.StreamingFusion`), so that its first samples
    do not wait for them."""
    from filterpy.kalman import ExtendedKalmanFilter
    from scipy.stats import chi2

    return ExtendedKalmanFilter, chi2


class PlanarEkf:
    """The filter: :meth:`predict` to the next node, then :meth:`update` with that interval's measurements.

    Parameters
    ----------
    config : FusionConfig
    states : tuple of registry.State, optional
        The run's scalar states (:func:`fusion_vo.backends.states.run_states`), appended to the pose and twist
        with their priors and random walks, frozen where not estimated. Default: those of a run that fuses
        the camera, the wheels and the IMU with its AHRS (:func:`default_states`).
    frame_errors : bool
        The state ends with the frame errors (:data:`FRAME_ERRORS` each, of the previous and of the current node)
        of the one sensor whose readings state them (:attr:`Readings.frame_cov
        <fusion_vo.sensors.readings.Readings.frame_cov>`: the camera's, :mod:`fusion_vo.sensors.visual`); their
        covariances come with :meth:`predict`. Default False.
    """

    def __init__(self, config: FusionConfig, initial_pose=None, initial_sigma=None, states=None,
                 frame_errors: bool = False):
        ExtendedKalmanFilter, chi2 = filter_libraries()
        self.config = config
        self.states = tuple(default_states(config) if states is None else states)
        self.dim = dim = DIM + len(self.states)
        #: state columns of each measurement-model argument: the pose's, the twist's and each state's
        self.columns = dict(STATE_COLUMNS)
        for i, state in enumerate(self.states):
            self.columns[state.name] = slice(DIM + i, DIM + i + 1)
        #: the frame errors: (columns of the previous node's, of this node's), or None
        self.frame_errors: tuple[slice, slice] | None = None
        if frame_errors:
            self.frame_errors = (slice(dim, dim + FRAME_ERRORS), slice(dim + FRAME_ERRORS, dim + 2 * FRAME_ERRORS))
            self.dim = dim = dim + 2 * FRAME_ERRORS
        self._frame_cov = np.eye(FRAME_ERRORS) * _FROZEN_VAR
        self.kf = ExtendedKalmanFilter(dim_x=dim, dim_z=1)
        x = np.zeros(dim)
        x[:3] = config.initial_pose if initial_pose is None else initial_pose
        var = np.zeros(dim)
        #: each state's random-walk variance per second (0 for a frozen one)
        self._walk = np.zeros(len(self.states))
        for i, state in enumerate(self.states):
            x[DIM + i] = state.initial
            var[DIM + i] = state.sigma**2 if state.estimated else _FROZEN_VAR
            self._walk[i] = state.random_walk**2 if state.estimated else 0.0
        self.kf.x = x.reshape(dim, 1)
        var[:3] = 1e-10 if initial_sigma is None else np.square(initial_sigma)
        var[VX] = var[VY] = config.initial_velocity_sigma**2
        var[W] = 0.5**2
        if self.frame_errors is not None:  # (no frame measured yet: their covariance comes with the first)
            var[self.frame_errors[0]] = var[self.frame_errors[1]] = _FROZEN_VAR
        self.kf.P = np.diag(var)
        self.gate = Gate(config.gate_probability, _REJECT_FACTOR)
        self.counts: dict[str, SensorCount] = {}
        #: the last prediction's linearisation (pose, twist, ∂position/∂twist, Δt, remainder applied), for
        #: :meth:`_relinearise_pose`; None before the first prediction
        self.linearisation: tuple | None = None
        #: every gated block's NIS and outcome (:meth:`record`), when a caller sets it (batch runs do;
        #: streaming use leaves it None, so that nothing grows with the hours it runs)
        self.innovations: InnovationLog | None = None
        #: time of the node the next blocks are applied at, for :attr:`innovations` [s]
        self.time = float("nan")

    # ------------------------------------------------------------------ state access
    @property
    def x(self) -> np.ndarray:
        return self.kf.x.ravel()

    @property
    def P(self) -> np.ndarray:
        return self.kf.P

    # ------------------------------------------------------------------ prediction
    def reset_state(self, name: str, value: float, sigma: float) -> None:
        """Start the scalar state ``name`` (one of :attr:`states`) again at ``value`` with standard
        deviation ``sigma`` and no correlation with the others (what was learned of it is forgotten)."""
        i = self.columns[name].start
        self.kf.x[i, 0] = value
        self.kf.P[i, :] = 0.0
        self.kf.P[:, i] = 0.0
        self.kf.P[i, i] = sigma**2

    def predict(self, dt: float, frame_cov: np.ndarray | None = None) -> np.ndarray:
        """Constant-twist prediction over ``dt``; returns the transition Jacobian ``F``.

        With frame errors in the state, this node's becomes the previous node's and the new node's error
        starts at zero with covariance ``frame_cov`` (3, 3) (:func:`fusion_vo.sensors.visual.frame_error_cov`;
        ``None``: the last one given).
        """
        cfg = self.config
        x = self.x
        vx, vy, w = x[VX], x[VY], x[W]
        th = w * dt
        a, b = se2.sinc_terms(th)
        da, db = se2.sinc_derivatives(th)
        ax = dt * (a * vx - b * vy)
        ay = dt * (b * vx + a * vy)
        c, s = np.cos(x[YAW]), np.sin(x[YAW])
        d_a = np.array([[a * dt, -b * dt, dt * dt * (da * vx - db * vy)],
                        [b * dt, a * dt, dt * dt * (db * vx + da * vy)]])
        rot = np.array([[c, -s], [s, c]])
        d_pos_v = rot @ d_a
        F = np.eye(self.dim)
        F[PX, YAW] = -s * ax - c * ay
        F[PY, YAW] = c * ax - s * ay
        F[0:2, VX:W + 1] = d_pos_v
        F[YAW, W] = dt
        G = np.zeros((self.dim, 3))
        G[0:2] = d_pos_v
        G[YAW, 2] = dt
        G[VX:W + 1] = np.eye(3)
        qv = np.array([cfg.ekf.accel_sigma, cfg.ekf.lateral_accel_sigma, cfg.ekf.yaw_accel_sigma]) ** 2 * dt
        Q = (G * qv) @ G.T
        for i, walk in enumerate(self._walk):
            Q[DIM + i, DIM + i] += walk * dt
        x_new = x.copy()
        x_new[PX] += c * ax - s * ay
        x_new[PY] += s * ax + c * ay
        x_new[YAW] = se2.wrap_angle(x[YAW] + th)
        if self.frame_errors is not None:  # e_prev <- e_this, e_this <- a new frame's error
            e0, e1 = self.frame_errors
            if frame_cov is not None:
                self._frame_cov = np.asarray(frame_cov, dtype=np.float64)
            F[e0, e0] = 0.0
            F[e0, e1] = np.eye(FRAME_ERRORS)
            F[e1, e1] = 0.0
            Q[e1, e1] += self._frame_cov
            x_new[e0] = x[e1]
            x_new[e1] = 0.0
        self.kf.x = x_new.reshape(self.dim, 1)
        self.kf.P = F @ self.kf.P @ F.T + Q
        self.kf.x_prior = self.kf.x.copy()
        self.kf.P_prior = self.kf.P.copy()
        # what the pose's second-order correction needs after the update (:meth:`_relinearise_pose`)
        self.linearisation = (x[:3].copy(), x[VX:W + 1].copy(), d_pos_v.copy(), float(dt), np.zeros(2))
        return F

    def _relinearise_pose(self) -> None:
        """Move the position to where the updated twist actually takes the robot.

        The prediction linearised ``p_{k+1} = p_k ⊕ exp(u Δt)`` at the predicted twist ``u_k``, so an update
        that changes the twist by ``δu`` (the robot accelerated) moves the position by ``F_u δu`` only.
        The remainder ``p_k ⊕ exp((u_k + δu) Δt) - p_k ⊕ exp(u_k Δt) - F_u δu``, second order in ``δu``
        (a few micrometres when the turn rate changes by 0.1 rad/s within a 50 ms interval at 60 mm/s), is
        added to the mean, as an iterated EKF's second pass would; the covariance is left as linearised.
        Without it, a camera fused alone ends micrometres off its own track at every change of turn rate.
        """
        lin = self.linearisation
        if lin is None:
            return
        pose, u0, F_u, dt, applied = lin
        u1 = self.kf.x[VX:W + 1, 0]
        du = u1 - u0
        if not np.any(du):
            return

        def moved(u):
            th = u[2] * dt
            a, b = se2.sinc_terms(th)
            c, s = np.cos(pose[2]), np.sin(pose[2])
            ax, ay = dt * (a * u[0] - b * u[1]), dt * (b * u[0] + a * u[1])
            return np.array([c * ax - s * ay, s * ax + c * ay])

        remainder = moved(u1) - moved(u0) - F_u @ du
        self.kf.x[PX:PY + 1, 0] += remainder - applied
        applied[:] = remainder

    def prior_correction(self) -> np.ndarray:
        """The remainder :meth:`_relinearise_pose` added in this step, as a state vector: the prediction
        linearised at the updated twist differs from the stored ``x_prior`` by it, and the RTS smoother must
        use that prediction, or it would smooth the correction back out as if it were an innovation."""
        out = np.zeros(self.dim)
        lin = self.linearisation
        if lin is not None:
            out[PX:PY + 1] = lin[4]
        return out

    # ------------------------------------------------------------------ one node
    def begin(self, readings: EkfReadings) -> bool:
        """Update with the readings at the first node of their grid (an AHRS heading), if any: whether there were
        any."""
        blocks = readings.start(self)
        if blocks:
            self.update(blocks)
        return bool(blocks)

    def step(self, readings: EkfReadings, k: int, inspect=None) -> np.ndarray:
        """Interval ``k`` of the readings' grid: :meth:`predict` across it (with its frame error), then
        :meth:`update` with its readings and those at its end node. ``inspect(blocks)`` sees the blocks at the
        prediction, before the update. Returns the prediction's ``F``; the prediction stays in ``kf.x_prior``,
        ``kf.P_prior``.

        The one filter step of every pass: the batch filter (:func:`run_ekf`), the streaming engine (one
        interval at a time) and the NIS of :mod:`fusion_vo.evaluation.consistency`.
        """
        F = self.predict(float(readings.t[k + 1] - readings.t[k]), readings.frame_cov(k))
        self.time = float(readings.t[k + 1])
        blocks = [b for _, b in readings.blocks(self, k)]
        if inspect is not None:
            inspect(blocks)
        self.update(blocks)
        return F

    # ------------------------------------------------------------------ measurement blocks
    def block(self, model: MeasurementModel, z, R, rows: tuple | None = None, name: str | None = None, **params):
        """``(sensor, z, h, H, R, angle_row)`` of one measurement through ``model`` at the current state.

        The model's arguments are read from the state (:attr:`columns`), except those given in ``params`` (held
        at those values, with the model's other parameters), and its Jacobians become the columns of ``H``;
        ``rows`` selects the model's rows that ``R`` covers (``z`` holds all of them); ``name`` (default the
        model's) is what the block is counted under.
        """
        x = self.kf.x[:, 0]
        columns = self.columns
        h, jac = model.evaluate(**{n: x[columns[n]] for n in model.args if n not in params}, **params)
        H = np.zeros((model.dim, self.dim))
        for arg, J in jac.items():
            if arg not in params:
                H[:, columns[arg]] = J
        angle = model.angle_rows[0] if model.angle_rows else None
        name = model.name if name is None else name
        if rows is not None:
            rows = list(rows)
            angle = rows.index(angle) if angle in rows else None
            z = np.asarray(z, dtype=np.float64).reshape(-1)[rows]
            return name, z, np.asarray(h)[rows], H[rows], np.asarray(R, dtype=np.float64), angle
        if model.dim == 1:
            return name, np.array([float(np.asarray(z).reshape(-1)[0])]), h, H, \
                np.array([[float(np.asarray(R).reshape(-1)[0])]]), angle
        return name, np.asarray(z, dtype=np.float64), h, H, np.asarray(R, dtype=np.float64), angle

    # ------------------------------------------------------------------ a measurement of the pose alone
    def update_pose(self, y, H_pose, R) -> None:
        """Update with the innovation ``y`` (m,) of a measurement whose Jacobian ``H_pose`` (m, 3) is on the pose
        ``(x, y, ψ)`` alone and whose noise is ``R`` (a sensor applied at a node on its own, e.g. a GPS fix)."""
        y = np.asarray(y, dtype=np.float64).reshape(-1, 1)
        H = np.zeros((len(y), self.dim))
        H[:, :3] = H_pose
        self.kf.update(y, HJacobian=lambda _x: H, Hx=lambda _x: np.zeros_like(y), R=R)
        self.kf.x[YAW, 0] = se2.wrap_angle(self.kf.x[YAW, 0])
        self._relinearise_pose()

    def record(self, sensor: str, d2: float, dof: int, status: str) -> None:
        """Add a block's NIS and outcome at :attr:`time` to :attr:`innovations` (nothing when it is None)."""
        if self.innovations is not None:
            self.innovations.add(self.time, sensor, d2, dof, status)

    # ------------------------------------------------------------------ update
    def update(self, blocks) -> None:
        """Gate each ``(sensor, z, h, H, R, angle_row)`` block, then apply the accepted ones together."""
        if not blocks:
            return
        P = self.kf.P
        keep = []
        for sensor, z, h, H, R, angle in blocks:
            y = z - h
            if angle is not None:
                y[angle] = se2.wrap_angle(y[angle])
            S = H @ P @ H.T + R
            d2 = float(y @ np.linalg.solve(S, y))
            count = self.counts.setdefault(sensor, SensorCount())
            factor = self.gate.inflation(d2, len(y))
            rows = max(1, int(np.count_nonzero(np.diag(R) < _FREE_VAR))) if self.innovations is not None else 0
            if factor is None:
                count.gated += 1
                self.record(sensor, d2, rows, "rejected")
                continue
            count.used += 1
            self.record(sensor, d2, rows, "down-weighted" if factor > 1.0 else "used")
            if factor > 1.0:
                # outside the gate but not absurd: down-weighted so that it sits on the gate (the
                # bounded influence of the graph's robust kernel) rather than dropped -- a robot that
                # brakes harder than the constant-twist model expects must not coast on
                count.gated += 1
                R = R * factor + H @ P @ H.T * (factor - 1.0)
            keep.append((y, H, R))
        if not keep:
            return
        y = np.concatenate([k[0] for k in keep]).reshape(-1, 1)
        H = np.vstack([k[1] for k in keep])
        R = _block_diag([k[2] for k in keep])
        # z is passed as the innovation with h(x) = 0 so angle rows arrive already wrapped
        self.kf.update(y, HJacobian=lambda _x: H, Hx=lambda _x: np.zeros_like(y), R=R)
        self.kf.x[YAW, 0] = se2.wrap_angle(self.kf.x[YAW, 0])
        self._relinearise_pose()


# --------------------------------------------------------------------------- batch run over intervals
def interval_readings(iv: Intervals, config: FusionConfig) -> EkfReadings:
    """The sensors' readings on the filter's grid ``iv.t`` (:class:`~fusion_vo.backends.ekf_adapter.EkfReadings`)."""
    return EkfReadings(sensor_readings(iv, config), iv.t)


def filter_for(iv: Intervals, config: FusionConfig, readings: EkfReadings | None = None) -> PlanarEkf:
    """The filter for the node grid ``iv`` at its first node: the run's states (``iv.states``), the start pose,
    and the frame errors when its readings (``readings``, default :func:`interval_readings`) state them."""
    readings = interval_readings(iv, config) if readings is None else readings
    return PlanarEkf(config, iv.initial_pose, iv.initial_sigma, iv.states, frame_errors=readings.frame_errors)


def default_states(config: FusionConfig) -> tuple:
    """The states of a run fusing the camera, the wheels (encoder ticks) and the IMU with its AHRS, with the
    configured priors: the filter's states when none are given."""
    return run_states(live_context(config, ("camera", "wheel", "imu"), scale_priors(config, None).facts()))


def run_ekf(iv: Intervals, config: FusionConfig) -> FusionResult:
    """Filter (``"ekf"``) and smooth (``"ekf_smoothed"``) over the node grid of ``iv``."""
    start = time.process_time()
    readings = interval_readings(iv, config)
    ekf = filter_for(iv, config, readings)
    ekf.innovations = InnovationLog()
    ekf.time = float(iv.t[0])
    K = iv.n_steps
    n = ekf.dim
    xs = np.zeros((K + 1, n))
    Ps = np.zeros((K + 1, n, n))
    x_prior = np.zeros((K + 1, n))
    P_prior = np.zeros((K + 1, n, n))
    Fs = np.zeros((K + 1, n, n))
    ekf.begin(readings)
    # absolute readings, applied at their nodes on their own after each step's update (GPS fixes)
    at_nodes = [EkfFixes(r, iv.t) for r in readings.absolute]
    for run in at_nodes:
        run.node(ekf, 0)
    xs[0], Ps[0] = ekf.x, ekf.P
    for k in range(K):
        Fs[k + 1] = ekf.step(readings, k)
        x_prior[k + 1], P_prior[k + 1] = ekf.kf.x_prior.ravel(), ekf.kf.P_prior
        for run in at_nodes:
            run.node(ekf, k + 1)
        xs[k + 1], Ps[k + 1] = ekf.x, ekf.P
        x_prior[k + 1] += ekf.prior_correction()
    result = FusionResult()
    for run in at_nodes:
        run.finish(ekf, result)
    result.trajectories["ekf"] = PoseData(iv.t.copy(), xs[:, :3].copy())
    result.covariances["ekf"] = Ps[:, :3, :3].copy()
    counts = _merge_counts(iv.counts, ekf.counts)
    result.counts["ekf"] = counts
    result.calibration["ekf"] = calibration_report(xs[-1], Ps[-1], iv)
    result.innovations["ekf"] = ekf.innovations.table()
    result.timing["ekf"] = time.process_time() - start
    if config.ekf.smoother:
        t1 = time.process_time()
        xsm, Psm = rts_smooth(xs, Ps, x_prior, P_prior, Fs)
        result.trajectories["ekf_smoothed"] = PoseData(iv.t.copy(), xsm[:, :3].copy())
        result.covariances["ekf_smoothed"] = Psm[:, :3, :3].copy()
        result.counts["ekf_smoothed"] = counts
        result.calibration["ekf_smoothed"] = calibration_report(xsm[-1], Psm[-1], iv)
        result.timing["ekf_smoothed"] = time.process_time() - t1
    result.notes.extend(iv.notes)
    return result


def rts_smooth(xs, Ps, x_prior, P_prior, Fs) -> tuple[np.ndarray, np.ndarray]:
    """Rauch–Tung–Striebel pass over filtered ``xs, Ps`` with the stored priors and Jacobians.

    ``x_prior[k], P_prior[k], Fs[k]`` belong to the prediction *into* step ``k`` (index 0 unused).
    """
    n = len(xs)
    xsm = xs.copy()
    Psm = Ps.copy()
    for k in range(n - 2, -1, -1):
        Pp = P_prior[k + 1]
        C = np.linalg.solve(Pp.T, (Ps[k] @ Fs[k + 1].T).T).T
        dx = xsm[k + 1] - x_prior[k + 1]
        dx[YAW] = se2.wrap_angle(dx[YAW])
        xsm[k] = xs[k] + C @ dx
        xsm[k, YAW] = se2.wrap_angle(xsm[k, YAW])
        Psm[k] = Ps[k] + C @ (Psm[k + 1] - Pp) @ C.T
    return xsm, Psm


def calibration_report(x, P, iv: Intervals) -> dict:
    """The calibration report (:func:`fusion_vo.backends.states.calibration`) of the state ``x, P`` with the states
    of the node grid ``iv`` (a batch run's, or a live run's last interval)."""
    values = {st.name: x[DIM + i] for i, st in enumerate(iv.states)}
    sigmas = {st.name: np.sqrt(P[DIM + i, DIM + i]) for i, st in enumerate(iv.states)}
    return calibration(iv, values, sigmas)


def _merge_counts(base: dict, extra: dict) -> dict:
    """Input-stage counts with the filter's gating added (``used`` is what the filter accepted)."""
    out = {k: SensorCount(**v.as_dict()) for k, v in base.items()}
    for sensor, c in extra.items():
        o = out.setdefault(sensor, SensorCount())
        o.used = c.used
        o.gated += c.gated
    return out


def _block_diag(mats) -> np.ndarray:
    n = sum(m.shape[0] for m in mats)
    out = np.zeros((n, n))
    i = 0
    for m in mats:
        k = m.shape[0]
        out[i:i + k, i:i + k] = m
        i += k
    return out
