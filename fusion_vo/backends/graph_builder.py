"""The factor graph's variables and the factors that arrive with each node.

Variables: ``X_k`` (:func:`X`) the Pose2 of B in W at graph node ``k`` (every ``keyframe_every``-th node of the
grid, and every node with an absolute reading); ``F_k`` (:func:`F`) the camera's measured pose at node ``k`` when
its readings state their frames' errors; per calibration segment ``c`` (``GraphConfig.calibration_interval``
seconds of nodes) a variable of each scalar state the run estimates (:func:`fusion_vo.backends.states.run_states`:
the gyro bias ``b_c``, the AHRS offset ``o_c``, the visual scale ``s_c``, the wheel-base factor ``w_c``, the wheels'
distance scale ``r_c``, and any a registered sensor declares; :meth:`GraphBuilder.state_key`) with its prior on
the first segment's, tied between segments by its random walk. A state the run does not estimate has no variable:
the models take it at its initial value.

:class:`GraphBuilder` turns :class:`~fusion_vo.backends.timeline.Intervals` into per-node batches
(:class:`NodeFactors`): the priors of the first node, the random walks of a new segment, the sensors' readings as
factors (:mod:`fusion_vo.backends.graph_adapter`), the initial value of the new pose, and a weak constant-twist
factor where nothing measures an interval's translation. All three solvers of :mod:`fusion_vo.backends.graph`
(batch, iSAM2, fixed lag) consume the same batches.
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass, field

import gtsam
import numpy as np

from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.result import SensorCount
from fusion_vo.backends.states import estimated
from fusion_vo.backends.graph_adapter import GraphReadings, frame_poses, interval_factor, node_factor
from fusion_vo.backends.graph_adapter import guess as readings_guess
from fusion_vo.backends.timeline import Intervals, sensor_readings
from fusion_vo.backends.factors import ModelFactor, POSE_LETTERS, covariance_noise
from fusion_vo.robust import mestimator
from fusion_vo.sensors import registry


logger = logging.getLogger(__name__)


def X(k: int) -> int:
    return gtsam.symbol("x", k)


#: GTSAM symbol letter of the camera's frame poses (:func:`F`)
FRAME_LETTER = POSE_LETTERS[1]


def F(k: int) -> int:
    """The camera's measured pose at node ``k`` (``X(k)`` with that frame's own error; ``visual_frame_error``,
    :mod:`fusion_vo.sensors.visual`)."""
    return gtsam.symbol(FRAME_LETTER, k)


#: GTSAM symbol letter of the world frame of a stream aligned to GPS fixes (:func:`T_WS`)
WORLD_LETTER = POSE_LETTERS[2]


def T_WS() -> int:
    """The pose of the start frame in ENU, ``T_WS``, when a stream's poses stay in the frame they started in and
    GPS fixes measure ``T_WS X_k`` (:class:`~fusion_vo.backends.online_graph.OnlineGraph`)."""
    return gtsam.symbol(WORLD_LETTER, 0)


_NO_INCREMENT = np.zeros(3)
_NO_INCREMENT.flags.writeable = False

#: GTSAM symbol letters of the states that name none of their own (:attr:`State.symbol
#: <fusion_vo.sensors.registry.State.symbol>`), in the order the states come
_STATE_LETTERS = "acdefghijklmnpqtuvyz"

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
    new_frames: list = field(default_factory=list)  # frame poses made here, which start at the node's pose


class GraphBuilder:
    """Turns :class:`~fusion_vo.backends.timeline.Intervals` into per-node factor batches."""

    #: the variables' keys, for the sensors' graph steps (pose and camera frame of a node; module docstring)
    X, F = staticmethod(X), staticmethod(F)

    def __init__(self, iv: Intervals, config: FusionConfig, offset: int = 0, t_origin: float | None = None,
                 states: tuple | None = None):
        """``offset``, ``t_origin`` and ``states`` let a stream be built one interval at a time: local node ``n``
        is variable ``X(offset + n)``, segments count from ``t_origin`` and ``states`` are the run's (default:
        ``iv.states``)."""
        self.iv = iv
        #: the run's scalar states (estimated or held); :attr:`variables`: those with variables
        self.states = tuple(iv.states if states is None else states)
        self.variables = estimated(self.states)
        # each estimated state's variables: the letter it names, else the next free one of GTSAM's symbols
        named = {st.symbol for st in self.variables}
        free = iter(letter for letter in _STATE_LETTERS if letter not in named)
        self._state_letter = {st.name: st.symbol or next(free) for st in self.variables}
        self._held = {st.name: float(st.initial) for st in self.states if not st.estimated}
        self.config = config
        self.offset = offset
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
        self.readings = GraphReadings(sensor_readings(iv, config), nodes)  # the sensors' readings on these nodes
        self.t = iv.t[nodes]
        # bias and calibration variables: one per segment of `calibration_interval` seconds
        origin = self.t[0] if t_origin is None else t_origin
        self.segment = np.floor((self.t - origin) / config.graph.calibration_interval + 1e-9).astype(int)
        # the same as Python lists: indexed once per node, faster than numpy scalars
        self._grid, self._segment, self._times = self.grid.tolist(), self.segment.tolist(), iv.t.tolist()
        self._kernels: dict[int, tuple] = {}  # rows -> ((name, width), GTSAM mEstimator) or None
        self.counts: dict[str, SensorCount] = {k: SensorCount(**v.as_dict()) for k, v in iv.counts.items()}
        for c in self.counts.values():
            c.used = 0
        #: global nodes whose frame pose ``F`` exists (a stream built one interval at a time shares one set)
        self.frames: set[int] = set()
        self.initial_estimate = initial_calibration(iv) if offset == 0 else {}

    # ------------------------------------------------------------------ helpers
    def kernel(self, dof: int):
        """``((name, width), GTSAM mEstimator)`` of the robust kernel for a factor of ``dof`` measured rows
        (:func:`kernel_width`), or None without one."""
        if dof not in self._kernels:
            width = kernel_width(self.config, dof)
            self._kernels[dof] = None if width is None else (
                (self.config.graph.robust, width), mestimator(self.config.graph.robust, width))
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
        robust = mestimator(kernel, width)
        return base if robust is None else gtsam.noiseModel.Robust.Create(robust, base)

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
        for st in self.variables:  # each estimated state's prior, at its initial guess
            key = self.state_key(st.name, 0)
            nf.factors.append(gtsam.PriorFactorDouble(key, st.initial, gtsam.noiseModel.Isotropic.Sigma(1, st.sigma)))
            nf.values[key] = est.get(st.name, st.initial)
        self._unary(nf, 0)
        return nf

    def node(self, n: int, previous_pose: gtsam.Pose2, estimate: dict | None = None) -> NodeFactors:
        """Factors that end at node ``n`` and an initial guess for its variables.

        ``estimate`` holds the running bias and calibration estimates (``gyro_bias``, ``visual_scale``,
        ``wheel_base_factor``, ...) and the previous increment, used only for initial guesses.

        The sensors' interval readings that end at node ``n`` become factors (:mod:`fusion_vo.backends.graph_adapter`),
        in their order; the new pose's initial value is the previous pose composed with the interval's motion as
        the readings over exactly that interval give it (their models' guesses, by rank), else the previous
        increment. Where none measured the translation a weak constant-twist factor keeps it determined. Then the
        node readings at ``n``.
        """
        cfg = self.config
        est = estimate or {}
        g0, g1 = self._grid[n - 1], self._grid[n]
        c, previous = self._segment[n], self._segment[n - 1]
        dt = self._times[g1] - self._times[g0]
        xi, xj = X(self.offset + n - 1), X(self.offset + n)
        nf = NodeFactors(n, self._times[g1])
        if c != previous:
            self._new_segment(nf, c, est, previous)
        spans = self.readings.ending_at(n)
        for span in spans:  # the sensors' interval readings that end here
            xs, xe, cov = X(self.offset + span.start), xj, None
            if span.frame_cov is not None:
                frames = frame_poses(self, nf, span, n, c, previous_pose)
                if frames is not None:
                    (xs, xe), cov = frames, span.cov - 2.0 * span.frame_cov
            # (a reading that starts before the grid, span.start < 0, is a camera increment: no dt)
            dt_span = self._times[g1] - self._times[self._grid[span.start]] if span.start >= 0 else float("nan")
            factor = interval_factor(self, span, xs, xe, c, dt_span, cov=cov)
            nf.factors.append(factor)
            nf.sensors.append(span.readings.sensor)
        (translation, _), (heading, _) = readings_guess(spans, n, est, dt)
        last = est.get("last_increment", _NO_INCREMENT)
        guess = np.array([*(last[:2] if translation is None else translation), last[2] if heading is None else heading])
        if translation is None:
            # nothing measures this interval's translation: a weak constant-twist factor keeps it determined
            e = cfg.ekf
            sig = np.array([e.accel_sigma, e.accel_sigma, e.yaw_accel_sigma]) * max(dt, 1e-3) * 4.0 + 1e-3
            nm = gtsam.noiseModel.Diagonal.Sigmas(sig)
            nf.factors.append(gtsam.BetweenFactorPose2(xi, xj, gtsam.Pose2(*guess), nm))
            nf.sensors.append("motion_model")
        nf.values[xj] = previous_pose.compose(gtsam.Pose2(*guess))
        for key in nf.new_frames:  # frame poses start at their node's pose
            nf.values[key] = nf.values[xj]
        nf.guess = guess
        self._unary(nf, n)
        return nf

    def state_variable(self, name: str, segment: int) -> int | None:
        """The variable of state ``name`` in calibration ``segment``, or None when the graph does not estimate it."""
        if name in self._state_letter:
            return self.state_key(name, segment)
        return None

    def state_initial(self, name: str) -> float:
        """The value a state the graph does not estimate is held at: its initial value (scales 1, offsets 0)."""
        if name in self._held:
            return self._held[name]
        for st in registry.all_states():
            if st.name == name:
                return float(st.initial)
        return 0.0

    def key(self, n: int) -> int:
        """The pose variable of local node ``n``."""
        return X(self.offset + n)

    def state_key(self, name: str, segment: int) -> int:
        """The variable of the estimated state ``name`` (:class:`fusion_vo.sensors.registry.State`) in calibration
        ``segment``."""
        return gtsam.symbol(self._state_letter[name], segment)

    def _new_segment(self, nf: NodeFactors, c: int, estimate: dict, previous: int) -> None:
        """Bias and calibration variables of segment ``c``, tied to the ``previous`` segment (``c-1``, or an
        earlier one across a stretch without nodes) by random walks over the time between them."""
        span = float(self.config.graph.calibration_interval) * (c - previous)
        for st in self.variables:
            sigma = max(st.random_walk * np.sqrt(span), 1e-7)
            nm = gtsam.noiseModel.Isotropic.Sigma(1, sigma)
            key = self.state_key(st.name, c)
            nf.factors.append(gtsam.BetweenFactorDouble(self.state_key(st.name, previous), key, 0.0, nm))
            nf.values[key] = estimate.get(st.name, st.initial)

    def segment_keys(self, n: int) -> list[int]:
        """Bias and calibration variables of node ``n``'s segment."""
        c = int(self.segment[n])
        return [self.state_key(st.name, c) for st in self.variables]

    def _unary(self, nf: NodeFactors, n: int) -> None:
        """The sensors' readings at node ``n`` (:func:`~fusion_vo.backends.graph_adapter.node_factor`)."""
        xn, segment = X(self.offset + n), int(self._segment[n])
        for r, j in self.readings.at(n):
            factor = node_factor(self, r, j, xn, segment)
            if factor is not None:
                nf.factors.append(factor)
                nf.sensors.append(r.sensor)

    def count(self, nf: NodeFactors) -> None:
        counts = self.counts
        for s in nf.sensors:
            c = counts.get(s)
            if c is None:
                c = counts[s] = SensorCount()
            c.used += 1


def initial_calibration(iv: Intervals) -> dict:
    """First values of the calibration states on the node grid ``iv``, by name: every sensor's
    :attr:`~fusion_vo.sensors.registry.Sensor.first_guesses` in their order, each given those before it.

    Only initial values (the graph estimates them): without them a dead-reckoned initial trajectory
    drifts with the uncorrected gyro bias and Levenberg–Marquardt needs many damped iterations.
    """
    out: dict = {}
    for _, step in registry.ordered("first_guesses"):
        out.update(step.run(iv, out))
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
    g = config.graph
    if g.robust == "none":
        return None
    return _chi_width(float(g.robust_k), int(dof))


@functools.lru_cache(maxsize=256)
def _chi_width(k: float, dof: int) -> float | None:
    """The width of :func:`kernel_width` for the one-row width ``k`` and ``dof`` rows (cached: a streamed run builds
    a graph builder per node)."""
    if dof == 1:
        return k
    from scipy.stats import chi2  # on first use, as the filter's gate loads it (a camera-only run does not)

    p = float(chi2.cdf(k**2, 1))
    if p >= 1.0:
        return None
    return float(np.sqrt(chi2.ppf(p, dof)))
