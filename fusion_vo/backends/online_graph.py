"""iSAM2 fed one node interval at a time: the factor-graph side of :class:`~fusion_vo.backends.streaming.StreamingFusion`.

Each node's factors come from :class:`~fusion_vo.backends.graph_builder.GraphBuilder` over the node's interval
(the readings of :mod:`fusion_vo.backends.graph_adapter`), linearised at the prediction and updated as in a batch
run's ``gtsam_online`` track (:mod:`fusion_vo.backends.isam`). On the caller's thread a node is built in three
calls, or all of them on one worker thread (``background``); late data rebuilds the nodes it changes and swaps
their factors in one update (:meth:`OnlineGraph.replace`).

GPS
---
Until the fixes have fixed the heading of ENU (:func:`~fusion_vo.sensors.gps.align_to_fixes`, on the streaming
side) the poses ``X_k`` are in the frame the stream started in (``initial_pose``). At the node ``m`` where they do,
:meth:`OnlineGraph.align` adds the start frame's pose in ENU, ``T_WS`` (:func:`~fusion_vo.backends.graph_builder.T_WS`),
with the alignment as its prior (:func:`~fusion_vo.backends.world.prior_from_alignment`'s standard deviations on its
tangent), and node ``m``'s pose once more in ENU, ``Y_m``, tied to both by ``Log((T_WS X_m)⁻¹ Y_m) = 0`` (σ
:data:`BRIDGE_SIGMA`, :func:`bridge`). Every later node's pose is a variable in ENU (symbol ``x``, index
:data:`ENU_INDEX` + k), so the world frame changes once, with nothing re-keyed or re-linearised, and the information
of later fixes flows back across the switch through ``T_WS``. A fix at a node from ``m`` on is the batch graph's
factor, the GPS model of :mod:`fusion_vo.sensors.gps` on that pose (lever arm included,
:func:`~fusion_vo.backends.graph_adapter.pose_factor`) in its robust kernel, gated first
(:func:`~fusion_vo.backends.fixes.graph_gate`: ``fusion.gps``'s gate against the node's prediction and the previous
node's covariance). A fix re-acquired after ``gps_reacquire`` seconds of rejections is added without the kernel, at
its full weight, as the EKF applies it after widening its own covariance (inside the kernel, at the distance that
failed the gate, it would barely pull, and an estimate that drifted from the fixes would not come back). A late fix
placed on a node before ``m`` measures ``T_WS X_k``. Poses and covariances are reported in ENU from ``m`` on, and for the nodes before it as
``T̂_WS X̂_k`` with the covariance of that composition from the joint marginal of ``(T_WS, X_k)``
(``δY = Ad(X⁻¹) δT + δX`` in GTSAM's tangent spaces).

Why not one ``T_WS`` that every fix measures with its start-frame pose: it would sit in every clique of the Bayes
tree, and each update's back-substitution would visit them all, at a cost per node growing with the drive.
"""

from __future__ import annotations

import logging
from collections import deque
from concurrent.futures import ThreadPoolExecutor

import gtsam
import numpy as np

from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.fixes import Reacquire, graph_gate
from fusion_vo.backends.graph import add_state_sigmas, calibration_report, world_covariances
from fusion_vo.backends.graph_adapter import pose_factor
from fusion_vo.backends.graph_builder import GraphBuilder, T_WS, X
from fusion_vo.backends.isam import (Isam2Driver, current_value_lookup, estimate_lookup, freeze_custom_factors,
                                     insert_values, update_reweighted)
from fusion_vo.sensors.gps import ANTENNA, GpsModel

logger = logging.getLogger(__name__)

#: the index of node k's pose in ENU is ``ENU_INDEX + k`` (after the switch to ENU; module docstring)
ENU_INDEX = 1 << 40
#: standard deviation [m, rad] of the tie ``Y_m = T_WS X_m`` at the switch to ENU
BRIDGE_SIGMA = 1e-6


def bridge(t: int, x: int, y: int) -> gtsam.CustomFactor:
    """The factor ``e = Log((T X)⁻¹ Y)`` of ``Y = T X`` on the keys ``t, x, y`` (σ :data:`BRIDGE_SIGMA`), with GTSAM's
    own Pose2 Jacobians."""

    def error(this, values, jacobians):
        h_t, h_x, h_p, h_y, h_l = (np.zeros((3, 3), order="F") for _ in range(5))
        composed = values.atPose2(t).compose(values.atPose2(x), h_t, h_x)
        e = gtsam.Pose2.Logmap(composed.between(values.atPose2(y), h_p, h_y), h_l)
        if jacobians is not None:
            jacobians[0], jacobians[1], jacobians[2] = h_l @ h_p @ h_t, h_l @ h_p @ h_x, h_l @ h_y
        return e

    return gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(3, BRIDGE_SIGMA), [t, x, y], error)


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

    def __init__(self, config: FusionConfig, t_origin: float, background: bool = False, states: tuple = (),
                 gps=None):
        self.config = config
        self.t_origin = t_origin
        self.states = states  # the run's scalar states (registry.State)
        # QR: a heading source dropped by the monitor leaves its offset variables to a random walk alone,
        # a conditioning that Cholesky can report as indeterminate
        self.driver = Isam2Driver(gtsam.Pose2(*config.initial_pose), config.graph.reweight_passes)
        self.isam = self.driver.isam
        self.n = 0  # nodes submitted
        self.online: dict[int, np.ndarray] = {}  # node -> its pose as last computed (seeds rebuilds)
        self.last = 0  # newest node in iSAM2 (behind ``n`` while background jobs wait)
        self._forget_below = 0  # nodes before this left the history
        # background: one worker thread owns iSAM2 (it is not thread-safe); jobs run in order
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="isam2") if background else None
        self._jobs: deque = deque()
        self.gps_model = None if gps is None else GpsModel(gps, config.gps)
        self.reacquire = Reacquire(config.gps_reacquire)
        self.head: tuple | None = None  # node 0's (pose, covariance) after the first step (:meth:`step`)
        self.switch: int | None = None  # the node where ENU starts (module docstring)
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

    def _offset(self, n: int) -> int:
        """The index of node ``n - 1``'s pose in node ``n``'s interval (both of its poses are in one frame)."""
        return n - 1 + (ENU_INDEX if self.switch is not None and n > self.switch else 0)

    def key(self, n: int) -> int:
        """Node ``n``'s pose variable as reported: in ENU from the switch on (module docstring)."""
        return X(n + (ENU_INDEX if self.switch is not None and n >= self.switch else 0))

    def _node_factors(self, n: int, iv, first: bool, previous_pose, head_update: bool = False):
        """Node ``n``'s builder and factors (ending ``iv``, from ``previous_pose``), and the first node's factor indices
        in iSAM2 and sensors when they went in here. ``first``: node 1, which carries the first node's own factors
        (priors, its readings); ``head_update``: those go into iSAM2 now, in an update of their own, as a batch run
        makes it, else they are merged into the node's (a rebuild for late data swaps them all at once)."""
        offset = self._offset(n)
        builder = GraphBuilder(iv, self.config, offset=offset, t_origin=self.t_origin,
                                          states=self.states)
        # the camera's frame poses made so far (fusion_vo.sensors.visual); a node rebuilt for late data makes
        # again the ones it made (their ties go with its old factors)
        self.frames -= self.frames_made.pop(n, set())
        builder.frames = self.frames
        before = {g for g in (offset, offset + 1) if g in self.frames}  # (its interval's two nodes)
        head_in = ([], [])
        if first and head_update:
            head = builder.first_node(self.driver.estimate)
            head_in = (self.driver.add(head, self.driver.freeze(head, -1))[0], head.sensors)
            self.driver.advance(builder, 0, head, self.isam.calculateEstimatePose2(X(0)))
            previous_pose, first = self.driver.prev_pose, False
        nf = builder.node(1, previous_pose, self.driver.estimate)
        made = {g for g in (offset, offset + 1) if g in self.frames} - before
        if made:
            self.frames_made[n] = made
        if first:
            head = builder.first_node()
            head.factors.extend(nf.factors)
            head.values.update(nf.values)
            head.sensors = head.sensors + nf.sensors  # (the first node's own readings: an AHRS heading)
            nf = head
        return builder, nf, head_in

    # ------------------------------------------------------------------ one node
    def prepare(self, iv) -> list | None:
        """The factors of the next node (ending ``iv``); changes nothing (background: None, the worker
        builds them)."""
        if self._pool is not None or self._pending_first:  # (the first node's factors update iSAM2 as they are built)
            return None
        builder, nf, _ = self._node_factors(self.n + 1, iv, False, self.driver.prev_pose)
        return [builder, nf, None]

    def freeze(self, prepared: list) -> None:
        """Linearise the prepared node's custom factors at the current estimate (background: the worker does)."""
        if prepared is None:
            return
        prepared[2] = self.driver.freeze(prepared[1], self._offset(self.n + 1))

    def step(self, iv, prepared: list | None = None, fixes: list = ()):
        """Add the node ending ``iv`` (its factors from :meth:`prepare` / :meth:`freeze` when given) with the GPS
        ``fixes`` at its time, once aligned (:meth:`align`): ``(pose, covariance, sensors)``. In the background only
        the interval is handed over: pose, covariance and sensors are None and come through :meth:`collect`. The first
        node's step reports node 0 as well, once its own factors are in: :attr:`head`, its
        ``(pose, covariance)`` (background: through :meth:`collect`)."""
        self.n += 1
        if self._pool is not None:
            self._jobs.append(self._pool.submit(self._add_node, self.n, iv, None, list(fixes)))
            return None, None, None
        out = self._add_node(self.n, iv, prepared, fixes)
        self.head = out[0][1:3] if len(out) > 1 else None
        return out[-1][1:]

    def _add_node(self, n: int, iv, prepared: list | None, fixes=()):
        head, head_sensors = [], []  # the first node's factors in iSAM2, when they went in with this step
        if prepared is None:
            builder, nf, (head, head_sensors) = self._node_factors(n, iv, self._pending_first, self.driver.prev_pose,
                                                                   head_update=True)
            frozen = None
        else:
            builder, nf, frozen = prepared
        if frozen is None:
            frozen = self.driver.freeze(nf, self._offset(n))
        self._pending_first = False
        sensors, more = head_sensors + nf.sensors, None
        head_result = [(0, *self._pose_cov(0), None)] if head else []
        if fixes:  # the fixes that pass the gate, linearised at the prediction as the node's other factors
            gps = [f for fix in fixes if (f := self._fix_factor(n, nf.values[self.key(n)], fix)) is not None]
            if gps:
                more = self.driver.freeze(nf, self._offset(n), gps)
                sensors = sensors + ["gps"] * len(gps)
        self.factors[n] = head + self.driver.add(nf, frozen, more)[0]
        self.last = n
        self.node_sensors[n] = sensors
        for old in [k for k in self.factors if k < self._forget_below]:
            del self.factors[old]
            self.frames_made.pop(old, None)
            self.frames.discard(self._offset(old))  # (no later node reaches back that far)
        for kept in (self.fix_factors, self.node_sensors):
            for old in [k for k in kept if k < self._forget_below]:
                del kept[old]
        pose, cov = self._pose_cov(n)
        self.prev_cov = cov
        self.driver.advance(builder, 1, nf, gtsam.Pose2(*map(float, pose)))
        self._remember(n, pose)
        return head_result + [(n, pose, cov, sensors)]

    def _remember(self, n: int, pose: np.ndarray) -> None:
        """Node ``n``'s pose as last computed, in the frame of :meth:`key` (it seeds the rebuild of node ``n + 1``)."""
        self.online[n] = pose
        self.online.pop(n - 4096, None)  # far older than any history

    # ------------------------------------------------------------------ GPS
    def _fix_factor(self, n: int, guess: gtsam.Pose2, fix, lever=None, pose_cov=None):
        """The factor of ``fix`` at node ``n`` (pose ``guess`` of :meth:`key`; before the switch, of ``X_n``), or None
        when the gate rejects it (against the previous node's covariance, with re-acquisition). A late fix placed on
        the node comes with its own ``lever`` arm and the node's ``pose_cov``, and is only gated."""
        keys = (self.key(n),)
        if n < self.switch:  # a late fix on a node before the switch: it measures T_WS X_n
            keys = (T_WS(), X(n))
            guess = self.isam.calculateEstimatePose2(T_WS()).compose(guess)
        xyyaw = np.array([guess.x(), guess.y(), guess.theta()])
        model, noise = self.gps_model, self.gps_model.noise
        if lever is None:
            how = graph_gate(model, self.reacquire, xyyaw, fix.enu, fix.covariance, self.prev_cov, fix.t)
            if how is None:
                return None
            if how == "reacquired":  # applied at its full weight, as the EKF applies it after widening its own
                noise = noise.model_copy(update={"kernel": "none"})
        else:
            model = GpsModel(lever, noise)
            if not model.check(xyyaw, fix.enu, fix.covariance, pose_cov, fix.t).accepted:
                return None
        factor = pose_factor(ANTENNA, fix.enu, model.covariance(fix.covariance), keys,
                             {"lever_arm": model.lever_arm}, noise)
        self.fix_factors.setdefault(n, []).append(factor)
        return factor

    def align(self, world: np.ndarray, sigma: np.ndarray, fixes: list) -> list:
        """The fixes fixed the heading of ENU at the newest node: ``T_WS`` is added with the prior ``world``
        ``(x, y, ψ)`` of standard deviations ``sigma`` on its tangent, with that node's pose in ENU tied to it and to
        its start-frame pose (module docstring); then the node's ``fixes`` are gated against its ENU pose and added.
        Returns that node's result ``(n, pose, covariance, sensors)`` (background: none yet, it comes through
        :meth:`collect`)."""
        if self._pool is not None:
            self._jobs.append(self._pool.submit(self._align, np.array(world), np.array(sigma), list(fixes)))
            return []
        return self._align(world, sigma, fixes)

    def _align(self, world: np.ndarray, sigma: np.ndarray, fixes: list) -> list:
        m = self.last
        prior = gtsam.Pose2(*map(float, world))
        start = self.isam.calculateEstimatePose2(X(m))
        self.switch = m
        new = {T_WS(): prior, self.key(m): prior.compose(start)}
        g = gtsam.NonlinearFactorGraph()
        g.add(gtsam.PriorFactorPose2(T_WS(), prior, gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigma, dtype=float))))
        for f in freeze_custom_factors([bridge(T_WS(), X(m), self.key(m))],
                                       current_value_lookup(new, self.isam, start, m)):
            g.add(f)
        values = gtsam.Values()
        insert_values(values, new)
        self.isam.update(g, values)
        self.prev_cov = self._pose_cov(m)[1]
        sensors = list(self.node_sensors.get(m, []))
        guess = self.isam.calculateEstimatePose2(self.key(m))
        gps = [f for fix in fixes if (f := self._fix_factor(m, guess, fix)) is not None]
        if gps:
            weights: list = []
            g = gtsam.NonlinearFactorGraph()
            for f in freeze_custom_factors(gps, estimate_lookup(self.isam), weights=weights):
                g.add(f)
            index = update_reweighted(self.isam, g, gtsam.Values(), gps, weights,
                                      passes=self.config.graph.reweight_passes)[0]
            self.factors[m] = self.factors.get(m, []) + index
            sensors += ["gps"] * len(gps)
            self.node_sensors[m] = sensors
        pose, cov = self._pose_cov(m)
        self.prev_cov = cov
        self.driver.prev_pose = gtsam.Pose2(*map(float, pose))
        self._remember(m, pose)
        return [(m, pose, cov, sensors)]

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
        """Node ``n``'s reported pose ``(x, y, ψ)`` and its world-frame covariance: :meth:`key`'s, or ``T_WS X_n`` in
        ENU for a node before the switch to ENU (module docstring)."""
        key = self.key(n)
        pose = self.isam.calculateEstimatePose2(key)
        if self.switch is None or n >= self.switch:
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
    def replace(self, batches, passes: int = 2, fixes: dict | None = None):
        """Swap the factors of nodes ``n`` for those of their rebuilt intervals.

        ``batches`` holds ``(n, Intervals)`` in node order (nodes that exist already). The factors are
        built (seeded by node ``n-1``'s pose as last computed) and swapped now, or in a background job.
        ``fixes``: node -> late GPS fixes placed on it, ``(fix, lever arm)``, gated against the node's current
        estimate and added to its factors. Returns the results ``(n, pose, covariance, sensors)`` of a swap that
        ran (background: none yet).
        """
        if self._pool is None:
            return self._swap(batches, passes, fixes or {})
        self._jobs.append(self._pool.submit(self._swap, batches, passes, dict(fixes or {})))
        return []

    def _swap(self, batches, passes: int, fixes: dict):
        """The custom factors are linearised at the current estimate and swapped in one iSAM2 update;
        ``passes`` > 1 linearises them again at the estimate that update gave (the late data may have
        moved it) and swaps again."""
        built = []
        for n, iv in batches:
            previous = self.online[n - 1]
            if n - 1 == self.switch:  # node n's interval starts at the switch's pose in ENU
                p = self.isam.calculateEstimatePose2(self.key(n - 1))
                previous = np.array([p.x(), p.y(), p.theta()])
            builder, nf, _ = self._node_factors(n, iv, n == 1, gtsam.Pose2(*map(float, previous)))
            if fixes.get(n) and self.switch is not None:
                pose_cov = self._pose_cov(n)[1]
                for fix, lever in fixes[n]:
                    guess = self.isam.calculateEstimatePose2(self.key(n) if n >= self.switch else X(n))
                    self._fix_factor(n, guess, fix, lever, pose_cov)
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
                previous = self.isam.calculateEstimatePose2(X(self._offset(n)))
                lookup = current_value_lookup(new, self.isam, previous, self._offset(n))
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
            if self.switch is None or n > self.switch:
                self._remember(n, pose)
            elif n < self.switch:  # (the next node's interval starts at its pose in the start frame)
                p = self.isam.calculateEstimatePose2(X(n))
                self._remember(n, np.array([p.x(), p.y(), p.theta()]))
            self.node_sensors[n] = nf.sensors
            out.append((n, pose, cov, nf.sensors))
            if n == self.last:
                self.prev_cov = cov
        pose = self.isam.calculateEstimatePose2(self.key(self.last))
        if built[-1][0] == self.last:
            self.driver.advance(builder, 1, nf, pose)
        else:
            self.driver.prev_pose = pose
        return out

    def calibration(self) -> dict:
        """The calibration report of the newest node's states (their current segment's variables) with their
        marginal σ, as a batch run reports its iSAM2 track's (empty before the first node's update)."""
        builder = self.driver.builder
        if builder is None:
            return {}
        out = calibration_report(self.isam.calculateEstimate(), builder)
        add_state_sigmas(out, builder, lambda keys: [self.isam.marginalCovariance(k)[0, 0] for k in keys])
        return out

    def poses(self) -> np.ndarray:
        """Current estimates ``(x, y, yaw)`` of nodes 0 .. n (in ENU once aligned: :meth:`_pose_cov`)."""
        est = self.isam.calculateEstimate()
        if self.n == 0:
            return np.array([np.asarray(self.config.initial_pose, dtype=np.float64)])
        poses = [est.atPose2(self.key(k)) for k in range(self.n + 1)]
        if self.switch is not None:
            world = est.atPose2(T_WS())
            poses[:self.switch] = [world.compose(p) for p in poses[:self.switch]]
        return np.array([[p.x(), p.y(), p.theta()] for p in poses])

    def forget(self, n: int) -> None:
        """Node ``n`` left the history: its factors are no longer replaced."""
        self._forget_below = max(self._forget_below, n + 1)  # (the thread that owns iSAM2 drops them)
        if self._pool is None:
            self.factors.pop(n, None)
