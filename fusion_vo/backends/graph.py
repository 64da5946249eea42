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
one array operation per sensor, and the block-tridiagonal normal equations of the chain-shaped graph solved
by sweeps that also give the marginal covariances (:mod:`fusion_vo.backends.chain`, where the measurement
that keeps it is stated). A graph that is not such a chain is solved by GTSAM's own
``LevenbergMarquardtOptimizer`` with the sensor-model factors as :class:`gtsam.CustomFactor` s
(:func:`gtsam_levenberg_marquardt`): the same iteration (``tests/backends/test_solver_equals_gtsam.py``) at
about 100 times the chain loop's CPU time (``docs/decisions/0006-own-levenberg-marquardt-loop.md``).
"""

from __future__ import annotations

import logging
import time

import gtsam
import numpy as np
from threadpoolctl import threadpool_limits

from fusion_vo.backends import chain
from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.result import FusionResult
from fusion_vo.backends.fixes import GraphFixes
from fusion_vo.backends.graph_adapter import absolute_factor
from fusion_vo.backends.timeline import Intervals
from fusion_vo.measurements import PoseData
from fusion_vo.backends.states import calibration
from fusion_vo.backends.factors import (POSE_LETTERS, ModelFactor, ModelFactors, ValuesMaker, group,
                                        pose_table)
from fusion_vo.backends.graph_builder import FRAME_LETTER, GraphBuilder, X
from fusion_vo.backends.residuals import sensor_nis
from fusion_vo.backends.isam import Isam2Driver, Retired, current_value_lookup, freeze_custom_factors, isam_params

logger = logging.getLogger(__name__)


# --------------------------------------------------------------------------- batch
def gtsam_levenberg_marquardt(graph: gtsam.NonlinearFactorGraph, groups: list[ModelFactors], values: gtsam.Values,
                              max_iterations: int = 20, relative_tolerance: float = 1e-3):
    """GTSAM's ``LevenbergMarquardtOptimizer`` on the batch graph, for a graph that is not a chain.

    ``graph`` holds GTSAM's own factors, ``groups`` the sensor-model factors, given to GTSAM as
    ``gtsam.CustomFactor`` s (:meth:`~fusion_vo.backends.factors.ModelFactor.custom_factor`); the iteration
    limit and relative tolerance are the chain solver's (:func:`fusion_vo.backends.chain.levenberg_marquardt`),
    the absolute tolerance 0. Returns ``(solution, iterations, linear_graph)``, the last the graph
    linearised at the solution (:func:`gtsam_linearization`), for the marginals.
    """
    full = gtsam.NonlinearFactorGraph(graph)
    for g in groups:
        for f in g.factors:
            full.add(f.custom_factor())
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(relative_tolerance)
    params.setAbsoluteErrorTol(0.0)
    optimizer = gtsam.LevenbergMarquardtOptimizer(full, values, params)
    solution = optimizer.optimize()
    return solution, optimizer.iterations(), gtsam_linearization(graph, groups, solution)


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
    maker = ValuesMaker()
    driver = Isam2Driver(gtsam.Pose2(*builder.initial_pose()), gcfg.reweight_passes, maker) if gcfg.online else None
    isam = None if driver is None else driver.isam
    lag = gtsam.IncrementalFixedLagSmoother(gcfg.fixed_lag, isam_params()) if gcfg.fixed_lag > 0 else None
    t_online = 0.0
    t_build = time.process_time()
    estimate: dict = {} if driver is None else driver.estimate  # running guesses of the next node's variables
    estimate.update(builder.initial_estimate)
    prev_pose = gtsam.Pose2(*builder.initial_pose())
    # sensors whose factors are gated against the online estimate (GPS fixes)
    at_nodes = [(GraphFixes(builder, r), absolute_factor(r)) for r in builder.readings.absolute]
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
            for fixes, factor in at_nodes:
                fixes.add(nf, n, pose_cov, factor)
        builder.count(nf)
        incremental = isam is not None or lag is not None
        new_values = maker.make(nf.values) if lag is not None else None
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
        if driver is not None:
            frozen = driver.freeze(nf, n - 1)
            new_graph = frozen.graph
            reweighted += driver.add(nf, frozen)[1] > 0
            retired.step(isam, n)
            pose = isam.calculateEstimatePose2(X(n))
            online_poses[n] = (pose.x(), pose.y(), pose.theta())
            online_cov[n] = isam.marginalCovariance(X(n))
            driver.advance(builder, n, nf, pose)
            t_online += time.process_time() - t0
            prev_pose = pose
        else:
            if lag is not None:
                lookup = current_value_lookup(nf.values, lag, prev_pose, n - 1)
                for f in freeze_custom_factors(nf.factors, lookup, maker):
                    new_graph.add(f)
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
    for fixes, _ in at_nodes:
        fixes.finish(result)
    if isam is not None:
        result.trajectories["gtsam_online"] = PoseData(builder.t.copy(), online_poses)
        result.covariances["gtsam_online"] = world_covariances(online_poses[:, 2], online_cov)
        result.counts["gtsam_online"] = counts
        online_values = retired.complete(isam.calculateEstimate())
        result.calibration["gtsam_online"] = calibration_report(online_values, builder)
        add_state_sigmas(result.calibration["gtsam_online"], builder, lambda keys: [isam.marginalCovariance(k)[0, 0]
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
            logger.info("gtsam: GTSAM's LevenbergMarquardtOptimizer for the batch solution (%s)", exc)
            problem = None
        if problem is not None:
            with threadpool_limits(limits=1, user_api="blas"):  # small blocks: see fusion_vo.backends.chain
                solution, iters, lin = chain.levenberg_marquardt(problem, start_values, gcfg.max_iterations,
                                                                 gcfg.relative_tolerance)
        else:
            solution, iters, lin = gtsam_levenberg_marquardt(graph, groups, start_values, gcfg.max_iterations,
                                                             gcfg.relative_tolerance)
        poses = np.array([[p.x(), p.y(), p.theta()] for p in (solution.atPose2(X(n)) for n in range(n_nodes))])
        result.trajectories["gtsam"] = PoseData(builder.t.copy(), poses)
        result.counts["gtsam"] = counts
        result.calibration["gtsam"] = calibration_report(solution, builder)
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
                    add_state_sigmas(result.calibration["gtsam"], builder,
                                  lambda keys: chain.pose_marginals(lin, keys, dim=1)[:, 0, 0])
            else:
                add_state_sigmas(result.calibration["gtsam"], builder, lambda keys, m=None: [
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
    def node_of(key: int):
        n = int(gtsam.Symbol(key).index()) - builder.offset
        return n, float(builder.t[n])

    return sensor_nis(factors, values, marginals, node_of, stride)


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


def _seed_poses(values: gtsam.Values, initial: PoseData, builder: GraphBuilder) -> gtsam.Values:
    out = gtsam.Values(values)
    for n, t in enumerate(builder.t):
        p = [np.interp(t, initial.t, initial.xyyaw[:, i]) for i in range(2)]
        yaw = np.interp(t, initial.t, np.unwrap(initial.xyyaw[:, 2]))
        out.update(X(n), gtsam.Pose2(p[0], p[1], float(yaw)))
    return out


def calibration_report(values: gtsam.Values, builder: GraphBuilder) -> dict:
    """The calibration report (:func:`fusion_vo.backends.states.calibration`): each estimated state's variable of
    the last segment of ``builder`` (a batch run's, or the builder of a live run's last node)."""
    last = int(builder.segment[-1])
    found = {st.name: values.atDouble(builder.state_key(st.name, last)) for st in builder.variables
             if values.exists(builder.state_key(st.name, last))}
    return calibration(builder.iv, found)


def add_state_sigmas(out: dict, builder: GraphBuilder, variances) -> None:
    """``NAME_sigma`` in ``out`` for each estimated state (its last segment's variable), as the EKF reports it;
    ``variances(keys)`` gives their marginal variances. Nothing when the marginals fail."""
    if not builder.variables:
        return
    last = int(builder.segment[-1])
    try:
        var = variances([builder.state_key(st.name, last) for st in builder.variables])
    except RuntimeError as exc:  # an indeterminate system: the estimates stand without their sigma
        logger.warning("gtsam: no marginal variance of the states (%s)", exc)
        return
    for st, v in zip(builder.variables, var):
        out[f"{st.name}_sigma"] = float(np.sqrt(v))

