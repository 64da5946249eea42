"""StreamingFusion's node scheduling: which node is due, its interval from the buffers, the heading monitor's
decision, the backend's update, a bounded amount of work per call (:mod:`fusion_vo.backends.streaming`)."""

from __future__ import annotations

import bisect
import dataclasses
import logging

import numpy as np

from fusion_vo.backends.ekf import PlanarEkf, calibration_report, interval_readings
from fusion_vo.backends.ekf_adapter import spread_covariance
from fusion_vo.backends.result import SensorCount
from fusion_vo.backends.timeline import SensorStreams, build_intervals, fill_nodes, fix_first, step_node
from fusion_vo.geometry import se2
from fusion_vo.measurements import VisualIncrement
from fusion_vo.sensors import registry

from fusion_vo.backends.stream_state import NodeRecord, Started, extrapolate, interval_coverage

logger = logging.getLogger(__name__)


def increment_part(inc: VisualIncrement, nodes: list[float], k: int) -> VisualIncrement | None:
    """The share of a camera increment that spans several node intervals (frames dropped or failed between its
    two), ``nodes`` from its first frame to its second, over its ``k``-th interval, as a batch run applies it
    (:mod:`fusion_vo.backends.ekf_adapter`): the increment's mean twist ``ξ / T`` (``ξ = log Δ`` over its span
    ``T``) with ``n`` times its covariance per unit time, ``n`` the intervals it spans
    (:func:`~fusion_vo.backends.ekf_adapter.spread_covariance`). The part is
    ``Δ_k = exp(ξ Δt_k / T)`` with covariance ``J_k⁻¹ (n (Δt_k / T)² J Σ Jᵀ) J_k⁻ᵀ`` (``J``, ``J_k`` the
    Jacobians of ``log`` at ``Δ`` and ``Δ_k``), so that a reading over the one interval, ``log(Δ_k) / Δt_k``
    with ``J_k Σ_k J_kᵀ / Δt_k²``, is that twist and covariance.

    None when the increment states its frames' own errors (those apply to single intervals only).
    """
    if not inc.ok or inc.frame_covariance is not None:
        return None
    t0, t1 = nodes[k], nodes[k + 1]
    span = inc.t1 - inc.t0
    delta = np.asarray(inc.delta, dtype=np.float64)
    xi, J = se2.log_with_jacobian(delta)
    J = J[0]
    part = se2.exp_many(xi * ((t1 - t0) / span))[0]
    Jk_inv = se2.exp_jacobian(se2.log_many(part))[0]
    rate_cov = spread_covariance(J @ np.asarray(inc.covariance, dtype=np.float64) @ J.T, len(nodes) - 1, span)
    cov = Jk_inv @ (rate_cov * (t1 - t0) ** 2) @ Jk_inv.T  # (the one-interval reading's R Δt_k²)
    return dataclasses.replace(inc, t0=t0, t1=t1, delta=part, covariance=0.5 * (cov + cov.T))


class NodesMixin:
    """Methods of :class:`~fusion_vo.backends.streaming.StreamingFusion` (module docstring); they use its state."""

    def _advance(self, t: float) -> None:
        self._collect()
        self._latest = max(self._latest, float(t))
        lag = max((clock.lag() for clock in self._clocks), default=0.0)
        until = self._latest - self.config.reorder_window - lag
        self._process(until, self._budget(until))

    def _budget(self, until: float) -> int | None:
        """Units of work for this call: ``steps_per_call``, more while the processed state is behind.

        When the samples come in fewer calls than there are units to do (a 10 Hz odometry and a 30 Hz
        IMU, 40 calls a second, against nodes at 20 Hz of two or three units each), a fixed budget falls
        further behind with every second. Once the last node is more than two node steps behind what is
        due, the budget grows with the backlog (one more ``steps_per_call`` for every two steps behind),
        so the backlog stays bounded and the extra work per call stays small.
        """
        budget = self.steps_per_call
        if budget is None or not self._t_nodes:
            return budget
        behind = (until - self._t_nodes[-1]) * self.config.step_hz
        if behind > 2.0:
            budget *= 1 + int(behind) // 2
        return budget

    def _twist(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Body twist of the newest node predicted ``dt`` seconds ahead and its covariance (:class:`Estimate`)."""
        if self.backend == "ekf":
            kf = self._ekf.kf
            if dt <= 0:
                return self._ekf.x[3:6].copy(), self._ekf.P[3:6, 3:6].copy()
            saved = kf.x.copy(), kf.P.copy(), kf.x_prior.copy(), kf.P_prior.copy(), self._ekf.linearisation
            try:
                self._ekf.predict(dt)
                return self._ekf.x[3:6].copy(), self._ekf.P[3:6, 3:6].copy()
            finally:
                kf.x, kf.P, kf.x_prior, kf.P_prior, self._ekf.linearisation = saved
        T = self._t_nodes
        q = np.array([self.config.ekf.accel_sigma, self.config.ekf.lateral_accel_sigma,
                      self.config.ekf.yaw_accel_sigma]) ** 2
        if len(T) < 2 or T[-1] - T[-2] <= 0:
            return np.zeros(3), np.diag(q * max(dt, 1.0 / self.config.step_hz))
        step = T[-1] - T[-2]
        prev, pose = self._poses[-2], self._poses[-1]
        c, s = np.cos(prev[2]), np.sin(prev[2])
        d = pose[:2] - prev[:2]
        dyaw = np.arctan2(np.sin(pose[2] - prev[2]), np.cos(pose[2] - prev[2]))
        twist = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], dyaw]) / step
        return twist, np.diag(q * (step + max(dt, 0.0)))

    def _predict(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose and covariance of the last node predicted ``dt`` seconds ahead (constant twist)."""
        if self.backend == "ekf":
            kf = self._ekf.kf
            saved = kf.x.copy(), kf.P.copy(), kf.x_prior.copy(), kf.P_prior.copy(), self._ekf.linearisation
            try:
                self._ekf.predict(dt)
                return self._ekf.x[:3].copy(), self._ekf.P[:3, :3].copy()
            finally:
                kf.x, kf.P, kf.x_prior, kf.P_prior, self._ekf.linearisation = saved
        return extrapolate(self._t_nodes, self._poses, self._covs, dt, self.config)

    # ------------------------------------------------------------------ processing
    def _next_node(self, after: float, until: float, end: float = np.inf) -> float | None:
        """The node after ``after``: toward the next frame, the batch grid's nodes (:meth:`_fill_to`); with none
        known, a batch run's steps after its last frame (:func:`~fusion_vo.backends.timeline.step_node`), up to
        ``end``, the last sample's time, once the stream finishes (so that the nodes never depend on when the
        samples arrived). A GPS fix is a node of its own."""
        step = 1.0 / self.config.step_hz
        frames = [v.t1 for v in self._visual if v.t1 > after + 1e-9]
        fixes = [f.t for f in self._gps if f.t > after + 1e-9]
        if frames:
            nxt = fix_first(self._fill_to(after, frames[0], step), fixes[0] if fixes else None)
        else:
            nxt = step_node(after, step, end, fixes[0] if fixes else None)
        return nxt if nxt is not None and nxt <= until else None

    def _fill_to(self, after: float, anchor: float, step: float) -> float:
        """The node after ``after`` toward the next frame ``anchor``: the batch grid's fill-in nodes between the two
        (:func:`~fusion_vo.backends.timeline.fill_nodes`, kept while ``anchor`` stays the next frame)."""
        fill = self._fill
        if fill is None or fill[1] != anchor or not (fill[0] == after or np.any(fill[2] == after)):
            fill = self._fill = (after, anchor, fill_nodes(after, anchor, step))
        later = fill[2][fill[2] > after]
        return float(later[0]) if len(later) else anchor

    def _start_time(self) -> float | None:
        """The first node: the first sample's time, or the first frame's when it comes within half a step of it
        (as the batch grid starts, :func:`~fusion_vo.backends.timeline.node_times`); None before any sample (a
        fix alone does not start the track)."""
        times = [b[0][0] for b in self._buffers.values() if b] + [v.t0 for v in self._visual]
        if not times:
            return None
        start = min(times)
        frames = [v.t0 for v in self._visual if v.t0 - start <= 0.5 / self.config.step_hz]
        return min(frames) if frames else start

    def _process(self, until: float, budget: int | None = None) -> None:
        """Process the nodes up to ``until``, at most ``budget`` units of work (None: all).

        A node is two units (iSAM2: four), one more when the heading monitor's check is due at it:
        building its interval from the buffers; the check; (iSAM2: the monitor's decisions and the node's
        factors; their linearisation;) the backend's update. With iSAM2 in the background the worker
        builds and linearises the factors, but the units are the same, so late data is swapped in at the
        same points as on the caller's thread and the results agree. The operations and
        their order are those of processing the node at once; only the call that runs each differs, so
        no call pays for all of them.
        """
        if self._dirty and (budget is None or self._pending is not None
                            or self._next_node(self._t_nodes[-1], until) is not None):
            # late data is swapped in when the next node is due (several late samples, one update)
            self._drop_pending()
            dirty, self._dirty = sorted(self._dirty), set()
            self._replace(dirty)
        if not self._t_nodes:
            start = self._start_time()
            if start is None or start > until:
                return
            self._first_node(start)
        done = 0
        while budget is None or done < budget:
            done += 1
            started = self._pending
            if started is None:
                t0 = self._t_nodes[-1]
                if np.isfinite(until):
                    t1 = self._next_node(t0, until)
                    if t1 is not None and self._awaits_carried(t0, until):
                        return
                else:  # finishing: the last samples end the track
                    end = self._last_time()
                    t1 = self._next_node(t0, end, end) if np.isfinite(end) else None
                if t1 is None:
                    return
                self._begin_step(t0, t1)
            elif self._monitor.due():
                self._monitor.check()
            elif self._graph is not None and started.stage == 0:
                self._decide(started)
                started.factors = self._graph.prepare(started.iv)
                started.stage = 1
            elif self._graph is not None and started.stage == 1:
                self._graph.freeze(started.factors)
                started.stage = 2
            else:
                self._end_step()

    def _ahead(self, name: str, carry: dict) -> float:
        """Seconds after an interval's start whose samples of sensor ``name`` the interval's build reads to find the
        value that sensor carries (:class:`~fusion_vo.sensors.registry.Carry`; the AHRS's offset to the initial
        heading, averaged over its first quarter second): 0 once ``carry`` holds it."""
        sensor = registry.resolve(name)
        if sensor is None or sensor.carry is None or sensor.carry.ahead is None or name in carry:
            return 0.0
        return float(sensor.carry.ahead(self._buffers.get(name) or []))

    def _awaits_carried(self, t0: float, until: float) -> bool:
        """Whether the interval from ``t0`` waits for the samples it reads to find a carried value (:meth:`_ahead`):
        only once the processed time ``until`` has passed them are they all in, in whatever order they came."""
        return any(until < t0 + ahead for name in self._buffers if (ahead := self._ahead(name, self._carry)) > 0)

    def _part(self, inc: VisualIncrement, t0: float, t1: float) -> tuple[VisualIncrement, int, int, int] | None:
        """The share of ``inc`` over the node interval ``(t0, t1)`` (:func:`increment_part`), its nodes those
        processed from its first frame up to ``t0``, ``t1``, and the later ones up to its second frame (those
        processed already when an interval is rebuilt, else those to come, :meth:`_next_node`). With it: the node
        of its first frame (an index of the processed nodes), the place of ``(t0, t1)`` among the intervals it
        spans, and their number. None if its first frame is not a processed node or its second is not reached."""
        T = self._t_nodes
        end = bisect.bisect_right(T, t0 + 1e-9)  # the processed nodes up to t0
        done = T[:end]
        j = bisect.bisect_left(done, inc.t0 - 1e-6)
        if j >= len(done) or abs(done[j] - inc.t0) > 1e-9:
            return None
        nodes = [*done[j:], t1]
        later = list(T[end + 1:]) if end < len(T) and abs(T[end] - t1) < 1e-9 else []
        while nodes[-1] < inc.t1 - 1e-9:
            nxt = later.pop(0) if later else self._next_node(nodes[-1], np.inf)
            if nxt is None or nxt > inc.t1 + 1e-9:
                return None
            nodes.append(nxt)
        if abs(nodes[-1] - inc.t1) > 1e-9 or len(nodes) < 3:
            return None
        k = len(done) - 1 - j
        part = increment_part(inc, nodes, k)
        return None if part is None else (part, j, k, len(nodes) - 1)

    def _last_time(self) -> float:
        times = [b[-1][0] for b in self._buffers.values() if b] + [v.t1 for v in self._visual]
        return max(times) if times else -np.inf

    def _streams_between(self, t0: float, t1: float, carry: dict, reach: dict | None = None) -> SensorStreams:
        """The buffered samples an interval needs: those inside it, the ones bracketing it, and (IMU,
        range finder) the neighbours the spike check's running median reads around those (the same values
        as in batch use); until a sensor's carried value is in ``carry``, the samples it is found from after ``t0``
        too (:meth:`_ahead`: the IMU's first quarter second, when its samples carry orientations)."""
        streams = SensorStreams(camera_height=self.camera_height)
        for name, buf in self._buffers.items():
            if name == "range" and self._range_in_visual:  # used once: already in the visual increments
                continue
            live = self._intake[name].live
            more = live.neighbours(self.config) if callable(live.neighbours) else int(live.neighbours)
            lo = max(bisect.bisect_right(buf, t0, key=lambda item: item[0]) - 1 - more, 0)
            hi = bisect.bisect_left(buf, t1, key=lambda item: item[0]) + 1 + more
            ahead = self._ahead(name, carry)
            if ahead > 0:
                hi = max(hi, bisect.bisect_right(buf, t0 + ahead + self.config.max_gap, key=lambda item: item[0]) + 1)
            rows = buf[lo:hi]
            if len(rows) < live.min_rows and self._finishing:  # no later sample comes: the earlier ones, which a
                rows = buf[max(min(hi, len(buf)) - live.min_rows, 0):hi]  # batch run's hook reads too
            if reach is not None:  # the time of the last sample read (any new one, if all were read)
                reach[name] = buf[hi - 1][0] if hi <= len(buf) else np.inf
            if len(rows) < live.min_rows:
                continue
            # the sensor's own module makes its data
            streams[name] = live.data(np.array([r[0] for r in rows]), [r[1] for r in rows], self)
        return streams

    def _interval(self, t0: float, t1: float, carry: dict):
        """The node interval ``(t0, t1)`` from the buffers: ``(Intervals, step counts, consumed increments,
        time of the last sample read per stream, the factor graph's camera readings)``.

        Consumes the buffered visual increments ending at or before ``t1``: one that spans exactly this interval
        is its camera reading; one that spans it and the next intervals up to its frame gives its share
        (:func:`increment_part`); failed ones are counted missing; any other cannot be applied and is counted
        late. The EKF and the heading monitor take the shares; iSAM2 takes such an increment whole, as a batch
        run's graph does: one factor between its two frames' nodes, added with the node of its second frame
        (:meth:`_span_reading`; the last item, None when the graph takes the interval's own readings).
        """
        step: dict[str, SensorCount] = {}
        reach: dict[str, float] = {}
        streams = self._streams_between(t0, t1, carry, reach)
        consumed = [v for v in self._visual if v.t1 <= t1 + 1e-9]
        failed = sum(not v.ok for v in consumed)  # frames the frontend could not measure: nodes, counted missing
        if failed:
            step.setdefault("camera", SensorCount()).missing += failed
        usable = [v for v in consumed if v.ok and abs(v.t1 - t1) < 1e-9 and abs(v.t0 - t0) < 1e-9]
        spanning = None  # an increment over several node intervals, applied over each as a batch run does
        if not usable:
            spanning = next(((v, *p) for v in self._visual if v.ok and v.t0 <= t0 + 1e-9 and v.t1 >= t1 - 1e-9
                             and (p := self._part(v, t0, t1)) is not None), None)
        for v in consumed:
            if v.ok and v not in usable and (spanning is None or v is not spanning[0]):
                step.setdefault("camera", SensorCount()).late += 1
        self._visual = [v for v in self._visual if v.t1 > t1 + 1e-9]
        if usable:
            streams.visual = usable
        elif spanning is not None:
            streams.visual = [spanning[1]]
        # the states and scale priors the backends carry for the whole run: an interval without the camera (an
        # outage) must not drop the wheels' curvature from their model while the filter and the graph still carry it
        iv = build_intervals(streams, self.config, np.array([t0, t1]), carry, states=self._states,
                             priors=self._priors)
        if spanning is not None and spanning[0].t1 > t1 + 1e-9:  # counted used once, at its last interval
            iv.counts["camera"].used -= 1
        for sensor, c in iv.counts.items():
            own = step.setdefault(sensor, SensorCount())
            own.gated += c.gated
            own.missing += c.missing
        graph_camera = None
        # (the whole increment needs its two nodes in one frame: not across the switch to ENU)
        if spanning is not None and self.backend != "ekf" and (
                "gps" not in self.sensors or (self._switch is not None and spanning[2] >= self._switch[0])):
            inc, _, first, k, n_intervals = spanning
            graph_camera = self._span_reading(iv, inc, first, k, n_intervals)
        return iv, step, consumed, reach, graph_camera

    def _span_reading(self, iv, inc: VisualIncrement, first: int, k: int, n_intervals: int):
        """iSAM2's camera readings of the interval ``iv``, the ``k``-th of the ``n_intervals`` that ``inc`` spans from
        the processed node ``first`` on: none before its last interval; at its last, the whole increment from node
        ``first``, a reading that starts ``n_intervals - 1`` nodes before ``iv`` (a
        :class:`~fusion_vo.sensors.visual.CameraGrid` over the nodes ``1 - n_intervals`` and 1 of ``iv``), its
        translation projected with the mean slope factors of the intervals it spans, as in a batch run (an interval
        whose node has left the history counts with ``iv``'s: the span is shorter than the history by default)."""
        cam = iv.sensors["camera"]
        if k < n_intervals - 1:
            return dataclasses.replace(cam, i0=np.zeros(0, int), i1=np.zeros(0, int), delta=np.zeros((0, 3)),
                                       cov=np.zeros((0, 3, 3)), frame_cov=None)
        slopes = [rec.slope if rec is not None and rec.slope is not None else (float(iv.cx[0]), float(iv.cy[0]))
                  for rec in self._records[first + 1:first + k + 1]] + [(float(iv.cx[0]), float(iv.cy[0]))]
        cx, cy = np.array(slopes).T
        delta = np.asarray(inc.delta, dtype=np.float64).reshape(1, 3).copy()
        delta[:, 0] *= cx.mean()
        delta[:, 1] *= cy.mean()
        return dataclasses.replace(cam, i0=np.array([1 - n_intervals]), i1=np.array([1]), delta=delta,
                                   cov=np.asarray(inc.covariance, dtype=np.float64).reshape(1, 3, 3).copy(),
                                   frame_cov=None)

    def _begin_step(self, t0: float, t1: float) -> None:
        """First unit of a node: its interval from the buffers, handed to the heading monitor."""
        iv, step, consumed, reach, graph_camera = self._interval(t0, t1, self._carry)
        covered = interval_coverage(iv)  # (a camera increment over several intervals: its share covers this one)
        monitor = self._monitor.state()
        self._monitor.add(iv)  # (the monitor judges the shares of an increment over several intervals)
        if graph_camera is not None:
            iv.sensors["camera"] = graph_camera
        self._pending = Started(t0, t1, iv, step, consumed, monitor, reach, covered)

    def _decide(self, started: Started) -> None:
        """The monitor's current decisions, applied to the started node's interval."""
        if started.dropped is None:
            started.dropped = frozenset(self._monitor.dropped)
            self._monitor.apply(started.iv)

    def _end_step(self) -> None:
        """Last unit: the monitor's decisions (after its check, if due), the backend's update, the record."""
        started = self._pending
        self._pending = None
        self._monitor.check()  # (a no-op when it ran as a unit of its own)
        self._decide(started)
        iv, step = started.iv, started.step
        self._last_iv = iv
        self._step_counts = step
        self._step_fixes = []
        self._step_offered = 0
        self._carry = dict(iv.carry)
        if self.backend == "ekf":
            self._ekf_step(iv)
            state = (self._ekf.x.copy(), self._ekf.P.copy()) if self.history > 0 else None
        else:
            self._graph_step(iv, started.factors)
            state = None
        t0 = self._t_nodes[-1]
        self._covered.append(started.covered)
        self._t_nodes.append(started.t1)
        keep = state is not None
        self._records.append(NodeRecord(state, dict(self._carry), step, started.consumed,
                                         monitor=self._monitor.state() if keep else None, dropped=started.dropped,
                                         fixes=self._step_fixes, gps=self._gps_state() if keep else None,
                                         offered=self._step_offered, slope=(float(iv.cx[0]), float(iv.cy[0])),
                                         reach=started.reach))
        self._retire()
        self._prune(t0)

    # ------------------------------------------------------------------ backends
    def _first_node(self, t: float) -> None:
        cfg = self.config
        self._t_nodes.append(t)
        if self.backend == "ekf":
            # (the filter is sized before any reading: the camera's readings state their frame errors when it is
            # fused with stated frame covariances or a frame-error share f > 0, as in a batch run)
            frame_errors = "camera" in self.sensors and (self._camera_frame_errors or cfg.visual_frame_error > 0)
            self._ekf = PlanarEkf(cfg, states=self._states, frame_errors=frame_errors)
            self._records.append(NodeRecord((self._ekf.x.copy(), self._ekf.P.copy()), {},
                                             monitor=self._monitor.state(), gps=self._gps_state()))
            self._record(self._ekf.x[:3], self._ekf.P[:3, :3])
        else:
            self._records.append(NodeRecord(None, {}))
            self._graph = self._online_graph(cfg, t, self.background, self._states,
                                             self._gps_lever if "gps" in self.sensors else None)
            pose, cov = self._graph.start()
            self._record(pose, cov)

    def _calibration(self) -> dict:
        """The calibration report of the states the backend carries, at the newest node
        (``FusionResult.calibration``: each estimated state, ``NAME_sigma``, the figures derived from it), as a
        batch run reports its online track's."""
        if self._last_iv is None:
            return {}
        if self.backend == "ekf":
            return calibration_report(self._ekf.x, self._ekf.P, self._last_iv)
        return self._graph.calibration()

    def _record(self, pose, cov) -> None:
        self._poses.append(np.asarray(pose, dtype=np.float64).copy())
        self._covs.append(np.asarray(cov, dtype=np.float64).copy())

    def _ekf_step(self, iv) -> None:
        ekf = self._ekf
        readings = interval_readings(iv, self.config)
        if len(self._t_nodes) == 1 and ekf.begin(readings):
            # the first interval: the readings at the first node (an AHRS heading) as a batch run applies them;
            # node 0's record keeps the state from before them, so a rewind to it applies them again
            self._poses[0], self._covs[0] = ekf.x[:3].copy(), ekf.P[:3, :3].copy()
        ekf.step(readings, 0)
        for fix in self._due_fixes(float(iv.t[-1])):
            self._apply_gps(fix)
        for sensor, c in ekf.counts.items():
            own = self._step_counts.setdefault(sensor, SensorCount())
            own.used += c.used
            own.gated += c.gated
        ekf.counts = {}
        self._record(ekf.x[:3], ekf.P[:3, :3])

    def _due_fixes(self, t1: float) -> list:
        """The queued fixes up to the node at ``t1`` leave the queue (kept in the node's record): those at it are
        returned; those at the first node, while the heading of ENU is unknown, are kept for the alignment (as a fix
        that does not fit yet is, :meth:`_align_world`: counted missing); any other before it is counted late (behind
        the last node already: it cannot be applied causally)."""
        due = []
        first = self._t_nodes[0] if len(self._t_nodes) == 1 and self._frame == "start" else None
        for fix in [f for f in self._gps if f.t <= t1 + 1e-3]:
            self._gps.remove(fix)
            self._step_fixes.append(fix)
            if abs(fix.t - t1) <= 1e-3:
                due.append(fix)
            elif first is not None and abs(fix.t - first) <= 1e-3:
                self._gps_seen.append(fix)
                self._step_counts.setdefault("gps", SensorCount()).missing += 1
            else:
                self._step_counts.setdefault("gps", SensorCount()).late += 1
        return due

    def _graph_step(self, iv, prepared=None) -> None:
        """iSAM2's update of the node ending ``iv``, with its fixes once ENU is aligned; before that a fix is kept for
        the alignment, which, once it fits, re-expresses the poses in ENU and adds the world frame to iSAM2
        (:meth:`~fusion_vo.backends.online_graph.OnlineGraph.align`, with that fix)."""
        fixes = self._due_fixes(float(iv.t[-1]))
        offered = fixes if self._frame == "enu" else []
        self._step_offered = len(offered)
        pose, cov, sensors = self._graph.step(iv, prepared, offered)
        if self._graph.head is not None:  # node 0 once its own factors are in (the first step)
            self._poses[0], self._covs[0] = self._graph.head
        if pose is None:  # background update under way: the last pose predicted meanwhile
            pose, cov = extrapolate(self._t_nodes, self._poses, self._covs, float(iv.t[-1]) - self._t_nodes[-1],
                                     self.config)
        self._used_from(self._step_counts, sensors, self._step_offered)
        self._record(pose, cov)
        for k, fix in enumerate(fixes if self._frame == "start" else ()):
            if self.background:  # the poses the alignment fits are iSAM2's, not the ones predicted meanwhile
                self._collect(wait=True)
            aligned = self._align_world(fix)
            if aligned is not None:
                fit, sigma = aligned
                self._to_enu(fit, fix.t)
                self._switch = (len(self._t_nodes), fit.yaw)
                self._step_offered = len(fixes) - k
                for n, pose, cov, sensors in self._graph.align(np.array([*fit.offset, fit.yaw]), sigma, fixes[k:]):
                    self._poses[n], self._covs[n] = pose, cov
                    self._used_from(self._step_counts, sensors, self._step_offered)
                break

    def _collect(self, wait: bool = False) -> None:
        """Take in the results of finished background iSAM2 updates (all of them with ``wait``)."""
        if self._graph is None or not self.background:
            return
        for n, pose, cov, sensors in self._graph.collect(wait):
            if n < len(self._poses):
                self._poses[n], self._covs[n] = pose, cov
            self._count_used(n, sensors)

    def _count_used(self, n: int, sensors) -> None:
        """Node ``n``'s factors are now those of ``sensors`` (None: unchanged): its ``used`` counts follow."""
        if sensors is None:
            return
        if n == len(self._records):  # the node being processed (its record comes at the end of its step)
            self._used_from(self._step_counts, sensors, self._step_offered)
            return
        rec = self._records[n] if n < len(self._records) else None
        if rec is None:  # left the history while its update ran: its counts were merged already
            return
        self._used_from(rec.counts, sensors, rec.offered)

    @staticmethod
    def _used_from(counts: dict, sensors, offered: int = 0) -> None:
        """``counts`` of a node whose factors are those of ``sensors`` (None: unchanged): one use per factor, and of
        the ``offered`` fixes those without a factor gated."""
        if sensors is None:
            return
        for c in counts.values():
            c.used = 0
        for s in sensors:
            counts.setdefault(s, SensorCount()).used += 1
        if offered:
            counts.setdefault("gps", SensorCount()).gated = offered - sum(s == "gps" for s in sensors)
