"""iSAM2 fed one node interval at a time: the factor-graph side of :class:`~fusion_vo.backends.streaming.StreamingFusion`.

Each node's factors come from :class:`~fusion_vo.backends.graph_builder.GraphBuilder` over the node's interval
(the readings of :mod:`fusion_vo.backends.graph_adapter`), linearised at the prediction and updated as in a batch
run's ``gtsam_online`` track (:mod:`fusion_vo.backends.isam`). On the caller's thread a node is built in three
calls, or all of them on one worker thread (``background``); late data rebuilds the nodes it changes and swaps
their factors in one update (:meth:`OnlineGraph.replace`).

GPS
---
The poses ``X_k`` stay in the frame the stream started in (``initial_pose``), as every sensor but GPS measures
them. Once the fixes have fixed the heading of ENU (:func:`~fusion_vo.sensors.gps.align_to_fixes`, on the
streaming side), :meth:`OnlineGraph.align` adds one Pose2 variable ``T_WS`` (:func:`~fusion_vo.backends.graph_builder.T_WS`),
the start frame's pose in ENU, with the alignment as its prior (:func:`~fusion_vo.backends.world.prior_from_alignment`'s
standard deviations on its tangent), and from then on a fix at node ``k`` measures the antenna at the ENU pose
``T_WS X_k``: the GPS measurement model of :mod:`fusion_vo.sensors.gps` (lever arm included) on that composition
(:func:`~fusion_vo.backends.graph_adapter.pose_factor`), in its robust kernel, gated first
(:func:`~fusion_vo.backends.fixes.graph_gate`: ``fusion.gps``'s gate against the prediction ``T̂_WS X̂_k`` and the
previous node's ENU covariance, re-acquisition after ``gps_reacquire`` seconds of rejections). The poses reported
are then ``T̂_WS X̂_k`` with the covariance of that composition from the joint marginal of ``(T_WS, X_k)``:
``δY = Ad(X⁻¹) δT + δX`` in GTSAM's tangent spaces. A rigid change of the world frame leaves every other factor as
it was, so nothing is re-linearised or re-keyed when the frame changes, and late data rebuilds a node with its
fix's factor as it was gated.
"""

from __future__ import annotations

import logging
from collections import deque
from concurrent.futures import ThreadPoolExecutor

import gtsam
import numpy as np

from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.fixes import Reacquire, graph_gate
from fusion_vo.backends.graph import world_covariances
from fusion_vo.backends.graph_adapter import pose_factor
from fusion_vo.backends.graph_builder import GraphBuilder, T_WS, X
from fusion_vo.backends.isam import (current_value_lookup, estimate_lookup, freeze_custom_factors, insert_values,
                                     isam_params, track_estimate, update_reweighted)
from fusion_vo.sensors.gps import ANTENNA, GpsModel

logger = logging.getLogger(__name__)


class OnlineGraph:
    """iSAM2 fed one node interval at a time through :class:`~fusion_vo.backends.graph_builder.GraphBuilder`.

    On the caller's thread a node is built in three calls: :meth:`prepare` (its factors),
    :meth:`freeze` (their linearisation at the current estimate), :meth:`step` (the iSAM2 update). With
    ``background`` one worker thread owns iSAM2 and runs all three, and the rebuilds of :meth:`replace`,
    in the order they were submitted, from the same state: the estimates are those of the caller-thread
    run, whatever the worker's timing.

    ``gps``: the antenna's lever arm in the body frame when fixes are fused (module docstring); the gate, its
    counters and the re-acquisition are this object's, so a worker thread decides as the caller's thread would.
    """

    def __init__(self, config: FusionConfig, t_origin: float, calibrate: tuple[bool, bool], background: bool = False,
                 states: tuple = (), gps=None):
        self.config = config
        self.t_origin = t_origin
        self.calibrate = calibrate
        self.states = states  # the sensors' own state variables (registry.State)
        # QR: a heading source dropped by the monitor leaves its offset variables to a random walk alone,
        # a conditioning that Cholesky can report as indeterminate
        self.isam = gtsam.ISAM2(isam_params())
        self.n = 0  # nodes submitted
        self.estimate: dict = {}  # running bias / calibration estimates (guesses of the next node)
        self.prev_pose = gtsam.Pose2(*config.initial_pose)  # iSAM2's estimate of the newest node
        self.online: dict[int, np.ndarray] = {}  # node -> its pose as last computed (seeds rebuilds)
        self.last = 0  # newest node in iSAM2 (behind ``n`` while background jobs wait)
        self._forget_below = 0  # nodes before this left the history
        # background: one worker thread owns iSAM2 (it is not thread-safe); jobs run in order
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="isam2") if background else None
        self._jobs: deque = deque()
        self.gps_model = None if gps is None else GpsModel(gps, config.gps)
        self.reacquire = Reacquire(config.gps_reacquire)
        self.aligned = False  # T_WS exists: the reported poses are in ENU
        self.prev_cov: np.ndarray | None = None  # reported covariance of the newest node (the fixes' gate)
        self.fix_factors: dict[int, list] = {}  # node -> its fixes' factors (a rebuilt node keeps them)
        self.node_sensors: dict[int, list] = {}  # node -> the sensors of its factors

    def start(self):
        cfg = self.config
        # the first node's own factors come with the first interval (which knows the sensors)
        self._pending_first = True
        self.factors: dict[int, list[int]] = {}  # node -> indices of its factors in iSAM2
        self.frames: set[int] = set()  # nodes whose camera frame pose exists
        self.frames_made: dict[int, set[int]] = {}  # node -> the frame poses its factors tie
        self.online[0] = np.asarray(cfg.initial_pose, dtype=np.float64)
        return self.online[0].copy(), np.diag([1e-8, 1e-8, 1e-8])

    def _node_factors(self, n: int, iv, first: bool, previous_pose):
        builder = GraphBuilder(iv, self.config, offset=n - 1, t_origin=self.t_origin,
                                          calibrate=self.calibrate, states=self.states)
        # the camera's frame poses made so far (fusion_vo.sensors.visual); a node rebuilt for late data makes
        # again the ones it made (their ties go with its old factors)
        self.frames -= self.frames_made.pop(n, set())
        builder.frames = self.frames
        before = {g for g in (n - 1, n) if g in self.frames}  # (its interval's two nodes)
        nf = builder.node(1, previous_pose, self.estimate)
        made = {g for g in (n - 1, n) if g in self.frames} - before
        if made:
            self.frames_made[n] = made
        if first:
            head = builder.first_node()
            head.factors.extend(nf.factors)
            head.values.update(nf.values)
            head.sensors = nf.sensors
            nf = head
        return builder, nf

    # ------------------------------------------------------------------ one node
    def prepare(self, iv) -> list | None:
        """The factors of the next node (ending ``iv``); changes nothing (background: None, the worker
        builds them)."""
        if self._pool is not None:
            return None
        builder, nf = self._node_factors(self.n + 1, iv, self._pending_first, self.prev_pose)
        return [builder, nf, None, None]

    def freeze(self, prepared: list) -> None:
        """Linearise the prepared node's custom factors at the current estimate (background: the worker does)."""
        if prepared is None:
            return
        n, nf = self.n + 1, prepared[1]
        lookup = current_value_lookup(nf.values, self.isam, self.prev_pose, n - 1)
        prepared[3] = []
        prepared[2] = freeze_custom_factors(nf.factors, lookup, weights=prepared[3])

    def step(self, iv, prepared: list | None = None, fixes: list = ()):
        """Add the node ending ``iv`` (its factors from :meth:`prepare` / :meth:`freeze` when given) with the GPS
        ``fixes`` at its time, once aligned (:meth:`align`): ``(pose, covariance, sensors)``. In the background only
        the interval is handed over: pose, covariance and sensors are None and come through :meth:`collect`."""
        self.n += 1
        if self._pool is not None:
            self._jobs.append(self._pool.submit(self._add_node, self.n, iv, None, list(fixes)))
            return None, None, None
        return self._add_node(self.n, iv, prepared, fixes)[0][1:]

    def _add_node(self, n: int, iv, prepared: list | None, fixes=()):
        if prepared is None:
            prepared = self._node_factors(n, iv, self._pending_first, self.prev_pose) + (None, None)
        builder, nf, frozen, weights = prepared
        if frozen is None:
            lookup = current_value_lookup(nf.values, self.isam, self.prev_pose, n - 1)
            weights = []
            frozen = freeze_custom_factors(nf.factors, lookup, weights=weights)
        self._pending_first = False
        factors, sensors = nf.factors, nf.sensors
        if fixes:  # the fixes that pass the gate, linearised at the prediction as the node's other factors
            lookup = current_value_lookup(nf.values, self.isam, self.prev_pose, n - 1)
            gps = [f for fix in fixes if (f := self._fix_factor(n, nf.values[X(n)], fix)) is not None]
            if gps:
                weights = list(weights)
                frozen = list(frozen) + freeze_custom_factors(gps, lookup, weights=weights)
                factors, sensors = factors + gps, sensors + ["gps"] * len(gps)
        g = gtsam.NonlinearFactorGraph()
        for f in frozen:
            g.add(f)
        values = gtsam.Values()
        insert_values(values, nf.values)
        # the robust weights at the updated estimate, as the whole-recording iSAM2 (graph.update_reweighted)
        self.factors[n] = update_reweighted(self.isam, g, values, factors, weights,
                                                       passes=self.config.graph.reweight_passes)[0]
        self.last = n
        self.node_sensors[n] = sensors
        for old in [k for k in self.factors if k < self._forget_below]:
            del self.factors[old]
            self.frames_made.pop(old, None)
            self.frames.discard(old - 1)  # (no later node reaches back that far)
        for kept in (self.fix_factors, self.node_sensors):
            for old in [k for k in kept if k < self._forget_below]:
                del kept[old]
        pose, cov = self._pose_cov(n)
        self.prev_cov = cov
        start = self._start_pose(n)
        self.prev_pose = gtsam.Pose2(*map(float, start))
        track_estimate(self.estimate, self.isam, builder, 1, nf)
        self._remember(n, start)
        return [(n, pose, cov, sensors)]

    def _remember(self, n: int, pose: np.ndarray) -> None:
        """Node ``n``'s pose in the start frame as last computed (it seeds the rebuilds)."""
        self.online[n] = pose
        self.online.pop(n - 4096, None)  # far older than any history

    def _start_pose(self, n: int) -> np.ndarray:
        """iSAM2's estimate of ``X_n`` (the start frame) as ``(x, y, ψ)``."""
        p = self.isam.calculateEstimatePose2(X(n))
        return np.array([p.x(), p.y(), p.theta()])

    # ------------------------------------------------------------------ GPS
    def _fix_factor(self, n: int, guess: gtsam.Pose2, fix):
        """The factor of ``fix`` at node ``n`` (start-frame pose ``guess``), or None when the gate rejects it."""
        world = self.isam.calculateEstimatePose2(T_WS())
        pose = world.compose(guess)
        if not graph_gate(self.gps_model, self.reacquire, np.array([pose.x(), pose.y(), pose.theta()]), fix.enu,
                          fix.covariance, self.prev_cov, fix.t):
            return None
        factor = pose_factor(ANTENNA, fix.enu, self.gps_model.covariance(fix.covariance), (T_WS(), X(n)),
                             {"lever_arm": self.gps_model.lever_arm}, self.gps_model.noise)
        self.fix_factors.setdefault(n, []).append(factor)
        return factor

    def align(self, world: np.ndarray, sigma: np.ndarray, fixes: list) -> list:
        """The fixes fixed the heading of ENU at the newest node: ``T_WS`` is added with the prior ``world``
        ``(x, y, ψ)`` of standard deviations ``sigma`` on its tangent, then the newest node's ``fixes`` are gated
        against its ENU pose and added. Returns that node's result ``(n, pose, covariance, sensors)`` (background:
        none yet, it comes through :meth:`collect`)."""
        if self._pool is not None:
            self._jobs.append(self._pool.submit(self._align, np.array(world), np.array(sigma), list(fixes)))
            return []
        return self._align(world, sigma, fixes)

    def _align(self, world: np.ndarray, sigma: np.ndarray, fixes: list) -> list:
        n = self.last
        prior = gtsam.Pose2(*map(float, world))
        g = gtsam.NonlinearFactorGraph()
        g.add(gtsam.PriorFactorPose2(T_WS(), prior, gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigma, dtype=float))))
        values = gtsam.Values()
        values.insert(T_WS(), prior)
        self.isam.update(g, values)
        self.aligned = True
        pose, cov = self._pose_cov(n)
        self.prev_cov = cov
        sensors = list(self.node_sensors.get(n, []))
        guess = self.isam.calculateEstimatePose2(X(n))
        gps = [f for fix in fixes if (f := self._fix_factor(n, guess, fix)) is not None]
        if gps:
            weights: list = []
            g = gtsam.NonlinearFactorGraph()
            for f in freeze_custom_factors(gps, estimate_lookup(self.isam), weights=weights):
                g.add(f)
            index = update_reweighted(self.isam, g, gtsam.Values(), gps, weights,
                                      passes=self.config.graph.reweight_passes)[0]
            self.factors[n] = self.factors.get(n, []) + index
            sensors += ["gps"] * len(gps)
            self.node_sensors[n] = sensors
            pose, cov = self._pose_cov(n)
            self.prev_cov = cov
        start = self._start_pose(n)
        self.prev_pose = gtsam.Pose2(*map(float, start))
        self._remember(n, start)
        return [(n, pose, cov, sensors)]

    def has_jobs(self) -> bool:
        """Whether background results are still to be collected."""
        return bool(self._jobs)

    def collect(self, wait: bool = False) -> list:
        """Results ``(n, pose, covariance, sensors)`` of the finished background jobs, in order."""
        out = []
        while self._jobs and (wait or self._jobs[0].done()):
            out += self._jobs.popleft().result()
        return out

    def _pose_cov(self, n: int):
        """Node ``n``'s reported pose ``(x, y, ψ)`` and its world-frame covariance: ``X_n``, or ``T_WS X_n`` in ENU
        once aligned (module docstring)."""
        key = X(n)
        pose = self.isam.calculateEstimatePose2(key)
        if not self.aligned:
            cov = world_covariances(np.array([pose.theta()]), self.isam.marginalCovariance(key)[None])[0]
            return np.array([pose.x(), pose.y(), pose.theta()]), cov
        t = T_WS()
        joint = self.isam.jointMarginalCovariance([t, key])
        both = np.block([[joint.at(t, t), joint.at(t, key)], [joint.at(key, t), joint.at(key, key)]])
        J = np.hstack([pose.inverse().AdjointMap(), np.eye(3)])
        enu = self.isam.calculateEstimatePose2(t).compose(pose)
        cov = world_covariances(np.array([enu.theta()]), (J @ both @ J.T)[None])[0]
        return np.array([enu.x(), enu.y(), enu.theta()]), cov

    # ------------------------------------------------------------------ late data
    def replace(self, batches, passes: int = 2):
        """Swap the factors of nodes ``n`` for those of their rebuilt intervals.

        ``batches`` holds ``(n, Intervals)`` in node order (nodes that exist already). The factors are
        built (seeded by node ``n-1``'s pose as last computed) and swapped now, or in a background job.
        Returns the results ``(n, pose, covariance, sensors)`` of a swap that ran (background: none yet).
        """
        if self._pool is None:
            return self._swap(batches, passes)
        self._jobs.append(self._pool.submit(self._swap, batches, passes))
        return []

    def _swap(self, batches, passes: int):
        """The custom factors are linearised at the current estimate and swapped in one iSAM2 update;
        ``passes`` > 1 linearises them again at the estimate that update gave (the late data may have
        moved it) and swaps again."""
        built = []
        for n, iv in batches:
            builder, nf = self._node_factors(n, iv, n == 1, gtsam.Pose2(*map(float, self.online[n - 1])))
            gps = self.fix_factors.get(n, [])  # the node's fixes, as they were gated
            nf.factors.extend(gps)
            nf.sensors.extend(["gps"] * len(gps))
            built.append((n, nf, builder))
        builder, nf = built[-1][2], built[-1][1]
        new_keys: set = set()
        for p in range(passes):
            g = gtsam.NonlinearFactorGraph()
            values = gtsam.Values()
            remove, sizes = [], []
            for n, nf, _ in built:
                new = {k: v for k, v in nf.values.items() if not self.isam.valueExists(k) and not values.exists(k)}
                new_keys.update(new)
                previous = self.isam.calculateEstimatePose2(X(n - 1))
                lookup = current_value_lookup(new, self.isam, previous, n - 1)
                frozen = freeze_custom_factors(nf.factors, lookup)
                for f in frozen:
                    g.add(f)
                insert_values(values, new)
                remove += self.factors.get(n, [])
                sizes.append(len(frozen))
            index = list(self.isam.update(g, values, remove).getNewFactorsIndices())
            for (n, _, _), size in zip(built, sizes):
                self.factors[n], index = index[:size], index[size:]
        out = []
        for n, nf, _ in built:
            pose, cov = self._pose_cov(n)
            self._remember(n, self._start_pose(n))
            self.node_sensors[n] = nf.sensors
            out.append((n, pose, cov, nf.sensors))
            if n == self.last:
                self.prev_cov = cov
        self.prev_pose = self.isam.calculateEstimatePose2(X(self.last))
        if built[-1][0] == self.last:
            track_estimate(self.estimate, self.isam, builder, 1, nf)
        return out

    def poses(self) -> np.ndarray:
        """Current estimates ``(x, y, yaw)`` of nodes 0 .. n (``T̂_WS X̂_k`` in ENU once aligned)."""
        est = self.isam.calculateEstimate()
        if self.n == 0:
            return np.array([np.asarray(self.config.initial_pose, dtype=np.float64)])
        poses = [est.atPose2(X(k)) for k in range(self.n + 1)]
        if self.aligned:
            world = est.atPose2(T_WS())
            poses = [world.compose(p) for p in poses]
        return np.array([[p.x(), p.y(), p.theta()] for p in poses])

    def forget(self, n: int) -> None:
        """Node ``n`` left the history: its factors are no longer replaced."""
        self._forget_below = max(self._forget_below, n + 1)  # (the thread that owns iSAM2 drops them)
        if self._pool is None:
            self.factors.pop(n, None)
