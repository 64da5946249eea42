"""StreamingFusion's history: late data rewinds the EKF or rebuilds iSAM2's nodes, old nodes retire, GPS's
switch to ENU is undone when a rewind goes back across it (:mod:`fusion_vo.backends.streaming`)."""

from __future__ import annotations

import bisect
import logging
import math

import numpy as np

from fusion_vo.backends.result import SensorCount
from fusion_vo.measurements import (
    GpsData, GpsFix,
)
from fusion_vo.backends.ekf import YAW
from fusion_vo.backends.world import prior_from_alignment
from fusion_vo.backends.fixes import OUTAGE_NOTE_S, Reacquire, outage_note
from fusion_vo.sensors import registry
from fusion_vo.sensors.gps import align_to_fixes
from fusion_vo.sensors.gps import predict as gps_predict

from fusion_vo.backends.stream_state import interval_coverage, merge_counts

logger = logging.getLogger(__name__)


class HistoryMixin:
    """Methods of :class:`~fusion_vo.backends.streaming.StreamingFusion` (module docstring); they use its state."""

    # ------------------------------------------------------------------ history (EKF rewind)
    def _rewind_index(self, t: float, back: int, first: int | None = None) -> int | None:
        """The node to re-filter from for a measurement at ``t``, or None if it is beyond the history (or
        more than ``max_gap`` before the first node, even while the track is younger than the history).

        A sample at ``t`` changes the interval that contains it and, through interpolation at that
        interval's start, the one before; so the filter restarts ``back=2`` nodes before ``t``. A visual
        increment is applied from its ``t0`` node (``back=0``). ``first``: the first node whose interval reads the
        sample (:meth:`_first_reader`), to restart from the node before it instead.
        """
        if self.history <= 0 or t < self._t_nodes[0] - self.config.max_gap:
            return None  # (a sample that far before the first node would be interpolated across the gap)
        i = max(bisect.bisect_left(self._t_nodes, t - 1e-9) - back, 0) if first is None else first - 1
        if self._records[i] is None or self._t_nodes[-1] - self._t_nodes[i] > self.history + 1e-9:
            return None
        return i

    def _rewind(self, i: int) -> None:
        """Restore the filter to node ``i`` and forget the nodes after it (their inputs stay buffered)."""
        self._drop_pending()
        rec = self._records[i]
        for later in self._records[i + 1:]:
            for v in later.visual:
                bisect.insort(self._visual, v, key=lambda inc: inc.t1)
        self._rewind_gps(i, rec.gps)
        x, P = rec.state
        self._ekf.kf.x = x.reshape(-1, 1).copy()
        self._ekf.kf.P = P.copy()
        self._ekf.linearisation = None  # that node's prediction is not the last one made
        self._carry = dict(rec.carry)
        if rec.monitor is not None:
            self._monitor.restore(rec.monitor)
        del self._t_nodes[i + 1:], self._poses[i + 1:], self._covs[i + 1:], self._records[i + 1:], self._covered[i:]
        self.rewinds += 1

    def _drop_pending(self) -> None:
        """Undo the started node (its increments go back to the buffer, the monitor to its state before)."""
        started, self._pending = self._pending, None
        if started is None:
            return
        for v in started.consumed:
            bisect.insort(self._visual, v, key=lambda inc: inc.t1)
        self._monitor.restore(started.monitor)

    def _replace(self, nodes: list[int]) -> None:
        """iSAM2: rebuild the intervals ending at ``nodes`` from the buffers (late data now in them) and
        swap their factors in one update; their recorded poses become iSAM2's estimates after it."""
        batches = []
        for j in nodes:
            rec = self._records[j]
            if rec is None or self._records[j - 1] is None:  # left the history meanwhile
                continue
            for v in rec.visual:
                bisect.insort(self._visual, v, key=lambda inc: inc.t1)
            prev = self._records[j - 1]
            iv, step, consumed, rec.reach, graph_camera = self._interval(self._t_nodes[j - 1], self._t_nodes[j],
                                                                          prev.carry)
            self._covered[j - 1] = interval_coverage(iv)  # (before the monitor's decisions, as when first processed)
            if "gps" in rec.counts:  # the node's fixes are not in its interval: their counts stay
                step["gps"] = rec.counts["gps"]
            rec.counts, rec.visual = step, consumed
            rec.slope = (float(iv.cx[0]), float(iv.cy[0]))
            self._monitor.update(j - 1, iv)
            self._monitor.apply(iv, rec.dropped)  # the decision taken when the node was first processed
            if graph_camera is not None:
                iv.sensors["camera"] = graph_camera
            rec.carry = dict(iv.carry)  # (iv was built from prev's)
            if self._switch is not None and j == self._switch[0]:
                rec.carry = registry.turned(rec.carry, self._switch[1])  # (the interval after it starts in ENU)
            batches.append((j, iv))
        late = {j: self._late_fixes.pop(j) for j, _ in batches if j in self._late_fixes}
        for j in list(self._late_fixes):  # (their node left the history meanwhile)
            self._retired_counts.setdefault("gps", SensorCount()).late += len(self._late_fixes.pop(j))
        if not batches:
            return
        self._carry = dict(self._records[-1].carry)
        for j, pose, cov, used in self._graph.replace(batches, fixes=late):
            self._poses[j], self._covs[j] = pose, cov
            self._count_used(j, used)
        self.rewinds += 1

    def _late_fix(self, fix: GpsFix) -> None:
        """iSAM2: a fix at or before the last processed node, within the history, re-timed onto the nearest node
        ``a`` (at most a node step away) as a late camera increment is: the antenna at the fix's time is at
        ``h(s) = s_t + R(s_ψ) l`` in node ``a``'s body frame (:func:`~fusion_vo.sensors.gps.predict` of the wheels'
        and gyro's motion ``s`` from the node to the fix, :meth:`_sliver`), which is the fix's lever arm at that node;
        its covariance grows by that motion's variance (the heading's through the lever arm). Node ``a`` is rebuilt
        with it (:meth:`_replace`), gated against iSAM2's estimate of that node (not re-acquired). Before the
        alignment the fix is kept for it as an in-order one is (missing), one at the first node too; any other fix that
        cannot be placed is late."""
        T = self._t_nodes
        k = bisect.bisect_left(T, fix.t)
        a = min((j for j in (k - 1, k) if 0 <= j < len(T)), key=lambda j: abs(T[j] - fix.t))
        rec = self._records[a]
        sliver = None
        if a > 0 and rec is not None and self._records[a - 1] is not None \
                and abs(T[a] - fix.t) <= 1.0 / self.config.step_hz:
            sliver = self._sliver(T[a], fix.t)
        if sliver is None and self._frame == "start" and a == 0 and abs(T[0] - fix.t) <= 1e-3:
            bisect.insort(self._gps_seen, fix, key=lambda f: f.t)  # at the first node: kept for the alignment
            self._count("gps").missing += 1
            return
        if sliver is None:
            self._count("gps").late += 1
            logger.warning("gps fix at t=%.3f arrived after t=%.3f was processed and could not be placed on a node; "
                           "not applied", fix.t, T[-1])
            return
        if self._frame == "start":
            bisect.insort(self._gps_seen, fix, key=lambda f: f.t)
            if self.background:  # the poses the alignment fits are iSAM2's, not the ones predicted meanwhile
                self._collect(wait=True)
            aligned = self._fit_world(np.array(T), np.array(self._poses), T[-1])
            if aligned is None:
                rec.counts.setdefault("gps", SensorCount()).missing += 1  # kept for the alignment
                return
            fit, sigma = aligned
            self._to_enu(fit, fix.t)
            self._switch = (len(T) - 1, fit.yaw)
            # the next node's interval starts in ENU
            self._records[-1].carry = registry.turned(self._records[-1].carry, fit.yaw)
            for n, pose, cov, used in self._graph.align(np.array([*fit.offset, fit.yaw]), sigma, []):
                self._poses[n], self._covs[n] = pose, cov
        motion, var = sliver
        lever = gps_predict(motion, self._gps_lever)
        cov = fix.covariance + np.eye(2) * (max(var[0], var[1]) + var[2] * float(lever @ lever))
        rec.offered += 1
        self._late_fixes.setdefault(a, []).append((GpsFix(fix.t, fix.enu, cov), lever))
        self._dirty.add(a)

    def _retire(self) -> None:
        """Drop the rewind data of nodes older than the history (their counts are kept)."""
        horizon = self._t_nodes[-1] - self.history - 1e-9
        for j in range(len(self._records) - 1, -1, -1):  # the newest already-retired node ends the scan
            if self._t_nodes[j] >= horizon:
                continue
            if self._records[j] is None:
                break
            if self._graph is not None and self._graph.has_jobs():
                # a worker more than the history behind: wait for it (its results set the node's counts)
                self._collect(wait=True)
            rec = self._records[j]
            merge_counts(self._retired_counts, rec.counts)
            self._records[j] = None
            if self._graph is not None:
                self._graph.forget(j)

    def _prune(self, t0: float) -> None:
        keep_from = t0 - self.history - 2.0 * self.config.max_gap
        for name, buf in self._buffers.items():
            cut = bisect.bisect_left(buf, keep_from, key=lambda item: item[0]) - 2
            if cut > 0:
                del buf[:cut]

    def _align_world(self, fix: GpsFix, current=None):
        """A fix while the heading of ENU is unknown: kept, and the online poses so far (``current``: the node being
        processed, when it is not recorded yet) fitted to the fixes kept (:func:`align_to_fixes`). Returns the fit and
        the standard deviations of the first pose's prior it gives (:func:`prior_from_alignment`), or None while it
        does not fit (the fix counted as missing: kept for the alignment)."""
        self._gps_seen.append(fix)
        poses = np.array(self._poses + ([] if current is None else [current]))
        aligned = self._fit_world(np.array(self._t_nodes[:len(poses) - 1] + [fix.t]), poses, fix.t)
        if aligned is None:
            self._step_counts.setdefault("gps", SensorCount()).missing += 1  # kept for the alignment
        return aligned

    def _fit_world(self, times: np.ndarray, poses: np.ndarray, t_end: float):
        """:func:`align_to_fixes` of the online ``poses`` at ``times`` (start frame) to the fixes kept up to ``t_end``:
        the fit and its prior's standard deviations, or None."""
        seen = GpsData(np.array([f.t for f in self._gps_seen]), np.column_stack(
            [np.array([f.enu for f in self._gps_seen]), np.zeros(len(self._gps_seen))]),
            np.array([f.covariance for f in self._gps_seen]), np.zeros((len(self._gps_seen), 3)),
            np.zeros(len(self._gps_seen), int), (0.0, 0.0, 0.0), self._gps_lever, 0.0)
        fit = align_to_fixes(times, poses, seen, t_end=t_end) if len(times) > 1 else None
        if fit is None:
            return None
        sigma = math.sqrt(float(np.median(np.trace(seen.covariance, axis1=1, axis2=2))) / 2.0)
        _, prior_sigma = prior_from_alignment(fit, poses[0], sigma)
        return fit, prior_sigma

    def _to_enu(self, fit, t: float) -> None:
        """The recorded poses and covariances re-expressed in ENU by the alignment ``fit`` (the start-frame ones kept
        for a rewind across the switch), the AHRS's heading offset turned with them (AHRS north was aligned to the
        start frame's heading), with a note."""
        c, s_ = math.cos(fit.yaw), math.sin(fit.yaw)
        rot = np.eye(3)
        rot[:2, :2] = [[c, -s_], [s_, c]]
        self._start_frame = (len(self._t_nodes), list(self._poses), list(self._covs), len(self._notes))
        self._poses = [p for p in fit.apply(np.array(self._poses))]
        self._covs = [rot @ cv @ rot.T for cv in self._covs]
        self._frame = "enu"
        self._carry = registry.turned(self._carry, fit.yaw)
        self._gps_reacquire = Reacquire(self.config.gps_reacquire)
        self._notes.append(f"gps: world frame re-expressed in ENU at t={t:.2f} (first heading "
                           f"{math.degrees(float(self._poses[0][2])):.2f} deg ± {math.degrees(fit.yaw_sigma):.2f})")

    def _apply_gps(self, fix: GpsFix) -> None:
        """EKF: a fix at the node just updated (module docstring of :mod:`~fusion_vo.backends.streaming`)."""
        ekf, model = self._ekf, self._gps_model
        last, self._gps_last = self._gps_last, fix.t
        if self._frame == "start":
            aligned = self._align_world(fix, ekf.x[:3])
            if aligned is None:
                return
            fit, prior_sigma = aligned
            c, s_ = math.cos(fit.yaw), math.sin(fit.yaw)
            T = np.eye(ekf.kf.P.shape[0])
            T[:2, :2] = [[c, -s_], [s_, c]]
            ekf.kf.x[:3, 0] = fit.apply(ekf.x[:3])[0]
            ekf.kf.P = T @ ekf.kf.P @ T.T
            ekf.kf.P[:2, :2] += np.eye(2) * prior_sigma[0] ** 2
            ekf.kf.P[YAW, YAW] += prior_sigma[2] ** 2
            self._to_enu(fit, fix.t)
        elif last is not None and fix.t - last >= OUTAGE_NOTE_S:  # the drift without fixes, as a batch run says it
            self._outages[fix.t] = outage_note(ekf, model, fix.enu, fix.covariance, last, fix.t, self._t_nodes[0])
        accepted = self._gps_reacquire.apply(ekf, model, fix.enu, fix.covariance, fix.t)
        count = self._step_counts.setdefault("gps", SensorCount())
        if accepted:
            count.used += 1
        else:
            count.gated += 1

    def _gps_state(self) -> tuple | None:
        """What a rewind restores of the GPS bookkeeping (frame, fixes kept for the alignment, re-acquisition)."""
        if "gps" not in self.sensors:
            return None
        re = self._gps_reacquire
        return (self._frame, len(self._gps_seen), None if re is None else (re.last_ok, len(re.times)),
                (self._gps_model.n_used, self._gps_model.n_rejected, len(self._gps_model.rejected_t)), self._gps_last)

    def _rewind_gps(self, i: int, state: tuple | None) -> None:
        """Back to the GPS bookkeeping after node ``i``; undo the switch to ENU if it came after ``i``."""
        for rec in self._records[i + 1:]:
            for fix in rec.fixes:
                bisect.insort(self._gps, fix, key=lambda f: f.t)
        if state is None:
            return
        frame, n_seen, reacquire, model, self._gps_last = state
        for t in [t for t in self._outages if t > self._t_nodes[i] + 1e-3]:  # (re-applied with the fixes after i)
            del self._outages[t]
        if self._frame == "enu" and frame == "start":
            _, poses, covs, n_notes = self._start_frame
            self._poses[:i + 1] = [p.copy() for p in poses[:i + 1]]
            self._covs[:i + 1] = [c.copy() for c in covs[:i + 1]]
            del self._notes[n_notes:]
            self._frame, self._gps_reacquire, self._start_frame = "start", None, None
        del self._gps_seen[n_seen:]
        if reacquire is not None:
            self._gps_reacquire.last_ok = reacquire[0]
            del self._gps_reacquire.times[reacquire[1]:]
        m = self._gps_model
        m.n_used, m.n_rejected = model[0], model[1]
        del m.rejected_t[model[2]:]
