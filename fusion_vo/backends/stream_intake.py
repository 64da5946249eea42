"""StreamingFusion's intake: each sample checked, counted, put on its stream's clock and buffered; a late
camera increment re-timed onto the nodes already processed (:mod:`fusion_vo.backends.streaming`)."""

from __future__ import annotations

import bisect
import dataclasses
import logging
import math
import time

import numpy as np

from fusion_vo.backends.result import SensorCount
from fusion_vo.backends.stream_state import payload_values
from fusion_vo.backends.timeline import build_intervals
from fusion_vo.errors import InputError
from fusion_vo.geometry import se2
from fusion_vo.measurements import VisualIncrement
from fusion_vo.sensors import registry

logger = logging.getLogger(__name__)


def _finite(value) -> bool:
    """Whether every number of ``value`` (a number or an array-like) is finite; TypeError or ValueError when it is
    not numeric."""
    if isinstance(value, float):  # (the common case, without numpy's per-call cost)
        return math.isfinite(value)
    return bool(np.isfinite(np.asarray(value, dtype=np.float64)).all())


class IntakeMixin:
    """Methods of :class:`~fusion_vo.backends.streaming.StreamingFusion` (module docstring); they use its state."""

    def _synchronised(self, stream: str, t, payload) -> tuple:
        """``(t, moved)``: ``t`` on the run's clock (:attr:`~fusion_vo.sensors.registry.Live.clock`: an odometry
        twist's moved back by its delay behind the gyro estimated so far, :class:`~fusion_vo.sensors.sync.TwistClock`,
        the rule of batch use); every other sample is shown to each clock (a gyro sample feeds that estimate). Nodes
        are processed that much later (``_advance``), so the corrected samples are not late. Values that cannot be
        read (counted as gated by ``_add``) pass unchanged. When this sample changes its clock's offset, the buffered
        samples of its stream move with it (:meth:`_shift_samples`) and ``moved`` is the earliest time they were or
        now are at (else None), for ``_add`` to process again the intervals that read them."""
        moved = None
        for clock in self._clocks:
            if stream != clock.stream:
                clock.observe(stream, t, payload)
                continue
            before = clock.offset
            t = clock.correct(t, payload)
            if clock.offset != before:
                moved = self._shift_samples(stream, before - clock.offset)
        return t, moved

    # ------------------------------------------------------------------ buffering
    def _check(self, sensor: str) -> None:
        if sensor not in self.sensors and not (sensor == "odom" and "wheel" in self.sensors):
            raise InputError(f"sensor '{sensor}' was not declared (sensors={self.sensors})")

    def _count(self, sensor: str) -> SensorCount:
        return self._input_counts.setdefault(sensor, SensorCount())

    def _valid(self, sensor: str, t, values) -> bool:
        """Non-finite values and times beyond the horizon are counted as gated, never raised."""
        try:
            t = float(t)
            finite = math.isfinite(t) and all(_finite(v) for v in (values if isinstance(values, (list, tuple))
                                                                     else [values]))
        except (TypeError, ValueError):
            finite = False
        if not finite:
            self._reject(sensor, "a non-finite or malformed value", f"t={t}")
            return False
        if np.isfinite(self._latest) and t > self._latest + self.horizon:
            self._reject(sensor, f"more than {self.horizon:g} s ahead of the newest sample",
                         f"t={t:.3f}, newest t={self._latest:.3f}")
            return False
        return True

    #: wall-clock seconds between two warnings about samples of one sensor rejected for one reason
    REJECT_LOG_INTERVAL = 10.0

    def _reject(self, sensor: str, reason: str, detail: str) -> None:
        """Count a rejected sample as gated and by its reason (summed up in ``finish``'s notes); a warning for the
        first of each sensor and reason, then at most one every :attr:`REJECT_LOG_INTERVAL` s with the count so
        far."""
        self._count(sensor).gated += 1
        entry = self._rejected.setdefault((sensor, reason), [0, -math.inf])
        entry[0] += 1
        now = time.monotonic()
        if now - entry[1] >= self.REJECT_LOG_INTERVAL:
            entry[1] = now
            logger.warning("%s sample rejected: %s (%s); %d so far, counted as gated", sensor, reason, detail, entry[0])
        else:
            logger.debug("%s sample rejected: %s (%s)", sensor, reason, detail)

    def _late(self, sensor: str, t: float, back: int = 2, first: int | None = None) -> bool:
        """True if ``t`` is before the last node and cannot be re-applied; rewinds the EKF if it can: from ``back``
        nodes before ``t``, or (``first``: the first node whose interval reads it, :meth:`_first_reader`) from the node
        before ``first``."""
        if not self._t_nodes or t >= self._t_nodes[-1] - 1e-9:
            return False
        i = self._rewind_index(t, back, first)
        if i is None:
            self._count(sensor).late += 1
            logger.warning("%s measurement at t=%.3f arrived after t=%.3f was processed (beyond the %.3g s "
                           "history); not applied", sensor, t, self._t_nodes[-1], self.history)
            return True
        if self.backend == "ekf":
            self._rewind(i)
        return False  # iSAM2: the intervals the sample changes are marked once it is buffered (_mark)

    def _mark(self, t_lo: float, t_hi: float) -> None:
        """iSAM2: mark the processed node intervals overlapping ``[t_lo, t_hi]`` for rebuilding (the last node's too when
        ``t_lo`` is at it: a camera increment re-timed onto it)."""
        if self.backend == "ekf" or not self._t_nodes or t_lo > self._t_nodes[-1] + 1e-9:
            return
        first = max(bisect.bisect_left(self._t_nodes, t_lo - 1e-9), 1)
        last = min(bisect.bisect_left(self._t_nodes, t_hi - 1e-9), len(self._t_nodes) - 1)
        self._dirty.update(range(first, last + 1))

    def _add(self, stream: str, t: float, payload, moved: float | None = None) -> None:
        """Buffer a sample of ``stream`` at ``t`` and process what it changes: the intervals that read it, and those
        that read the samples of the stream a new delay estimate moved from ``moved`` on (:meth:`_synchronised`),
        even when the sample itself is left out (:meth:`_reread`)."""
        self._check(stream)
        sensor = self._counted[stream]  # the name its counts are reported under
        if not self._valid(sensor, t, payload_values(payload)):
            if moved is not None:
                self._reread(stream, moved)
            return
        t = float(t)
        # the first interval this sample (and the samples moved with it) changes, when processed
        t_from = t if moved is None else min(t, moved)
        self._touch(stream, t_from)
        buf = self._buffers[stream]
        k = bisect.bisect_right(buf, t, key=lambda item: item[0])  # (a rewind or a late count leaves the buffers)
        T = self._t_nodes
        redo = self._read_by_processed(stream, t_from)
        first = self._first_reader(stream, t_from) if redo else None
        if T and t < T[-1] - 1e-9:
            if self._late(sensor, t, first=first):
                return
        elif first is not None and self.backend == "ekf":
            i = self._rewind_index(t, 0, first)
            if i is not None:
                self._rewind(i)
        if buf and t < buf[-1][0]:
            self._count(sensor).reordered += 1
        buf.insert(k, (t, payload))
        if redo and self.backend != "ekf":
            # a late sample changes the intervals that read it (their interpolation across a gap of the stream, the
            # gating and the spike medians of its neighbours)
            t_lo = buf[max(k - 3, 0)][0] if first is None else min(buf[max(k - 3, 0)][0], T[first])
            self._mark(t_lo, max(buf[min(k + 3, len(buf) - 1)][0], t))
        self._advance(t)

    def _reread(self, stream: str, t_from: float) -> None:
        """Process again the intervals that read the samples of ``stream`` from ``t_from`` on (moved by a new delay
        estimate whose sample was itself left out), by :meth:`_add`'s rule for the samples moved with a sample it
        takes: the EKF rewinds to the node before the first of them, iSAM2 marks them for rebuilding; a node started
        meanwhile is started again."""
        self._touch(stream, t_from)
        if not self._read_by_processed(stream, t_from):
            return
        T = self._t_nodes
        first = self._first_reader(stream, t_from)
        if self.backend == "ekf":
            i = None if first is None else self._rewind_index(t_from, 0, first)
            if i is not None:
                self._rewind(i)
        else:
            self._mark(t_from if first is None else min(t_from, T[first]), T[-1])
        self._advance(self._latest)

    def _first_reader(self, stream: str, t: float) -> int | None:
        """The first processed node whose interval would read a sample of ``stream`` at ``t``, or None before the
        first interval.

        Node ``j``'s interval read the stream's samples up to its reach (:attr:`NodeRecord.reach`: the last sample
        it read, or any new one when it read all), so a sample before it changes what it read. Reach grows with
        the node, so the nodes are scanned back from the newest while they would read ``t``: in a gap of the stream
        the first reader is the gap's first interval, not the one holding ``t``. None also when the scan reaches a
        node that has left the history (the first reader may be older still): the sample is then applied from two
        nodes before it, or counted late (:meth:`_late`).
        """
        T, records = self._t_nodes, self._records
        if len(T) < 2:
            return None
        j = len(T) - 1
        while j >= 1 and records[j] is not None and records[j].reach.get(stream, np.inf) > t:
            j -= 1
        if j >= 1 and records[j] is None:  # (retired: the first reader may be older than the history)
            return None
        return min(j + 1, len(T) - 1)

    def _read_by_processed(self, stream: str, t: float) -> bool:
        """Whether a processed interval reads a sample of ``stream`` at ``t``: it lies before the last node, or the last
        node's interval reads it (:meth:`_read_by_last`). Those intervals are processed again with it."""
        T = self._t_nodes
        return bool(T) and (t < T[-1] - 1e-9 or self._read_by_last(stream, t))

    def _read_by_last(self, stream: str, t: float) -> bool:
        """Whether a sample of ``stream`` at ``t``, at or after the last node, is one that node's interval would have
        read: before the last sample it read of the stream (the first after its end, a neighbour of the spike check),
        at most ``max_gap`` after the node. Such a sample came out of order within the window but after the node was
        processed (the window vouches for the samples up to the node, not for those after it that the interval
        reads), and the node is processed again with it, as for a late sample."""
        if not self._t_nodes or not self._records or self._records[-1] is None:
            return False
        last = self._t_nodes[-1]
        return last <= t < min(self._records[-1].reach.get(stream, -np.inf), last + self.config.max_gap)

    def _on_nodes(self, inc: VisualIncrement) -> VisualIncrement | None:
        """iSAM2: a late increment moved onto the processed nodes nearest its frames (None: it cannot be).

        iSAM2's nodes stay where they were processed (fill-in nodes when the camera was late), so the
        increment is re-timed: the wheels' (and gyro's) motion over the slivers between each frame and its
        nearest node is composed onto it, ``B(n_a)->B(t0)  (+)  delta  (+)  B(t1)->B(n_b)``, and its covariance
        grows by 2 % of each sliver's motion (plus 0.1 mm / 0.1 mrad). Both nodes must be within the history, the
        slivers shorter than a node step, and no other increment on the intervals between them; an increment over
        dropped frames spans several, and is then one factor between its two nodes, as in time order.
        """
        T = self._t_nodes
        a = min(range(max(bisect.bisect_left(T, inc.t0) - 1, 0), min(bisect.bisect_left(T, inc.t0) + 1, len(T))),
                key=lambda k: abs(T[k] - inc.t0))
        step = 1.0 / self.config.step_hz
        if inc.t1 > T[-1] + 0.5 * step:
            # ends after the last node: the next node is its frame, only t0 moves (within half a step of the last node
            # it ends there: fill-in nodes stepped from an epoch-scale start drift off the frames by float steps)
            b, t_b = None, inc.t1
            if a != len(T) - 1:
                return None
        else:
            k = bisect.bisect_left(T, inc.t1)
            b = min(range(max(k - 1, 0), min(k + 1, len(T))), key=lambda j: abs(T[j] - inc.t1))
            t_b = T[b]
            if b <= a:
                return None
        if abs(T[a] - inc.t0) < 1e-9 and abs(t_b - inc.t1) < 1e-9:
            return inc
        if max(abs(T[a] - inc.t0), abs(t_b - inc.t1)) > step or self._records[a] is None:
            return None
        # every interval it spans (frames dropped between its two: several) processed, within the history, and
        # without another increment, taken or waiting
        if b is not None and (any(self._records[j] is None or any(v.ok for v in self._records[j].visual)
                                  for j in range(a + 1, b + 1))
                              or any(v.ok and v.t1 > T[a] + 1e-9 and v.t0 < t_b - 1e-9 for v in self._visual)):
            return None
        head = self._sliver(T[a], inc.t0)
        tail = self._sliver(inc.t1, t_b)
        if head is None or tail is None:
            return None

        delta = se2.compose(se2.compose(head[0], np.asarray(inc.delta, dtype=np.float64)), tail[0])
        cov = np.asarray(inc.covariance, dtype=np.float64) + np.diag(head[1] + tail[1])
        return dataclasses.replace(inc, t0=float(T[a]), t1=float(t_b), delta=delta, covariance=cov)

    def _sliver(self, x: float, y: float):
        """Body motion from ``x`` to ``y`` (either order) from the buffered samples of the sensors that declare their
        :attr:`~fusion_vo.sensors.registry.Sensor.motion` (the wheels' arc with the gyro's turn), and its variance
        (2 % of the motion, plus 0.1 mm / 0.1 mrad); None where they do not measure it."""
        lo, hi = min(x, y), max(x, y)
        if hi - lo < 1e-9:
            return np.zeros(3), np.zeros(3)
        iv = build_intervals(self._streams_between(lo, hi, self._carry), self.config, np.array([lo, hi]),
                             self._carry)
        motion = np.full((1, 3), np.nan)
        for _, step in registry.ordered("motion"):
            motion = step.run(iv, motion)
        inc = motion[0]
        if not np.all(np.isfinite(inc)):
            return None
        var = (0.02 * np.abs(inc)) ** 2 + np.array([1e-4, 1e-4, 1e-4]) ** 2
        return (inc if y >= x else se2.inverse(inc)), var

    def _insert_visual(self, inc: VisualIncrement) -> None:
        if self._visual and inc.t1 < self._visual[-1].t1:
            self._count("camera").reordered += 1
        bisect.insort(self._visual, inc, key=lambda v: v.t1)

    def _shift_samples(self, stream: str, dt: float) -> float | None:
        """A clock's offset changed: move the buffered samples of ``stream`` not yet processed by ``dt`` [s] (those
        that land before the last processed node stay buffered for a rewind or rebuild, as late data). Returns a float
        step before the earliest time a moved sample was or now is at (every interval that read one at its old time,
        or would at its new time, is processed again: :meth:`_first_reader` counts the samples before a time), or
        None when none moved."""
        buf = self._buffers.get(stream, [])
        last = self._t_nodes[-1] if self._t_nodes else -np.inf
        keep = [item for item in buf if item[0] <= last]
        moved = [(item[0] + dt, item[1]) for item in buf if item[0] > last]
        if buf:
            self._buffers[stream] = sorted(keep + moved, key=lambda item: item[0])
        return float(np.nextafter(min(moved[0][0], moved[0][0] - dt), -np.inf)) if moved else None

    def _touch(self, stream: str, t: float) -> None:
        """A measurement of ``stream`` at ``t`` arrived: a started node it would change is started again
        (a sample among those its interval read, a frame that could be its node, a fix up to it)."""
        started = self._pending
        if started is None:
            return
        if stream == "visual":
            changes = t <= max(started.t1, started.t0 + 1.5 / self.config.step_hz) + 1e-9
        elif stream == "gps":
            changes = t <= started.t1 + 1e-3
        else:
            changes = t <= started.reach.get(stream, np.inf)
        if changes:
            self._drop_pending()
