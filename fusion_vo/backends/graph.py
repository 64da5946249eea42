"""Factor-graph backend with GTSAM: batch smoothing, iSAM2 online estimates and a fixed-lag smoother.

Variables
---------
``X_k``  Pose2 of B in W at node (keyframe) ``k`` — the camera frames, or every ``keyframe_every``-th;
``B_c``  gyro bias [rad/s] of segment ``c``;
``S_c``  visual scale ``k_v = h_configured / h_true`` of segment ``c`` (only with self-calibration);
``W_c``  wheel-base factor ``k_b = b_true / b_configured`` of segment ``c`` (only with self-calibration);
``O_c``  offset [rad] of the AHRS heading from the true heading in segment ``c`` (whenever the IMU is used);
a registered sensor's own state (:class:`fusion_vo.sensors.registry.State`) is a variable per segment too
(:meth:`GraphBuilder.state_key`), with its prior on the first and its random walk between segments.

A segment is ``GraphConfig.calibration_interval`` seconds of nodes (default 1 s); node ``k`` uses the
variables of its segment ``c(k)``. Slowly varying quantities are thus variables tied by random walks
between segments rather than single global variables (a variable shared by all factors sits in every
clique of the Bayes tree and each iSAM2 update would re-solve the whole history) or one per camera
frame (long chains of nearly equal variables that every update nudges all the way back).

Factors (``δ = X_i⁻¹ X_j = (d_x, d_y, d_ψ)``, the relative pose). Every sensor's factor is its measurement
model of :mod:`fusion_vo.sensors` (the same prediction, Jacobians and noise the EKF uses), turned into
GTSAM factors by :mod:`fusion_vo.backends.factors`; where GTSAM has a native factor that is the model,
that factor is used. Each sensor's factors are built by its own module, registered with
:mod:`fusion_vo.sensors.registry` (``graph_factors``, ``graph_unary``, ``graph_run``), and
:class:`GraphBuilder` runs the registered steps in their order::

    prior      X_0 = initial pose,  B_0 ~ N(0, σ_b²),  S_0 ~ N(1, σ_s²),  W_0 ~ N(1, σ_w²),  O_0 ~ N(0, σ_ψ²)
    visual     sensors.visual  e = (S_c d_x, S_c d_y, d_ψ) - m        Σ = frontend covariance
               (without self-calibration: BetweenFactorPose2)
    wheel      sensors.wheel   e = (R_c d_x, R_c d_y, W_c d_ψ) - m    Σ = arc model (whole, as the EKF's)
               (a stream component the monitor dropped: e = (R_c d_x, R_c d_y) - m_xy and
               e = W_c d_ψ - m_ψ apart; without self-calibration: BetweenFactorPose2, whole arc covariance)
    gyro       sensors.imu     e = d_ψ + B_c Δt - Θ_ij                σ² = σ_g² Δt      (linear)
    standstill sensors.wheel   e = d_ψ   (wheels at rest)             σ = σ_still Δt   (linear)
    walks      B_c - B_{c-1} ~ N(0, σ_bw² τ),  S_c - S_{c-1} ~ N(0, q_v² τ),  W_c - W_{c-1} ~ N(0, q² τ),
               O_c - O_{c-1} ~ N(0, σ_ow² τ)                                           (τ: segment length)
    heading    sensors.imu     e = ψ_k + O_c - ψ_AHRS                 σ² = σ_ψ²
               (an absolute AHRS, no offset: PriorFactorPose2 on the heading)
    range      sensors.range   S_c ~ N(h_c / z, (h_c σ_r / z²)²)     (the model solved for S_c)
    motion     weak constant-twist BetweenFactorPose2 where no sensor measures an interval's translation
    GPS        sensors.gps     e = X_k.t + R(ψ_k) l - z    Σ = the fix's covariance, Huber/Cauchy

GTSAM's ``BetweenFactorPose2`` expresses the noise in the frame at the end of the measured increment
(its tangent space): it is the model with the covariance rotated by the increment's own turn.

The noise of the wheels' heading is on the measurement ``m_ψ``, so the wheel-base factor must multiply
the estimated heading change (``W d_ψ - m_ψ``); writing it as ``d_ψ - m_ψ / W`` would be linear but
attenuates the estimate like a regression on a noisy regressor.

The wheels' heading error on a skid-steered base is correlated over a turn: its variance per
interval is inflated by its correlation time (``WheelNoise.yaw_scale_time``, see
:mod:`fusion_vo.sensors.wheel`) and scaled by the gyro's turn, so the wheels' turn rate does not outweigh the gyro and drag its bias. A standstill (both wheels at rest) fixes the
heading change to zero, which ties the bias to the gyro's reading at rest.

The AHRS heading has its own slowly wandering offset (the magnetometer's disturbances, see
:mod:`fusion_vo.backends.ekf`): a heading that strays from the gyro's integral moves ``O_c``, not
the poses, and still bounds the heading drift over the long run.

Without self-calibration the visual factor is a plain ``BetweenFactorPose2``. Visual, wheel-translation
and AHRS factors use a robust noise model (Huber or Cauchy, ``GraphConfig.robust``), so a wrong
visual match costs at most linearly and cannot drag the trajectory; the linear heading factors are not
robust, their inputs are gated upstream (gyro spikes, encoder jumps). The kernel's width on a factor's
whitened distance is by default the EKF's chi-square gate for the factor's number of rows
(:func:`kernel_width`): a measurement the filter takes at full weight keeps its full weight here.

GPS
---
Every fix time is a node (:mod:`fusion_vo.backends.timeline`) and a keyframe. A fix is gated
(:meth:`fusion_vo.sensors.gps.GpsModel.check`) against the prediction of its node from the iSAM2
estimate of the previous node and that node's marginal covariance (against the prediction alone when
iSAM2 is off); an accepted fix adds the unary factor of :func:`fusion_vo.sensors.gps.gps_factor` inside
the model's robust kernel, to all three solvers. A rejected fix (a multipath jump) adds nothing and is
counted. With GPS the first pose's prior is the ENU pose aligned to the fixes
(:mod:`fusion_vo.backends.world`) with that alignment's uncertainty instead of the exact initial pose.

Solvers
-------
``gtsam``             batch Levenberg–Marquardt over the whole graph;
``gtsam_online``      iSAM2, one update per node; the estimate of ``X_k`` right after its update is the
                      online (causal) trajectory;
``gtsam_fixed_lag``   ``IncrementalFixedLagSmoother`` with a lag of ``GraphConfig.fixed_lag`` seconds.

The incremental solvers receive the sensor-model factors linearised at the prediction of the newest
pose (:func:`freeze_custom_factors`); iSAM2 linearises them once more at its updated estimate when a
robust weight there differs from the prediction's (:func:`update_reweighted`); the batch solution
relinearises everything at every iteration.

Every covariance enters with all its correlations (:func:`~fusion_vo.backends.factors.covariance_noise`),
however small its entries, as in the EKF.
iSAM2 marginalises the nodes more than :data:`ONLINE_HORIZON` behind the newest (:class:`Retired`), so
that its cost per update does not grow with the drive.

The batch Levenberg–Marquardt loop is written out, with the sensor-model factors evaluated in numpy,
one array operation per sensor. Its linear systems are solved by :mod:`fusion_vo.backends.chain` (the
block-tridiagonal normal equations of the chain-shaped graph, and the marginal covariances from the
same factorisation; see there for why and what it measured), and by :func:`levenberg_marquardt` here,
on GTSAM's linearisation and sparse elimination (``NonlinearFactorGraph.linearize``,
``GaussianFactorGraph.optimize``) with the sensor-model factors handed to GTSAM as ``JacobianFactor`` s,
when the graph is not such a chain. GTSAM's own optimizers need each of them as a :class:`gtsam.CustomFactor` that
calls back into Python, and that is what costs: ``python benchmarks/bench_solvers.py`` (the batch graph
of the 60 s drive of ``benchmarks/bench_fusion.py``, 5039 factors of which 4797 sensor-model factors,
CPU time, 3 interleaved runs on a shared 2-core machine under heavy load) measured this loop at
184–278 ms against 10.0–11.5 s for ``LevenbergMarquardtOptimizer``, 10.3–11.1 s for
``GaussNewtonOptimizer`` and 13.6–15.2 s for ``DoglegOptimizer``, all reaching the same cost 1961.53 in
3 iterations (Dogleg 4). With the earlier hand-written CustomFactors (no generic model layer in the
callback) on a less loaded machine: loop 256–278 ms, LevenbergMarquardtOptimizer 3245–3378 ms,
GaussNewtonOptimizer 3246–3452 ms, DoglegOptimizer 4287–4496 ms; with those factors frozen to linear
ones GaussNewtonOptimizer took 85 ms and the loop 124 ms, so the cost is the callbacks, not GTSAM's
solver. The algorithm is the standard one: try the Gauss–Newton step, and while the cost does not
decrease (or the undamped system is too poorly conditioned to factorise), add ``λ I`` damping
(λ × 10) and retry.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import gtsam
import numpy as np
from threadpoolctl import threadpool_limits

from fusion_vo.backends import chain
from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.damping import damped_gauss_newton
from fusion_vo.backends.ekf import calibration_observable
from fusion_vo.backends.result import FusionResult, SensorCount
from fusion_vo.backends.timeline import Intervals
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData
from fusion_vo.backends.factors import (POSE_LETTERS, ModelFactor, ModelFactors, ValuesMaker, covariance_noise, group,
                                        pose_table)
from fusion_vo.sensors import registry
from fusion_vo.sensors.wheel import arc_covariance, arc_increment, at_rest, gyro_turn
from fusion_vo.sensors.visual import frame_covariances

logger = logging.getLogger(__name__)


def X(k: int) -> int:
    return gtsam.symbol("x", k)


def B(k: int) -> int:
    return gtsam.symbol("b", k)


def O(k: int) -> int:  # noqa: E743 (the symbol's letter)
    return gtsam.symbol("o", k)


def S(k: int) -> int:
    return gtsam.symbol("s", k)


def W(k: int) -> int:
    return gtsam.symbol("w", k)


def R(k: int) -> int:
    return gtsam.symbol("r", k)


#: GTSAM symbol letter of the camera's frame poses (:func:`F`)
FRAME_LETTER = POSE_LETTERS[1]


def F(k: int) -> int:
    """The camera's measured pose at node ``k`` (``X(k)`` with that frame's own error; ``visual_frame_error``,
    :mod:`fusion_vo.sensors.visual`)."""
    return gtsam.symbol(FRAME_LETTER, k)


_NO_INCREMENT = np.zeros(3)
_NO_INCREMENT.flags.writeable = False

#: GTSAM symbol letters of the sensors' own state variables (the built-in ones use x, b, o, s, w, r)
_STATE_LETTERS = "acdefghijklmnpqtuvyz"

#: graph steps of the sensors ordered before this set the initial guess of a node; the builder then adds the
#: motion model where none measured the translation (:meth:`GraphBuilder.node`)
GUESS_ORDER = 40.0


# --------------------------------------------------------------------------- graph construction
@dataclass
class NodeFactors:
    """Factors and initial values that arrive with one node (used by all three solvers)."""

    k: int
    t: float
    factors: list = field(default_factory=list)
    values: dict = field(default_factory=dict)
    sensors: list = field(default_factory=list)
    guess: np.ndarray | None = None


@dataclass(slots=True)
class NodeContext:
    """What a sensor's graph step (:mod:`fusion_vo.sensors.registry`) needs to know about the node it adds to.

    ``n`` is the local node, ``g0, g1`` the interval-grid indices of the previous node and this one (equal at
    a unary step), ``dt`` the time between them, ``segment`` the calibration segment of node ``n`` (the
    variables ``B``, ``S``, ``W``, ``R``, ``O`` of it), ``xi, xj`` the pose keys of the previous node and this
    one, ``estimate`` the running estimates for initial guesses. Steps before :data:`GUESS_ORDER` set
    ``translation`` (2,) and ``heading`` (the interval's motion, for the initial guess) when they measure them;
    ``previous_pose`` is the previous node's current estimate; ``scratch`` passes anything else between one
    sensor's steps (``new_frames``: variables that start at this node's initial pose).
    """

    n: int
    g0: int
    g1: int
    dt: float
    segment: int
    xi: int
    xj: int
    estimate: dict
    previous_pose: gtsam.Pose2 | None = None
    translation: np.ndarray | None = None
    heading: float | None = None
    scratch: dict = field(default_factory=dict)


class GraphBuilder:
    """Turns :class:`~fusion_vo.backends.timeline.Intervals` into per-node factor batches."""

    #: the variables' keys, for the sensors' graph steps (pose, gyro bias, AHRS offset, visual scale, wheel base
    #: and radius factors of a segment; module docstring)
    X, B, O, S, W, R = staticmethod(X), staticmethod(B), staticmethod(O), staticmethod(S), staticmethod(W), staticmethod(R)
    F = staticmethod(F)

    def __init__(self, iv: Intervals, config: FusionConfig, offset: int = 0, t_origin: float | None = None,
                 calibrate: tuple[bool, bool] | None = None, states: tuple | None = None):
        """``offset``, ``t_origin``, ``calibrate`` and ``states`` let a stream be built one interval at a time:
        local node ``n`` is variable ``X(offset + n)``, segments count from ``t_origin``, ``calibrate``
        says which calibration factors are estimated (default: where observable in ``iv``) and ``states``
        which sensors' state variables exist (default: ``iv.states``)."""
        self.iv = iv
        self.states = tuple(iv.states if states is None else states)
        # each state's variables: one letter of GTSAM's symbols per state, besides the built-in ones
        self._state_letter = {st.name: _STATE_LETTERS[i] for i, st in enumerate(self.states)}
        self.config = config
        self.offset = offset
        if calibrate is None:
            calibrate = calibration_observable(iv)
        self.kv_on, self.kb_on = calibrate if config.self_calibration else (False, False)
        # the wheels' distance scale: with the visual scale, only their ratio is measured
        self.kr_on = self.kv_on and self.kb_on
        every = config.graph.keyframe_every
        nodes = np.arange(0, len(iv.t), every)
        if nodes[-1] != len(iv.t) - 1:
            nodes = np.append(nodes, len(iv.t) - 1)
        if every > 1:  # the nodes a sensor needs as keyframes (a GPS fix's)
            for sensor in registry.sensors():
                if sensor.graph_keyframes is not None:
                    keep = sensor.graph_keyframes(iv)
                    if keep is not None and len(keep):
                        nodes = np.union1d(nodes, keep)
        self.grid = nodes  # node index -> interval-grid index
        self.t = iv.t[nodes]
        # bias and calibration variables: one per segment of `calibration_interval` seconds
        origin = self.t[0] if t_origin is None else t_origin
        self.segment = np.floor((self.t - origin) / config.graph.calibration_interval + 1e-9).astype(int)
        # the same as Python lists: indexed once per node, faster than numpy scalars
        self._grid, self._segment, self._times = self.grid.tolist(), self.segment.tolist(), iv.t.tolist()
        self._kernels: dict[int, tuple] = {}  # rows -> ((name, width), GTSAM mEstimator) or None
        # the AHRS offset variables exist with the IMU (an AHRS may report in any interval of a stream)
        self.ahrs_offset_on = iv.uses("gyro") and config.imu.ahrs_offset_walk > 0
        self.counts: dict[str, SensorCount] = {k: SensorCount(**v.as_dict()) for k, v in iv.counts.items()}
        for c in self.counts.values():
            c.used = 0
        self.visual_spans = self._visual_spans()
        #: global nodes whose frame pose ``F`` exists (a stream built one interval at a time shares one set)
        self.frames: set[int] = set()
        if iv.uses("wheel"):  # per-interval arc increments, vectorised
            self._wheel_inc = arc_increment(iv.wheel_dl, iv.wheel_dr, iv.wheel_base)
            self._wheel_inc[:, 0] *= iv.cx
            self._wheel_inc[:, 1] *= iv.cy
            self._turn = gyro_turn(iv)
            self._wheel_cov = arc_covariance(iv.wheel_dl, iv.wheel_dr, iv.wheel_base, config.wheel_model(iv.twist)[0],
                                             np.diff(iv.t), self._turn)
            self._still = at_rest(iv, config)
        self.initial_estimate = initial_calibration(iv) if offset == 0 else {}

    # ------------------------------------------------------------------ helpers
    def kernel(self, dof: int):
        """``((name, width), GTSAM mEstimator)`` of the robust kernel for a factor of ``dof`` measured rows
        (:func:`kernel_width`), or None without one."""
        if dof not in self._kernels:
            width = kernel_width(self.config, dof)
            self._kernels[dof] = None if width is None else (
                (self.config.graph.robust, width), _robust_kernel(self.config.graph.robust, width))
        return self._kernels[dof]

    def model_factor(self, model, z, cov, keys: dict, fixed: dict | None = None, params: dict | None = None,
                     rows: tuple | None = None, robust: bool = True, dof: int | None = None) -> ModelFactor:
        """A measurement of a sensor model (:mod:`fusion_vo.backends.factors`), in the robust kernel unless
        ``robust`` is False; ``dof``: the rows that measure something (default: all of ``cov``'s), for the
        kernel's width."""
        cov = np.asarray(cov, dtype=np.float64)
        kernel = self.kernel(dof or len(np.atleast_2d(cov))) if robust else None
        return ModelFactor(model, np.array(z, dtype=np.float64).reshape(-1), keys, cov,
                           fixed or {}, params or {}, rows, None if kernel is None else kernel[0])

    def noise(self, cov: np.ndarray, robust: bool = True, dof: int | None = None):
        """GTSAM's noise model of ``cov``, in the robust kernel of ``dof`` rows (default: all) unless ``robust``
        is False."""
        cov = np.asarray(cov, dtype=np.float64)
        base = covariance_noise(cov)
        kernel = self.kernel(dof or len(cov)) if robust else None
        if kernel is not None:
            return gtsam.noiseModel.Robust.Create(kernel[1], base)
        return base

    @staticmethod
    def robust_noise(cov: np.ndarray, kernel: str, width: float):
        """GTSAM's noise model of ``cov`` inside the ``mEstimator`` ``kernel`` (``"huber"``, ``"cauchy"``; ``"none"``:
        the Gaussian alone) of ``width`` on the whitened distance."""
        base = covariance_noise(np.asarray(cov, dtype=np.float64))
        robust = _robust_kernel(kernel, width)
        return base if robust is None else gtsam.noiseModel.Robust.Create(robust, base)

    def _visual_spans(self) -> dict[int, list]:
        """Visual increments re-expressed between keyframes, keyed by their end node: (start node, delta,
        covariance, covariance of its frames' own errors or None, :func:`fusion_vo.sensors.visual.frame_covariances`;
        a composed span takes its last increment's, and keeps the inner frames' errors in its covariance)."""

        iv = self.iv
        pos = {int(g): n for n, g in enumerate(self.grid)}
        out: dict[int, list] = {}
        chain = None  # (start node, delta, cov, end grid index)
        fcs = frame_covariances(iv)
        for m, (i0, i1, d, c) in enumerate(zip(iv.vis_i0, iv.vis_i1, iv.vis_delta, iv.vis_cov)):
            i0, i1 = int(i0), int(i1)
            if chain is not None and chain[3] == i0:
                delta, cov = _compose_with_covariance(chain[1], chain[2], d, c)
                chain = (chain[0], delta, cov, i1)
            elif i0 in pos:
                chain = (pos[i0], d, c, i1)
            else:
                chain = None
                continue
            if i1 in pos:
                out.setdefault(pos[i1], []).append((chain[0], chain[1], chain[2], None if fcs is None else fcs[m]))
                chain = None
        return out

    def initial_pose(self) -> np.ndarray:
        """The first pose: aligned to the GPS fixes when fused, else the configured one."""
        if self.iv.initial_pose is not None:
            return np.asarray(self.iv.initial_pose, dtype=np.float64)
        return np.asarray(self.config.initial_pose, dtype=np.float64)

    # ------------------------------------------------------------------ per node
    def first_node(self, estimate: dict | None = None) -> NodeFactors:
        """Priors on the first pose, bias and calibration (``estimate`` gives initial values)."""
        cfg = self.config
        est = estimate or {}
        nf = NodeFactors(0, float(self.t[0]))
        pose = gtsam.Pose2(*self.initial_pose())
        sigma = 1e-4 if self.iv.initial_sigma is None else None
        nm = (gtsam.noiseModel.Isotropic.Sigma(3, sigma) if sigma is not None
              else gtsam.noiseModel.Diagonal.Sigmas(np.asarray(self.iv.initial_sigma, dtype=np.float64)))
        nf.factors.append(gtsam.PriorFactorPose2(X(0), pose, nm))
        nf.values[X(0)] = pose
        priors = []  # (key, prior mean, prior sigma, initial value)
        if self.iv.uses("gyro"):
            priors.append((B(0), 0.0, cfg.imu.gyro_bias_sigma, est.get("gyro_bias", 0.0)))
        if self.ahrs_offset_on:
            priors.append((O(0), 0.0, cfg.imu.ahrs_yaw_sigma, est.get("ahrs_offset", 0.0)))
        if self.kv_on:
            priors.append((S(0), 1.0, self.iv.visual_scale_sigma, est.get("visual_scale", 1.0)))
        if self.kb_on:
            priors.append((W(0), 1.0, cfg.wheel_model(self.iv.twist)[1], est.get("wheel_base_factor", 1.0)))
        if self.kr_on:
            priors.append((R(0), 1.0, self.iv.wheel_scale_sigma, est.get("wheel_scale", 1.0)))
        for st in self.states:
            priors.append((self.state_key(st.name, 0), st.initial, st.sigma, est.get(st.name, st.initial)))
        for key, mean, sigma, guess in priors:
            nf.factors.append(gtsam.PriorFactorDouble(key, mean, gtsam.noiseModel.Isotropic.Sigma(1, sigma)))
            nf.values[key] = guess
        self._unary(nf, 0)
        return nf

    def node(self, n: int, previous_pose: gtsam.Pose2, estimate: dict | None = None) -> NodeFactors:
        """Factors that end at node ``n`` and an initial guess for its variables.

        ``estimate`` holds the running bias and calibration estimates (``gyro_bias``, ``visual_scale``,
        ``wheel_base_factor``) and the previous increment, used only for initial guesses.

        Every registered sensor's ``graph_factors`` steps (:mod:`fusion_vo.sensors.registry`) add their
        factors in their order; those before :data:`GUESS_ORDER` may set the interval's translation and
        heading change for the initial guess (``NodeContext.translation``, ``heading``). Where none measured
        the translation a weak constant-twist factor keeps it determined. Then the unary steps
        (``graph_unary``) of the node.
        """
        cfg = self.config
        est = estimate or {}
        g0, g1 = self._grid[n - 1], self._grid[n]
        c, previous = self._segment[n], self._segment[n - 1]
        node = NodeContext(n=n, g0=g0, g1=g1, dt=self._times[g1] - self._times[g0], segment=c,
                           xi=X(self.offset + n - 1), xj=X(self.offset + n), estimate=est,
                           previous_pose=previous_pose)
        nf = NodeFactors(n, self._times[g1])
        if c != previous:
            self._new_segment(nf, c, est, previous)
        steps = registry.ordered("graph_factors")
        for _, step in steps:
            if step.order >= GUESS_ORDER:
                break
            step.run(self, nf, node)
        last = est.get("last_increment", _NO_INCREMENT)
        translation, heading = node.translation, node.heading
        guess = np.array([*(last[:2] if translation is None else translation), last[2] if heading is None else heading])
        if translation is None:
            # nothing measures this interval's translation: a weak constant-twist factor keeps it determined
            e = cfg.ekf
            sig = np.array([e.accel_sigma, e.accel_sigma, e.yaw_accel_sigma]) * max(node.dt, 1e-3) * 4.0 + 1e-3
            nm = gtsam.noiseModel.Diagonal.Sigmas(sig)
            nf.factors.append(gtsam.BetweenFactorPose2(node.xi, node.xj, gtsam.Pose2(*guess), nm))
            nf.sensors.append("motion_model")
        nf.values[node.xj] = previous_pose.compose(gtsam.Pose2(*guess))
        for key in node.scratch.pop("new_frames", ()):  # frame poses start at their node's pose
            nf.values[key] = nf.values[node.xj]
        nf.guess = guess
        for _, step in steps:  # (sorted by order)
            if step.order >= GUESS_ORDER:
                step.run(self, nf, node)
        self._unary(nf, n, node)
        return nf

    def wheel_increment(self, g0: int, g1: int) -> tuple[np.ndarray, np.ndarray]:
        """Arc-model increment and covariance of the wheel travel between grid indices ``g0`` and ``g1``."""
        iv = self.iv
        if g1 == g0 + 1:
            return self._wheel_inc[g0].copy(), self._wheel_cov[g0]
        dl, dr = iv.wheel_dl[g0:g1].sum(), iv.wheel_dr[g0:g1].sum()
        m = arc_increment(dl, dr, iv.wheel_base)[0]
        m[0] *= iv.cx[g0:g1].mean()
        m[1] *= iv.cy[g0:g1].mean()
        turn = None if self._turn is None else self._turn[g0:g1].sum()
        return m, arc_covariance(dl, dr, iv.wheel_base, self.config.wheel_model(iv.twist)[0], iv.t[g1] - iv.t[g0],
                                 turn)[0]

    def wheels_at_rest(self, g0: int, g1: int) -> bool:
        """Both wheels at rest in every interval from grid index ``g0`` to ``g1``
        (:func:`~fusion_vo.sensors.wheel.at_rest`, evaluated for all intervals at once)."""
        return bool(self._still[g0:g1].all())

    def key(self, n: int) -> int:
        """The pose variable of local node ``n``."""
        return X(self.offset + n)

    def state_key(self, name: str, segment: int) -> int:
        """The variable of a sensor's state ``name`` (:class:`fusion_vo.sensors.registry.State`) in ``segment``
        (``NodeContext.segment``)."""
        return gtsam.symbol(self._state_letter[name], segment)

    def _new_segment(self, nf: NodeFactors, c: int, estimate: dict, previous: int) -> None:
        """Bias and calibration variables of segment ``c``, tied to the ``previous`` segment (``c-1``, or an
        earlier one across a stretch without nodes) by random walks over the time between them."""
        cfg = self.config
        span = float(cfg.graph.calibration_interval) * (c - previous)
        walks = []
        if self.iv.uses("gyro"):
            walks.append((B, cfg.imu.gyro_random_walk, estimate.get("gyro_bias", 0.0)))
        if self.ahrs_offset_on:
            walks.append((O, cfg.imu.ahrs_offset_walk, estimate.get("ahrs_offset", 0.0)))
        if self.kv_on:
            walks.append((S, cfg.ekf.visual_scale_random_walk, estimate.get("visual_scale", 1.0)))
        if self.kb_on:
            walks.append((W, cfg.ekf.scale_random_walk, estimate.get("wheel_base_factor", 1.0)))
        if self.kr_on:
            walks.append((R, cfg.ekf.scale_random_walk, estimate.get("wheel_scale", 1.0)))
        for st in self.states:
            walks.append((lambda c, name=st.name: self.state_key(name, c), st.random_walk,
                          estimate.get(st.name, st.initial)))
        for key, q, guess in walks:
            sigma = max(q * np.sqrt(span), 1e-7)
            nm = gtsam.noiseModel.Isotropic.Sigma(1, sigma)
            nf.factors.append(gtsam.BetweenFactorDouble(key(previous), key(c), 0.0, nm))
            nf.values[key(c)] = guess

    def segment_keys(self, n: int) -> list[int]:
        """Bias and calibration variables of node ``n``'s segment."""
        c = int(self.segment[n])
        keys = [B(c)] if self.iv.uses("gyro") else []
        keys += [O(c)] if self.ahrs_offset_on else []
        keys += ([S(c)] if self.kv_on else []) + ([W(c)] if self.kb_on else []) + ([R(c)] if self.kr_on else [])
        return keys + [self.state_key(st.name, c) for st in self.states]

    def _unary(self, nf: NodeFactors, n: int, node: NodeContext | None = None) -> None:
        """The registered sensors' factors at node ``n`` alone (``graph_unary``, e.g. an absolute heading);
        ``node`` is the context of the interval ending there (its ``g1``, ``xj`` and ``segment`` are the node's)."""
        if node is None:
            g = int(self.grid[n])
            node = NodeContext(n=n, g0=g, g1=g, dt=0.0, segment=int(self.segment[n]), xi=X(self.offset + n),
                               xj=X(self.offset + n), estimate={})
        for _, step in registry.ordered("graph_unary"):
            step.run(self, nf, node)

    def count(self, nf: NodeFactors) -> None:
        counts = self.counts
        for s in nf.sensors:
            c = counts.get(s)
            if c is None:
                c = counts[s] = SensorCount()
            c.used += 1


def initial_calibration(iv: Intervals) -> dict:
    """Closed-form first guesses of the gyro bias, visual scale and wheel-base factor.

    Only initial values (the graph estimates them): without them a dead-reckoned initial trajectory
    drifts with the uncorrected gyro bias and Levenberg–Marquardt needs many damped iterations.
    The reference heading change is the camera's (independent of every calibration) where available.
    """
    out: dict = {}
    dt = iv.dt
    single = iv.vis_i1 == iv.vis_i0 + 1
    vis_yaw = np.full(iv.n_steps, np.nan)
    vis_xy = np.full(iv.n_steps, np.nan)
    vis_yaw[iv.vis_i0[single]] = iv.vis_delta[single, 2]
    vis_xy[iv.vis_i0[single]] = np.hypot(iv.vis_delta[single, 0], iv.vis_delta[single, 1])
    wheel_yaw = wheel_xy = None
    if iv.uses("wheel"):
        inc = arc_increment(iv.wheel_dl, iv.wheel_dr, iv.wheel_base)
        yaw_ok = iv.wheel_ok if iv.wheel_yaw_ok is None else iv.wheel_ok & iv.wheel_yaw_ok
        wheel_yaw = np.where(yaw_ok, inc[:, 2], np.nan)
        wheel_xy = np.where(iv.wheel_ok, np.hypot(inc[:, 0], inc[:, 1]), np.nan)
    ref = vis_yaw if np.isfinite(vis_yaw).sum() > 10 else wheel_yaw
    if iv.uses("gyro") and ref is not None:
        ok = iv.gyro_ok & np.isfinite(ref)
        if ok.sum() > 10:
            out["gyro_bias"] = float(np.sum(iv.gyro_angle[ok] - ref[ok]) / np.sum(dt[ok]))
    if wheel_xy is not None:
        ok = np.isfinite(vis_xy) & np.isfinite(wheel_xy)
        if ok.sum() > 10 and np.sum(wheel_xy[ok]) > 0:
            out["visual_scale"] = float(np.sum(vis_xy[ok]) / np.sum(wheel_xy[ok]))
        heading = vis_yaw if np.isfinite(vis_yaw).sum() > 10 else None
        if heading is None and "gyro_bias" in out:
            heading = np.where(iv.gyro_ok, iv.gyro_angle - out["gyro_bias"] * dt, np.nan)
        if heading is not None:
            ok = np.isfinite(heading) & np.isfinite(wheel_yaw)
            if ok.sum() > 10 and np.sum(heading[ok] ** 2) > 1e-6:
                out["wheel_base_factor"] = float(np.sum(wheel_yaw[ok] * heading[ok]) / np.sum(heading[ok] ** 2))
    for key, lo, hi in (("visual_scale", 0.8, 1.25), ("wheel_base_factor", 0.5, 2.0)):
        if key in out and not lo < out[key] < hi:
            del out[key]
    return out


def kernel_width(config: FusionConfig, dof: int) -> float | None:
    """Width of the graph's robust kernel on the whitened distance ``‖W e‖`` of a factor of ``dof`` rows
    (None: no kernel).

    GTSAM's robust noise models weigh a factor by the norm of its whole whitened residual, which for an
    honest measurement of ``m`` rows is chi-distributed with ``m`` degrees of freedom: a width meant for one
    row (Huber's 1.345) down-weights 18 % of honest one-row residuals but 40 % of two-row and 61 % of
    three-row ones (the camera's and the wheels' increments), and then the graph no longer solves the
    problem the filter solves. The width therefore keeps the tail probability of ``GraphConfig.robust_k``
    (a width for one row) for every ``m``. Its default, 3.2905, is the EKF's default gate (chi-square
    0.999): a measurement inside the filter's gate keeps its full weight in the batch and iSAM2 alike,
    and beyond it its influence is bounded, as the filter bounds it (:class:`~fusion_vo.sensors.model.Gate`).
    """
    from scipy.stats import chi2

    g = config.graph
    if g.robust == "none":
        return None
    if dof == 1:
        return float(g.robust_k)
    p = float(chi2.cdf(g.robust_k**2, 1))
    if p >= 1.0:
        return None
    return float(np.sqrt(chi2.ppf(p, dof)))


def _robust_kernel(name: str, width: float):
    if name == "huber":
        return gtsam.noiseModel.mEstimator.Huber.Create(width)
    if name == "cauchy":
        return gtsam.noiseModel.mEstimator.Cauchy.Create(width)
    return None


def _compose_with_covariance(a, cov_a, b, cov_b):
    """``a ⊕ b`` and its covariance ``J_a Σ_a J_aᵀ + J_b Σ_b J_bᵀ`` (first order, vector form)."""
    c, s = np.cos(a[2]), np.sin(a[2])
    ja = np.array([[1.0, 0.0, -s * b[0] - c * b[1]], [0.0, 1.0, c * b[0] - s * b[1]], [0.0, 0.0, 1.0]])
    jb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return se2.compose(a, b), ja @ cov_a @ ja.T + jb @ cov_b @ jb.T


def freeze_custom_factors(factors: list, lookup, maker: ValuesMaker | None = None,
                          weights: list | None = None) -> list:
    """Replace each sensor-model factor (:class:`~fusion_vo.backends.factors.ModelFactor`, or a
    :class:`gtsam.CustomFactor`) by its linearisation at ``lookup(key)`` values.

    Used for the incremental solvers, which relinearise only GTSAM's own nonlinear factors: they receive
    the (robustly weighted) linearisation as a ``LinearContainerFactor``. The factors are relative
    constraints between close nodes, linearised at the prediction of the newest pose, where they are
    nearly linear (the gyro's and the standstill's are exactly linear in the headings); the robust
    weight is fixed at that prediction, so a visual increment that disagrees with the wheels and the
    gyro beyond the gate (:func:`kernel_width`) enters with a small weight. The batch solution
    relinearises them and re-evaluates their weights at every iteration.

    The prediction of the newest pose comes from the wheels, so a camera residual there carries the
    wheels' error too: with a kernel one row wide on the camera's three rows, 76 % of the camera
    increments of the generated ``square`` drive entered iSAM2 down-weighted (mean weight 0.64), and its
    track (ATE 0.168 mm) fell behind the batch (0.085 mm) and the EKF (0.074 mm); with the gate's width
    12 % are (mean weight 0.98), and iSAM2 scores 0.089 mm. iSAM2 therefore evaluates the weights again
    where its update puts the node (:func:`update_reweighted`). ``weights``: the robust weight each
    sensor-model factor gets at these values is appended to it (1 without a kernel).
    """
    out = []
    keys = {key for f in factors if isinstance(f, ModelFactor) for key in f.all_keys()}
    point = (maker or ValuesMaker()).make({key: lookup(key) for key in keys}) if keys else None
    for f in factors:
        if isinstance(f, ModelFactor):
            out.append(f.linearized(lookup, point, weights))
        elif isinstance(f, gtsam.CustomFactor):
            lin = gtsam.Values()
            insert_values(lin, {key: lookup(key) for key in f.keys()})
            out.append(gtsam.LinearContainerFactor(f.linearize(lin), lin))
        else:
            out.append(f)
    return out


#: iSAM2 linearises a node's sensor-model factors again at its updated estimate when the robust weight of one
#: of them there differs from the one it entered with by more than this (:func:`update_reweighted`)
REWEIGHT_TOLERANCE = 1e-3


def estimate_lookup(solver):
    """``lookup(key)``: the incremental ``solver``'s current estimate of a variable (Pose2 or float)."""

    def value(key: int):
        if chr(gtsam.Symbol(key).chr()) in POSE_LETTERS:
            return solver.calculateEstimatePose2(key)
        return solver.calculateEstimateDouble(key)

    return value


def update_reweighted(isam, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, factors: list, weights: list,
                      maker: ValuesMaker | None = None, passes: int = 2) -> tuple[list[int], int]:
    """One iSAM2 update with a node's factors, the robust weights evaluated where the update puts the node.

    ``graph`` holds ``factors`` (the node's, in order) as :func:`freeze_custom_factors` linearised them at
    the prediction, and ``weights`` the robust weights it gave their sensor-model factors there. After the
    update, each robust factor's weight is evaluated at the new estimate; where one differs (by more than
    :data:`REWEIGHT_TOLERANCE`), all the node's sensor-model factors are linearised again at that estimate
    and replace the ones that went in (an iterated update, as an iterated EKF's, and the batch solution's
    reweighting at each iteration), at most ``passes`` times. Only a node with a weight below 1 at the
    prediction is checked: with every factor inside its kernel there, the update moves the node by a
    weighted mean of residuals inside their kernels (on the 16 generated drives of the measurement below,
    1210 nodes were linearised again, every one of them with a weight below 1 at the prediction).

    Why: the prediction of the newest pose comes from the wheels (translation) and the gyro (heading),
    and the camera's residual there carries their error, which is far larger than the camera's own noise
    (on the generated ``square`` drive the wheels' track is 600 times worse than the camera's). A kernel
    evaluated there down-weights good camera increments that the filter, gating with the prediction's
    uncertainty in the innovation covariance, takes at full weight; the update then pulls the pose most of
    the way to the camera, where the increment is well inside the kernel. An increment that is still
    beyond the kernel at the updated estimate (a wrong match, outvoted by the other sensors) keeps its
    small weight. On the generated ``square`` drive (seed 101) iSAM2 scored 0.111 mm with the weights of
    the prediction (``benchmarks/fusion_vs_best.py`` variant "iSAM2 weights at the prediction") and 0.102 mm
    with these, as the EKF. Returns the
    indices of the factors in iSAM2 (in the order of ``factors``) and the number of passes made.
    """
    index = list(isam.update(graph, values).getNewFactorsIndices())
    if passes <= 0 or min(weights, default=1.0) >= 1.0:
        return index, 0
    model = [i for i, f in enumerate(factors) if isinstance(f, ModelFactor)]
    robust = [j for j, i in enumerate(model) if factors[i].robust is not None]
    made = 0
    for _ in range(passes):
        estimate = estimate_lookup(isam)
        lookup = {key: estimate(key) for j in robust for key in factors[model[j]].all_keys()}.__getitem__
        if all(abs(factors[model[j]].weight(lookup) - weights[j]) <= REWEIGHT_TOLERANCE for j in robust):
            break
        lookup = estimate
        weights = []
        again = gtsam.NonlinearFactorGraph()
        for f in freeze_custom_factors([factors[i] for i in model], lookup, maker, weights):
            again.add(f)
        new = list(isam.update(again, gtsam.Values(), [index[i] for i in model]).getNewFactorsIndices())
        for i, k in zip(model, new):
            index[i] = k
        made += 1
    return index, made


def insert_values(values: gtsam.Values, items: dict) -> None:
    """Insert ``key -> Pose2 or float`` items into ``values``."""
    for key, v in items.items():
        if isinstance(v, gtsam.Pose2):
            values.insert(key, v)
        else:
            values.insert(key, float(v))


# --------------------------------------------------------------------------- batch
def levenberg_marquardt(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, dims: dict[int, int],
                        max_iterations: int = 20, relative_tolerance: float = 1e-3,
                        model_factors: list[ModelFactors] | None = None):
    """Levenberg–Marquardt on GTSAM's linearisation and elimination (see the module docstring).

    ``graph`` holds GTSAM's own factors; ``model_factors`` the sensor-model factors, evaluated and
    linearised in groups (:class:`~fusion_vo.backends.factors.ModelFactors`).
    Returns ``(solution, iterations, linear_graph)``; the last linearisation serves the marginals.
    """
    groups = model_factors or []
    pose_keys = pose_table(values)["keys"] if groups else None
    if any(g.linear for g in groups):
        # linear, non-robust factors (gyro, standstill) are exact as linear factors: linearised once
        graph = gtsam.NonlinearFactorGraph(graph)
        poses = pose_table(values, pose_keys)
        for g in groups:
            if g.linear:
                for f in g.linearize(values, poses):
                    graph.add(gtsam.LinearContainerFactor(f, values))
        groups = [g for g in groups if not g.linear]

    def total_error(v: gtsam.Values) -> float:
        poses = pose_table(v, pose_keys) if groups else None
        return graph.error(v) + sum(g.error(v, poses) for g in groups)

    def linearize(v: gtsam.Values) -> gtsam.GaussianFactorGraph:
        lin = graph.linearize(v)
        poses = pose_table(v, pose_keys) if groups else None
        for g in groups:
            for f in g.linearize(v, poses):
                lin.add(f)
        return lin

    def attempt(v: gtsam.Values, lin: gtsam.GaussianFactorGraph, lam: float):
        system = lin
        if lam > 0:
            system = lin.clone()
            for key, dim in dims.items():
                system.add(gtsam.JacobianFactor(key, np.sqrt(lam) * np.eye(dim), np.zeros(dim),
                                                gtsam.noiseModel.Unit.Create(dim)))
        try:
            trial = v.retract(system.optimize())
            return trial, total_error(trial)
        except RuntimeError as exc:  # a (nearly) singular Gauss-Newton system: damp it, as GTSAM's LM does
            if "Indeterminate" not in str(exc):
                raise
            return None, math.inf

    return damped_gauss_newton(values, total_error(values), linearize, attempt, max_iterations,
                               relative_tolerance)


def run_graph(iv: Intervals, config: FusionConfig, initial: PoseData | None = None) -> FusionResult:
    """Batch (``"gtsam"``), iSAM2 (``"gtsam_online"``) and fixed-lag (``"gtsam_fixed_lag"``) solutions."""
    gcfg = config.graph
    result = FusionResult()
    builder = GraphBuilder(iv, config)
    n_nodes = len(builder.t)
    online_poses = np.zeros((n_nodes, 3))
    online_cov = np.zeros((n_nodes, 3, 3))
    lag_poses = np.zeros((n_nodes, 3))
    graph = gtsam.NonlinearFactorGraph()
    model_factors: list[ModelFactor] = []
    values = gtsam.Values()
    dims: dict[int, int] = {}
    isam = gtsam.ISAM2(isam_params()) if gcfg.online else None
    lag = gtsam.IncrementalFixedLagSmoother(gcfg.fixed_lag, isam_params()) if gcfg.fixed_lag > 0 else None
    t_online = 0.0
    t_build = time.process_time()
    estimate: dict = dict(builder.initial_estimate)
    prev_pose = gtsam.Pose2(*builder.initial_pose())
    # sensors whose factors are gated against the online estimate (GPS fixes)
    at_nodes = [run for run in (s.graph_run(builder) for s in registry.sensors() if s.graph_run is not None)
                if run is not None]
    maker = ValuesMaker()
    batch_values: dict = {}
    # the sensors' residuals need every factor in iSAM2: nothing is marginalised then
    retired = Retired(builder, horizon=n_nodes + 1) if gcfg.residuals else Retired(builder)
    reweighted = 0  # iSAM2 updates repeated for the robust weights at the updated estimate
    for n in range(n_nodes):
        nf = builder.first_node(estimate) if n == 0 else builder.node(n, prev_pose, estimate)
        if at_nodes:
            if n == 0:
                pose_cov = None if iv.initial_sigma is None else np.diag(np.square(iv.initial_sigma))
            elif isam is not None:
                pose_cov = world_covariances(online_poses[n - 1:n, 2], online_cov[n - 1:n])[0]
            else:
                pose_cov = None
            for run in at_nodes:
                run.add(nf, n, pose_cov)
        builder.count(nf)
        incremental = isam is not None or lag is not None
        new_values = maker.make(nf.values) if incremental else None
        if gcfg.batch:
            for f in nf.factors:
                if isinstance(f, ModelFactor):
                    model_factors.append(f)
                else:
                    graph.add(f)
            batch_values.update(nf.values)  # made into gtsam.Values at once after the loop
        elif gcfg.residuals:
            model_factors.extend(f for f in nf.factors if isinstance(f, ModelFactor))
        for key, v in nf.values.items():
            dims[key] = 3 if isinstance(v, gtsam.Pose2) else 1
        t0 = time.process_time() if incremental else 0.0
        new_graph = gtsam.NonlinearFactorGraph()
        weights: list = []
        if incremental:
            lookup = current_value_lookup(nf.values, isam if isam is not None else lag, prev_pose, n - 1)
            for f in freeze_custom_factors(nf.factors, lookup, maker, weights):
                new_graph.add(f)
        if isam is not None:
            reweighted += update_reweighted(isam, new_graph, new_values, nf.factors, weights, maker,
                                            gcfg.reweight_passes)[1] > 0
            retired.step(isam, n)
            pose = isam.calculateEstimatePose2(X(n))
            online_poses[n] = (pose.x(), pose.y(), pose.theta())
            online_cov[n] = isam.marginalCovariance(X(n))
            track_estimate(estimate, isam, builder, n, nf)
            t_online += time.process_time() - t0
            prev_pose = pose
        else:
            prev_pose = nf.values[X(n)]
            estimate["last_increment"] = nf.guess if nf.guess is not None else np.zeros(3)
        if lag is not None:
            # the current segment's bias and calibration stay in the window while factors still use them
            stamps = {key: nf.t for key in list(nf.values) + builder.segment_keys(n)}
            lag.update(new_graph, new_values, stamps)
            p = lag.calculateEstimatePose2(X(n))
            lag_poses[n] = (p.x(), p.y(), p.theta())
    if batch_values and isam is None:  # with iSAM2 the batch starts from its estimate
        values = ValuesMaker().make(batch_values)
    t_graph = time.process_time() - t_build - t_online
    counts = builder.counts
    for run in at_nodes:
        run.finish(result)
    if isam is not None:
        result.trajectories["gtsam_online"] = PoseData(builder.t.copy(), online_poses)
        result.covariances["gtsam_online"] = world_covariances(online_poses[:, 2], online_cov)
        result.counts["gtsam_online"] = counts
        online_values = retired.complete(isam.calculateEstimate())
        result.calibration["gtsam_online"] = _calibration(online_values, builder)
        _state_sigmas(result.calibration["gtsam_online"], builder, lambda keys: [isam.marginalCovariance(k)[0, 0]
                                                                                  for k in keys])
        result.timing["gtsam_online"] = t_online
        result.timing["gtsam_online_per_node_ms"] = 1e3 * t_online / max(n_nodes, 1)
        logger.info("gtsam_online: %d of %d nodes updated again for their robust weights", reweighted, n_nodes)
        if gcfg.residuals:
            final = isam.calculateBestEstimate()  # fully back-substituted (no wildfire threshold)
            result.residuals["gtsam_online"] = graph_residuals(
                model_factors, final, gtsam.Marginals(isam.getFactorsUnsafe(), final), builder)
    if lag is not None:
        result.trajectories["gtsam_fixed_lag"] = PoseData(builder.t.copy(), lag_poses)
        result.counts["gtsam_fixed_lag"] = counts
    if gcfg.batch:
        t0 = time.process_time()
        start_values = values
        if isam is not None:
            start_values = online_values
        elif initial is not None:
            start_values = _seed_poses(values, initial, builder)
        groups = group(model_factors)
        try:  # the block-tridiagonal solver of a chain-shaped graph (see fusion_vo.backends.chain)
            problem = chain.ChainProblem(graph, groups, start_values, dims, time_rank(builder))
        except chain.NotAChain as exc:
            logger.info("gtsam: GTSAM's elimination for the batch solution (%s)", exc)
            problem = None
        if problem is not None:
            with threadpool_limits(limits=1, user_api="blas"):  # small blocks: see fusion_vo.backends.chain
                solution, iters, lin = chain.levenberg_marquardt(problem, start_values, gcfg.max_iterations,
                                                                 gcfg.relative_tolerance)
        else:
            solution, iters, lin = levenberg_marquardt(graph, start_values, dims, gcfg.max_iterations,
                                                       gcfg.relative_tolerance, groups)
        poses = np.array([[p.x(), p.y(), p.theta()] for p in (solution.atPose2(X(n)) for n in range(n_nodes))])
        result.trajectories["gtsam"] = PoseData(builder.t.copy(), poses)
        result.counts["gtsam"] = counts
        result.calibration["gtsam"] = _calibration(solution, builder)
        t_solve = time.process_time() - t0
        if gcfg.marginals:
            t1 = time.process_time()
            if problem is not None:
                with threadpool_limits(limits=1, user_api="blas"):
                    cov = chain.pose_marginals(lin, [X(n) for n in range(n_nodes)])
            else:
                cov = pose_marginals(lin, solution, n_nodes)
            result.covariances["gtsam"] = world_covariances(poses[:, 2], cov)
            if problem is not None:
                with threadpool_limits(limits=1, user_api="blas"):
                    _state_sigmas(result.calibration["gtsam"], builder,
                                  lambda keys: chain.pose_marginals(lin, keys, dim=1)[:, 0, 0])
            else:
                _state_sigmas(result.calibration["gtsam"], builder, lambda keys, m=None: [
                    (m := m or gtsam.Marginals(lin, solution)).marginalCovariance(k)[0, 0] for k in keys])
            result.timing["gtsam_marginals"] = time.process_time() - t1
        if gcfg.residuals:
            if problem is not None:  # GTSAM's linearisation at the same point as the solver's last one
                lin = gtsam_linearization(graph, groups, lin.point)
            result.residuals["gtsam"] = graph_residuals(model_factors, solution, gtsam.Marginals(lin, solution), builder)
        result.timing["gtsam"] = time.process_time() - t0 + t_graph
        result.timing["gtsam_build"] = t_graph
        result.timing["gtsam_solve"] = t_solve
        logger.info("gtsam: %d nodes, %d factors, %d LM iterations", n_nodes, graph.size() + len(model_factors), iters)
    result.notes.extend(iv.notes)
    return result


def time_rank(builder: GraphBuilder):
    """Position in time of variables (an array of keys): node ``n`` for its pose, just before the first
    node of its segment for a segment's bias and calibration variables (the column order of the batch
    solver, :mod:`fusion_vo.backends.chain`)."""
    seg = np.asarray(builder.segment)

    def rank(keys: np.ndarray) -> np.ndarray:
        keys = np.asarray(keys, dtype=np.uint64)
        letter = (keys >> np.uint64(56)).astype(np.int64)  # gtsam.Symbol: the letter in the top byte
        index = (keys & np.uint64((1 << 56) - 1)).astype(np.int64)
        first = np.searchsorted(seg, index).astype(np.float64) - 0.5  # a segment's first node, before it
        pose = (letter == ord("x")) | (letter == ord(FRAME_LETTER))
        return np.where(pose, index - builder.offset, first)

    return rank


#: iSAM2 keeps this many nodes (camera frames) behind the newest; older ones are marginalised
ONLINE_HORIZON = 200


class Retired:
    """Marginalises the variables of iSAM2's oldest nodes, keeping its Bayes tree to the last
    :data:`ONLINE_HORIZON` to :data:`2 ONLINE_HORIZON <ONLINE_HORIZON>` nodes, and remembers their estimates.

    Why: the graph is a chain, so iSAM2's Bayes tree is a path as long as the drive, and GTSAM 4.3
    destroys each update's temporary Bayes tree by visiting every clique below it (the breadth-first
    ``BayesTree`` destructor that avoids deep recursion), which is the whole history: ``perf`` on a
    400 s drive put 83 % of the update time there, and the cost per update grew from 0.3 ms at the
    start of a 600 s drive to 4.8 ms at its end. No future factor touches a variable that old (a node's
    factors reach its previous node and its segment's variables), and the marginal keeps the
    information of the old factors on the variables that remain, linearised where they are. That is
    exact for the newest pose unless iSAM2 would have relinearised the old variables later: on the
    generated drives and robot_localization's Jackal log nothing changes; on its Husky log the
    standstill at 236 s, which reveals the gyro bias, used to relinearise the history behind it, and
    the online track now moves by up to 1.12 m (RMS error against the GPS 6.17 m before, 6.08 m now).
    The old nodes' estimates are the ones at the time they leave (the batch solution starts from them).
    """

    def __init__(self, builder: GraphBuilder, horizon: int = ONLINE_HORIZON):
        self.builder = builder
        self.horizon = horizon
        self.first = 0  # nodes before it are marginalised
        self.values: dict = {}

    def step(self, isam, n: int) -> None:
        """Marginalise whole segments of nodes more than ``horizon`` behind node ``n`` (every ``horizon`` nodes)."""
        if n - self.first < 2 * self.horizon:
            return
        b = self.builder
        seg = np.asarray(b.segment)
        end = int(np.searchsorted(seg, seg[n - self.horizon]))  # the first node of that node's segment
        if end <= self.first:
            return
        keys = [X(b.offset + k) for k in range(self.first, end)]
        keys += [F(b.offset + k) for k in range(self.first, end) if b.offset + k in b.frames]
        seg_keys = []
        for c in np.unique(seg[self.first:end]):
            seg_keys += b.segment_keys(int(np.searchsorted(seg, c)))
        leaves = gtsam.KeyList()
        for key in keys + seg_keys:
            leaves.push_back(key)
        try:
            estimates = {key: isam.calculateEstimatePose2(key) for key in keys}
            estimates.update({key: isam.calculateEstimateDouble(key) for key in seg_keys})
            self._make_leaves(isam, set(keys + seg_keys))
            isam.marginalizeLeaves(leaves)
        except RuntimeError as exc:  # not the leaves of the tree: keep them for now
            logger.debug("iSAM2: nodes %d-%d not marginalised (%s)", self.first, end - 1, exc)
            return
        self.values.update(estimates)
        self.first = end

    @staticmethod
    def _make_leaves(isam, old: set) -> None:
        """Re-eliminate the Bayes tree with the ``old`` variables first, so that they are its leaves.

        ``marginalizeLeaves`` needs them in leaf cliques and checks that only in part: on a 120 s
        generated drive of wheels and gyro alone (no camera, no heading reference) it failed half-way
        through the seventh marginalisation with "variables ... not unused" and left a tree that
        crashed the process on the next update. GTSAM's IncrementalFixedLagSmoother orders the
        variables it marginalises first for the same reason. Every variable is re-eliminated (at most
        two horizons of nodes, once per horizon) at its current linearisation point: none is
        relinearised by it. The online track is unchanged to 1e-9 (``tests/backends/test_chain.py``).
        """
        groups = gtsam.KeyGroupMap()
        reelim = gtsam.KeyList()
        for key in isam.getLinearizationPoint().keys():
            groups.insert2(key, 0 if key in old else 1)
            reelim.push_back(key)
        params = gtsam.ISAM2UpdateParams()
        params.constrainedKeys = groups
        params.extraReelimKeys = reelim
        params.noRelinKeys = reelim
        isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), params)

    def complete(self, values: gtsam.Values) -> gtsam.Values:
        """``values`` with the marginalised variables' estimates added."""
        if self.values:
            values = gtsam.Values(values)
            insert_values(values, {k: v for k, v in self.values.items() if not values.exists(k)})
        return values


def gtsam_linearization(graph: gtsam.NonlinearFactorGraph, groups: list[ModelFactors], values: gtsam.Values):
    """The whole graph linearised at ``values`` as a ``GaussianFactorGraph`` (GTSAM's own factors and
    the sensor-model factors as ``JacobianFactor`` s), for GTSAM's ``Marginals``."""
    lin = graph.linearize(values)
    poses = pose_table(values)
    for g in groups:
        for f in g.linearize(values, poses):
            lin.add(f)
    return lin


def graph_residuals(factors: list[ModelFactor], values: gtsam.Values, marginals, builder: GraphBuilder,
                    stride: int = 5) -> dict:
    """Each sensor's NIS at a solution (:func:`fusion_vo.backends.residuals.sensor_nis`), every ``stride``-th node."""
    from fusion_vo.backends.residuals import sensor_nis

    def node_of(key: int):
        n = int(gtsam.Symbol(key).index()) - builder.offset
        return n, float(builder.t[n])

    return sensor_nis(factors, values, marginals, node_of, stride)


def current_value_lookup(new: dict, solver, prev_pose: gtsam.Pose2, prev: int):
    """Current value of a key: new variables from ``new``, others from the incremental ``solver``."""

    estimate = estimate_lookup(solver)

    def value(key: int):
        if key in new:
            return new[key]
        if key == X(prev):
            return prev_pose
        return estimate(key)

    return value


def world_covariances(yaw: np.ndarray, cov_local: np.ndarray) -> np.ndarray:
    """Pose covariances (N, 3, 3) from GTSAM's Pose2 tangent space (x, y along the body's own axes)
    to the world frame's (x, y, yaw), as the EKF reports them and ``NAME.cov.csv`` holds them:
    ``P_W = J P Jᵀ`` with ``J = diag(R(ψ), 1)`` (first order of ``p ⊕ δ``)."""
    yaw = np.asarray(yaw, dtype=np.float64)
    J = np.zeros((len(yaw), 3, 3))
    c, s = np.cos(yaw), np.sin(yaw)
    J[:, 0, 0], J[:, 0, 1], J[:, 1, 0], J[:, 1, 1], J[:, 2, 2] = c, -s, s, c, 1.0
    return J @ np.asarray(cov_local) @ np.transpose(J, (0, 2, 1))


def pose_marginals(linear: gtsam.GaussianFactorGraph, solution: gtsam.Values, n_nodes: int) -> np.ndarray:
    """Marginal covariances (N, 3, 3) of all poses (Pose2 tangent space: x, y forward/left, yaw).

    ``linear`` is the graph linearised at (or, after convergence, next to) ``solution``. When
    the factorisation finds the system too poorly conditioned, every variable gets a vague prior
    (``σ = 100`` in its tangent space, far wider than anything is estimated to) and the
    factorisation is repeated; if that fails too the covariances are NaN (logged).
    """
    try:
        marginals = gtsam.Marginals(linear, solution)
    except RuntimeError as exc:
        if "Indeterminate" not in str(exc):
            raise
        logger.warning("gtsam: marginals of a poorly conditioned system; adding vague priors")
        linear = linear.clone()
        for key in solution.keys():
            dim = 3 if chr(gtsam.Symbol(key).chr()) in POSE_LETTERS else 1
            linear.add(gtsam.JacobianFactor(key, np.eye(dim) * 0.01, np.zeros(dim), gtsam.noiseModel.Unit.Create(dim)))
        try:
            marginals = gtsam.Marginals(linear, solution)
        except RuntimeError:
            logger.warning("gtsam: no marginal covariances (the linearised system is indeterminate)")
            return np.full((n_nodes, 3, 3), np.nan)
    return np.array([marginals.marginalCovariance(X(n)) for n in range(n_nodes)])


def track_estimate(estimate: dict, isam, builder: GraphBuilder, n: int, nf: NodeFactors) -> None:
    """Running estimates of the bias and calibration for initial guesses of the next node."""
    if builder.iv.uses("gyro"):
        estimate["gyro_bias"] = isam.calculateEstimateDouble(B(int(builder.segment[n])))
    if builder.ahrs_offset_on:
        estimate["ahrs_offset"] = isam.calculateEstimateDouble(O(int(builder.segment[n])))
    if builder.kv_on:
        estimate["visual_scale"] = isam.calculateEstimateDouble(S(int(builder.segment[n])))
    if builder.kb_on:
        estimate["wheel_base_factor"] = isam.calculateEstimateDouble(W(int(builder.segment[n])))
    if builder.kr_on:
        estimate["wheel_scale"] = isam.calculateEstimateDouble(R(int(builder.segment[n])))
    for st in builder.states:
        estimate[st.name] = isam.calculateEstimateDouble(builder.state_key(st.name, int(builder.segment[n])))
    estimate["last_increment"] = nf.guess if nf.guess is not None else np.zeros(3)


def _seed_poses(values: gtsam.Values, initial: PoseData, builder: GraphBuilder) -> gtsam.Values:
    out = gtsam.Values(values)
    for n, t in enumerate(builder.t):
        p = [np.interp(t, initial.t, initial.xyyaw[:, i]) for i in range(2)]
        yaw = np.interp(t, initial.t, np.unwrap(initial.xyyaw[:, 2]))
        out.update(X(n), gtsam.Pose2(p[0], p[1], float(yaw)))
    return out


def _calibration(values: gtsam.Values, builder: GraphBuilder) -> dict:
    iv = builder.iv
    out = {}
    last = int(builder.segment[-1])
    if iv.uses("gyro") and values.exists(B(last)):
        out["gyro_bias"] = float(values.atDouble(B(last)))
    if builder.kv_on:
        kv = float(values.atDouble(S(last)))
        out["visual_scale"] = kv
        if iv.camera_height:
            out["camera_height"] = float(iv.camera_height / kv)
    if builder.kb_on:
        kb = float(values.atDouble(W(last)))
        out["wheel_base_factor"] = kb
        if not iv.twist:  # an odometry twist has no wheel base: the factor scales its yaw rate
            out["wheel_base"] = float(iv.wheel_base * kb)
    if builder.kr_on:
        out["wheel_scale"] = float(values.atDouble(R(last)))
    for st in builder.states:  # the sensors' own states
        out[st.name] = float(values.atDouble(builder.state_key(st.name, last)))
    return out


def _state_sigmas(out: dict, builder: GraphBuilder, variances) -> None:
    """``NAME_sigma`` in ``out`` for each of the sensors' own states (their last segment's variable), as the EKF
    reports it; ``variances(keys)`` gives their marginal variances. Nothing when the marginals fail."""
    if not builder.states:
        return
    last = int(builder.segment[-1])
    try:
        var = variances([builder.state_key(st.name, last) for st in builder.states])
    except RuntimeError as exc:  # an indeterminate system: the estimates stand without their sigma
        logger.warning("gtsam: no marginal variance of the sensors' states (%s)", exc)
        return
    for st, v in zip(builder.states, var):
        out[f"{st.name}_sigma"] = float(np.sqrt(v))


def isam_params() -> gtsam.ISAM2Params:
    """iSAM2 settings that keep the cost per node nearly constant.

    The gyro bias and the calibration couple every heading to the whole history: a small change of the
    bias estimate moves old headings by ``δb · age``. Updating and relinearising all of them for such
    changes would make each update O(N). Relinearisation is therefore checked only along the
    re-eliminated part of the tree, every 10 updates, for changes above 0.1, and back-substitution
    stops where changes fall under 1.0 (the wildfire threshold). The newest pose — the online estimate —
    sits at the root and is always solved exactly; the batch solution refines the history. Tighter
    settings (relinearisation threshold 0.001 every update, wildfire threshold 0) changed no online ATE
    of the generated ``short``, ``square``, ``circle`` and ``random60`` drives in the fourth digit [mm]:
    the sensor-model factors enter linearised (:func:`freeze_custom_factors`), so relinearisation
    touches only GTSAM's own factors. Checked again with the camera and the gyro alone (threshold 0 at
    every update, wildfire 0; ``square``, its seed 101 and ``random60``): the same ATEs to 1e-4 mm.

    The factorisation is QR. Cholesky squares the condition number, and systems that are well posed
    but badly conditioned are then reported as indeterminate: with GPS, a loose first-heading prior (from
    the fixes) beside near-exact wheel heading changes at low speed; on a generated barrel-lens recording
    (``real_barrel_fine``), a gyro-bias variable beside very precise camera increments, where Cholesky
    stopped the whole run. QR costs 3-8 % more per node on the 60 s and 600 s drives of
    benchmarks/bench_fusion.py (0.42-0.45 ms against 0.39-0.43 ms with Cholesky, interleaved runs).
    """
    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(0.1)
    params.relinearizeSkip = 10
    params.enablePartialRelinearizationCheck = True
    params.setOptimizationParams(gtsam.ISAM2GaussNewtonParams(1.0))
    params.setFactorization("QR")
    return params
