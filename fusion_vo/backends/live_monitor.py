"""The consistency monitor run causally, node by node, for streaming use: heading sources and speeds.

:func:`~fusion_vo.backends.monitor.check_heading_sources` and :func:`~fusion_vo.backends.monitor.check_speed_sources`
judge a whole recording at once. A live stack cannot wait for the end: :class:`LiveHeadingMonitor` keeps the node
intervals of the last ``15 * monitor_window`` seconds (the longest window the checks use), runs the same checks on
them every ``monitor_window / 2`` seconds of data, and a component a check drops in the newest interval is
dropped from the intervals that follow until a later check no longer drops it there. The AHRS heading,
once dropped, stays dropped (its offset is no longer known; the batch check, which sees the whole
recording, may trust it again where its absolute heading agrees). Each span in which
a component was dropped becomes an :class:`~fusion_vo.backends.monitor.Episode`.

Decisions only use data up to the interval they are applied to, so they can differ from the batch
check's (which also sees what comes after): a lie is used until the check has seen enough of it. Until
the gyro's bias can be measured (ten intervals at rest or with a heading reference), the gyro neither
judges the other sources nor is judged: a constant bias is the backends' to estimate, not a lie.

Speeds: the batch check holds the suspect's distance (the wheels') to ``ρ₀`` times the other's (the camera's),
``ρ₀`` the median ratio over the recording's windows. Here ``ρ₀`` is the median over the windows of
``monitor_window`` seen so far, each counted once when it is complete, those overlapping a span in which the
suspect was dropped left out (a lie is no calibration); the check starts after :data:`MIN_SPEED_WINDOWS` of them.
The intervals of a span already closed are left out of the check's windows too, so a long window reaching back
into it does not find the lie again after its end.

The window the checks judge starts at a node that moves on in steps of at least 64 intervals; where it starts is
part of the state a rewind restores (:class:`MonitorState`), and the rows before it are kept while a rewind of
``history`` seconds can reach them, so a stream rewound for late data judges the windows it would have judged with
the same data in time order.
"""

from __future__ import annotations

import bisect
import copy
import dataclasses
import logging

import numpy as np

from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.monitor import (Episode, check_heading_sources, heading_changes, speed_disagreement, speed_pair,
                                       windows)
from fusion_vo.backends.timeline import Intervals
from fusion_vo.sensors import registry

logger = logging.getLogger(__name__)


def _components() -> dict:
    """The heading sources the live monitor decides for (those that can be cleared from an interval), in the
    registry's order: key -> ``(sensor name, source)``."""
    return {h.key: (sensor.name, h) for sensor, h in registry.heading_sources() if h.clear is not None}


def _speed_components() -> dict:
    """The distance sources the live speed check can drop from an interval: ``"<key> <component>"`` (``"wheel
    speed"``) -> ``(sensor name, source)``."""
    return {f"{d.key} {d.component}": (sensor.name, d) for sensor, d in registry.distance_sources()
            if d.drop is not None}


def _described(key: str) -> tuple[str, str]:
    """``(sensor, component)`` of a decision's key, heading source or distance source."""
    sensor, source = _components().get(key) or _speed_components()[key]
    return sensor, source.component


#: fewest windows of ``monitor_window`` with both distances before the live speed check judges (their median is the
#: distance ratio the check holds the two to)
MIN_SPEED_WINDOWS = 5


@dataclasses.dataclass(frozen=True)
class MonitorState:
    """What a rewind restores: the dropped components, the open spans, the intervals kept, where the checks' window
    starts and the speed ratios counted."""

    dropped: frozenset
    open_spans: tuple
    n_closed: int
    next_check: float
    n_intervals: int
    rest_bias: float | None
    first: int = 0
    n_ratios: int = 0
    ratios_until: float = -np.inf


class LiveHeadingMonitor:
    """Causal, windowed :func:`~fusion_vo.backends.monitor.check_heading_sources` and
    :func:`~fusion_vo.backends.monitor.check_speed_sources` over node intervals.

    Parameters
    ----------
    config : FusionConfig
        ``monitor``, ``monitor_window`` and the check's other settings.
    history : float
        How far back [s] a rewind may restore one of its states (``StreamingFusion``'s ``history``).
    """

    def __init__(self, config: FusionConfig, history: float = 2.0):
        self.config = config
        self.history = history  # how far back a rewind may restore a state (StreamingFusion's history)
        self.enabled = bool(config.monitor)
        self.span = 15.0 * config.monitor_window
        self.every = 0.5 * config.monitor_window
        self.dropped: set[str] = set()
        self.episodes: list[Episode] = []  # closed spans
        self._open: dict[str, list] = {}  # component -> [start, max NIS, against]
        self._next_check = -np.inf
        self._t: list[float] = []  # node times: _t[0] starts the first kept interval
        self._node: dict[str, _Column] = {}  # per-node fields, one row per node time
        self._interval: dict[str, _Column] = {}  # per-interval fields
        self._pairs: dict[str, _Pairs] = {}  # sensor -> its readings over node pairs (_pair_grids)
        self._uses: set[str] = set()
        self._last: Intervals | None = None
        self._dropped_before = 0  # intervals trimmed from the front
        self._first = 0  # the first node of the window the check judges (counting every node ever added)
        self._firsts: list[tuple[float, int]] = []  # (newest node time, _first before) of each move of _first
        self._rest_bias: float | None = None  # the gyro's bias at the last standstill
        self._ratios: list[float] = []  # the speed check's distance ratio per window seen (module docstring)
        self._ratios_until = -np.inf  # end of the last window counted there

    # ------------------------------------------------------------------ intervals
    def add(self, iv: Intervals) -> None:
        """Keep one two-node interval (raw, before any masking); it must start where the last one ended."""
        if not self.enabled:
            return
        fields = _split(iv)
        if not self._t:
            self._t = [float(iv.t[0])]
            for name, v in fields[0].items():
                self._node[name] = _Column(v[0], 1)
        self._t.append(float(iv.t[1]))
        for name, v in fields[0].items():
            if name not in self._node:
                self._node[name] = _Column(v[0], len(self._t) - 1)
            self._node[name].append(v[1])
        for name, v in fields[1].items():
            if name not in self._interval:
                self._interval[name] = _Column(v[0])
            self._interval[name].append(v[0])
        pos = len(self._t) - 2
        for name, grid, rows in _pair_grids(iv):
            self._pairs.setdefault(name, _Pairs(grid, rows)).add(pos, grid)
        self._uses |= set(iv.counts)
        self._last = iv
        self._trim()

    def update(self, index: int, iv: Intervals) -> None:
        """Interval number ``index`` (counting every interval ever added), rebuilt with late data."""
        pos = index - self._dropped_before
        if not self.enabled or pos < 0 or pos >= len(self._t) - 1:
            return
        nodes, intervals = _split(iv)
        for name, v in nodes.items():
            if name in self._node:
                self._node[name].set(pos + 1, v[1])
        for name, v in intervals.items():
            if name in self._interval:
                self._interval[name].set(pos, v[0])
        for name, grid, rows in _pair_grids(iv):
            self._pairs.setdefault(name, _Pairs(grid, rows)).replace(pos, grid)
        self._uses |= set(iv.counts)

    def _trim(self) -> None:
        """Move the window's first node on, in steps of at least 64 intervals, to within ``span`` of the newest one,
        and forget the rows no rewind can reach (those before the first node of ``history`` seconds ago).

        The window is a function of the nodes added since the stream started, as each state restores it, so a
        stream rewound for late data judges the same windows as the same data in time order."""
        p = self._first - self._dropped_before  # (the row of the window's first node)
        cut = bisect.bisect_left(self._t, self._t[-1] - self.span, lo=p) - 1 - p
        if cut >= 64:  # trim in batches
            self._firsts.append((self._t[-1], self._first))
            self._first += cut
        t_old = self._t[-1] - self.history - 1.0
        self._firsts = [(t, f) for t, f in self._firsts if t > t_old]
        cut = (self._firsts[0][1] if self._firsts else self._first) - self._dropped_before
        if cut < 64:
            return
        del self._t[:cut]
        for col in self._node.values():
            col.drop_front(cut)
        for col in self._interval.values():
            col.drop_front(cut)
        for pairs in self._pairs.values():
            pairs.drop_front(cut)
        self._dropped_before += cut

    def _merged(self) -> Intervals:
        """The intervals of the window (from its first node on) as one :class:`Intervals`: the array fields of the
        grid and of every sensor's measurements from their columns, everything else as the newest interval has it,
        the readings over node pairs (the camera's increments) from their rows."""
        last = self._last
        p = self._first - self._dropped_before
        columns = {**self._node, **self._interval}
        kw = {f.name: getattr(last, f.name) for f in dataclasses.fields(Intervals)
              if not isinstance(getattr(last, f.name), np.ndarray)}
        kw.update({key[1]: col.array()[p:] for key, col in columns.items() if key[0] is None})
        kw["t"] = np.array(self._t[p:])
        kw["counts"] = {name: None for name in self._uses}
        kw["notes"], kw["episodes"] = [], []
        kw["sensors"] = sensors = {}
        for name, grid in last.sensors.items():
            windowed = {key[1]: col.array()[p:] for key, col in columns.items() if key[0] == name}
            sensors[name] = _with_parts(grid, windowed) if windowed else grid
        for name, pairs in self._pairs.items():
            if name in last.sensors:
                sensors[name] = pairs.merged(last.sensors[name], p)
        return Intervals(**kw)

    @property
    def n_intervals(self) -> int:
        """Intervals added so far (those trimmed from the front included)."""
        return self._dropped_before + max(len(self._t) - 1, 0)

    # ------------------------------------------------------------------ decisions
    def due(self) -> bool:
        """Whether :meth:`check` would run the check now."""
        return self.enabled and len(self._t) >= 3 and self._t[-1] >= self._next_check

    def check(self) -> None:
        """Run the check on the kept intervals when due; update the dropped components."""
        if not self.due():
            return
        self._next_check = self._t[-1] + self.every
        iv = self._merged()
        components = _components()
        raw = {key: rows[0] for key, (_, _, rows) in heading_changes(iv, self.config).items()}
        for key, (_, h) in components.items():
            if h.absolute and key in self.dropped:  # a heading known to drift judges nothing any more
                h.clear(iv)
        bias, at_rest = _bias(iv, self.config)
        if at_rest:
            self._rest_bias = bias
        elif self._rest_bias is not None:
            bias = self._rest_bias  # the last standstill's bias beats one measured against a moving reference
        unknown = set()
        if bias is None:  # too few intervals yet to measure the bias: the source neither judges nor is judged
            unknown = {key for key, (_, h) in components.items() if h.biased and key in raw and key not in self.dropped}
            for key in unknown:
                components[key][1].clear(iv)
        episodes = check_heading_sources(iv, self.config, bias)
        kept = {key: h.kept(iv) for key, (_, h) in components.items()}
        t_now = self._t[-1]
        for name, (sensor, h) in components.items():
            if name not in raw or not raw[name][-1] or name in unknown:
                continue  # not measured in the newest interval (or not judged yet): no new evidence
            liar = not kept[name][-1]
            if liar and name not in self.dropped:
                ep = next((e for e in reversed(episodes) if e.component == h.component), None)
                self.dropped.add(name)
                self._open[name] = [t_now, 0.0 if ep is None else ep.max_nis, "" if ep is None else ep.against]
                logger.info("live monitor: %s %s dropped at t=%.2f (inconsistent with %s)", sensor,
                            h.component, t_now, self._open[name][2])
            elif liar:
                ep = next((e for e in reversed(episodes) if e.component == h.component), None)
                if ep is not None:
                    self._open[name][1] = max(self._open[name][1], ep.max_nis)
            elif name in self.dropped and not h.absolute:  # an absolute heading's offset is lost for good
                self._close(name, t_now)
        self._check_speed(iv, t_now)

    def _check_speed(self, iv: Intervals, t_now: float) -> None:
        """The speed check on the kept intervals (module docstring): the suspect's distance dropped from the next
        intervals while the newest disagrees with the distance ratio of the stream so far.

        The ratio is the median over the windows of ``monitor_window`` seen so far, leaving out those that overlap a
        span in which the suspect was dropped (a lie is no calibration). The intervals of a span already closed are
        no evidence either: a long window reaching back into it would otherwise find the lie again after its end.
        """
        pair = speed_pair(iv, self.config)
        if pair is None or pair.source.drop is None:
            return
        T = iv.t
        key = pair.key
        sensor, component = pair.sensor, pair.source.component
        closed = [(e.start, e.end) for e in self.episodes if (e.sensor, e.component) == (sensor, component)]
        spans = closed + ([(self._open[key][0], np.inf)] if key in self._open else [])
        for a, b in windows(T, self.config.monitor_window)[:-1]:  # the complete windows not counted yet
            if T[a] >= self._ratios_until - 1e-9:
                self._ratios_until = float(T[b])
                if not any(T[b] > s0 and T[a] < s1 for s0, s1 in spans) and (r := pair.ratio(a, b)) is not None:
                    self._ratios.append(r)
        if len(self._ratios) < MIN_SPEED_WINDOWS or not pair.both[-1]:
            return  # no ratio to hold the two to yet, or no new evidence
        for s0, s1 in closed:
            pair.both &= ~((T[1:] > s0) & (T[:-1] < s1))
        rho = float(np.median(self._ratios))
        bad, peak = speed_disagreement(pair, T, rho, self.config)
        if bad[-1] and key not in self.dropped:
            self.dropped.add(key)
            self._open[key] = [t_now, float(peak[-1]), pair.reference.key,
                               f" ({pair.source.key}/{pair.reference.key} distance ratio {rho:.3f} so far)"]
            logger.info("live monitor: %s %s dropped at t=%.2f (inconsistent with %s)", sensor, component, t_now,
                        pair.reference.key)
        elif bad[-1]:
            self._open[key][1] = max(self._open[key][1], float(peak[-1]))
        elif key in self.dropped:
            self._close(key, t_now)

    def _close(self, name: str, t_end: float) -> None:
        start, nis, against, *detail = self._open.pop(name)
        self.dropped.discard(name)
        sensor, component = _described(name)
        self.episodes.append(Episode(sensor, component, start, t_end, nis, against, *detail))

    def apply(self, iv: Intervals, dropped=None) -> None:
        """Mask the dropped components in ``iv`` (in place; default: the current decisions)."""
        dropped = self.dropped if dropped is None else dropped
        if not dropped:  # (the common case: no registry lookups on every node)
            return
        for key, (_, h) in _components().items():
            if key in dropped:
                h.clear(iv)
        for key, (_, d) in _speed_components().items():
            if key in dropped:
                d.drop(iv, np.ones(iv.n_steps, bool))

    def all_episodes(self, t_end: float) -> list[Episode]:
        """Closed spans and the open ones, ending at ``t_end``."""
        open_eps = [Episode(*_described(n), s, t_end, nis, who, *detail)
                    for n, (s, nis, who, *detail) in self._open.items()]
        return sorted(self.episodes + open_eps, key=lambda e: e.start)

    # ------------------------------------------------------------------ rewind
    def state(self) -> MonitorState:
        return MonitorState(frozenset(self.dropped), tuple((k, tuple(v)) for k, v in self._open.items()),
                            len(self.episodes), self._next_check, self._dropped_before + max(len(self._t) - 1, 0),
                            self._rest_bias, self._first, len(self._ratios), self._ratios_until)

    def restore(self, state: MonitorState) -> None:
        """Back to ``state`` (taken after an earlier interval); later intervals are forgotten."""
        self.dropped = set(state.dropped)
        self._open = {k: list(v) for k, v in state.open_spans}
        del self.episodes[state.n_closed:]
        self._next_check = state.next_check
        self._rest_bias = state.rest_bias
        self._first = max(state.first, self._dropped_before)  # (rows before it forgotten: a rewind beyond history)
        self._firsts = [(t, f) for t, f in self._firsts if f < state.first]
        del self._ratios[state.n_ratios:]
        self._ratios_until = state.ratios_until
        self.truncate(state.n_intervals)

    def truncate(self, n_intervals: int) -> None:
        """Keep the first ``n_intervals`` intervals ever added (those trimmed stay trimmed)."""
        keep = n_intervals - self._dropped_before
        if keep < 0 or keep >= len(self._t) - 1 or not self._t:
            return
        del self._t[keep + 1:]
        for col in self._node.values():
            col.keep(keep + 1)
        for col in self._interval.values():
            col.keep(keep)
        for pairs in self._pairs.values():
            pairs.keep(keep)


def _bias(iv: Intervals, config: FusionConfig) -> tuple[float | None, bool]:
    """The bias of the biased heading source (the gyro) over the kept intervals, and whether it was measured at rest.

    With ten intervals at rest (where a source says so: the wheels), the median rate there (as the whole-recording
    check does). Without, the rate difference to a heading reference is averaged over the span where both are
    measured: the heading change telescopes, so the bias comes out to ``σ / T`` with ``σ`` the reference's error
    over the span. Of the references that state their error (the AHRS, the camera), the one with the smaller is
    taken: the AHRS's is ``√2 σ_ψ`` per run of readings (its end points; plus its offset walk over the span), the
    camera's the root of its increments' summed heading variances. The median of per-interval rate
    differences (what the whole-recording check uses when there is no standstill) would follow the
    AHRS's interval noise. A reference that states none (the wheels' yaw, which depends on their calibration) is
    used only without either.

    Why the smaller error: over the first seconds of a stream the AHRS's end points give the bias to
    ``√2 σ_ψ / T``, 0.028 rad/s after 1 s at σ_ψ 0.02 rad, twenty times ``monitor_bias_sigma``; the camera's
    summed increments (15-20 µrad each on the generated drives) give it to about 1e-4 rad/s
    (``docs/decisions/0023-monitor-removes-the-gyro-bias-first.md``).
    """
    changes = heading_changes(iv, config)
    key = next((k for k, (_, h, _) in changes.items() if h.biased), None)
    if key is None:
        return None, False
    ok_b, angle_b = changes[key][2][0], changes[key][2][1]
    dt = iv.dt
    rest = next((h for _, h, _ in changes.values() if h.at_rest is not None), None)
    if rest is not None:
        still = rest.at_rest(iv, config) & ok_b
        if np.count_nonzero(still) >= 10:
            return float(np.median(angle_b[still] / dt[still])), True
    refs = []  # (error variance of the summed reference heading, ok, heading change per interval)
    others = sorted(((h.reference, k) for k, (_, h, _) in changes.items() if k != key and h.reference is not None))
    for _, k in others:
        h, (ok, angle, var) = changes[k][1], changes[k][2]
        ok = ok & ok_b
        if h.reference_error is not None and np.count_nonzero(ok) >= 10:
            refs.append((h.reference_error(iv, config, ok, var), ok, angle))
    if not refs:
        for _, k in others:
            h, (ok, angle, _) = changes[k][1], changes[k][2]
            ok = ok & ok_b
            if h.reference_error is None and np.count_nonzero(ok) >= 10:
                refs.append((0.0, ok, angle))
                break
    if not refs:
        return None, False
    _, ok, angle = min(refs, key=lambda r: r[0])
    return float(np.sum(angle_b[ok] - angle[ok]) / np.sum(dt[ok])), False


class _Column:
    """A growing array of rows of one shape and type (amortised appends, views of the rows kept)."""

    def __init__(self, like, repeat: int = 0):
        like = np.asarray(like)
        self._data = np.empty((max(64, 2 * repeat),) + like.shape, dtype=like.dtype)
        self._data[:repeat] = like
        self.n = repeat

    def append(self, value) -> None:
        if self.n == len(self._data):
            self._data = np.concatenate([self._data, np.empty_like(self._data)])
        self._data[self.n] = value
        self.n += 1

    def set(self, i: int, value) -> None:
        self._data[i] = value

    def keep(self, n: int) -> None:
        """Keep the first ``n`` rows."""
        self.n = min(self.n, max(n, 0))

    def drop_front(self, k: int) -> None:
        """Forget the first ``k`` rows."""
        k = min(k, self.n)
        self._data[:self.n - k] = self._data[k:self.n].copy()
        self.n -= k

    def shift(self, delta) -> None:
        self._data[:self.n] += delta

    def replace(self, rows: np.ndarray) -> None:
        self._data = np.concatenate([rows, np.empty((64,) + rows.shape[1:], dtype=rows.dtype)])
        self.n = len(rows)

    def array(self) -> np.ndarray:
        """The rows (a copy)."""
        return self._data[:self.n].copy()


class _Pairs:
    """The rows of one sensor's readings over node pairs (:func:`_pair_grids`), in the order of their first node:
    ``i0``, ``i1`` counted from the first kept node, and the per-reading arrays its grid names."""

    def __init__(self, grid, rows: tuple):
        self.rows = rows
        self.columns = {"i0": _Column(0), "i1": _Column(0)}
        self.columns.update({key: _Column(np.zeros(np.shape(getattr(grid, key))[1:])) for key in rows})

    def _new(self, pos: int, grid) -> dict:
        new = {"i0": np.asarray(grid.i0, int) + pos, "i1": np.asarray(grid.i1, int) + pos}
        new.update({key: np.asarray(getattr(grid, key)) for key in self.rows})
        return new

    def add(self, pos: int, grid) -> None:
        """The readings of a two-node interval whose first node is ``pos``."""
        new = self._new(pos, grid)
        for key, col in self.columns.items():
            for value in new[key]:
                col.append(value)

    def replace(self, pos: int, grid) -> None:
        """Those of the interval starting at ``pos`` replaced (rebuilt with late data)."""
        keep = self.columns["i0"].array() != pos
        new = self._new(pos, grid)
        merged = {k: np.concatenate([c.array()[keep], new[k]]) for k, c in self.columns.items()}
        order = np.argsort(merged["i0"], kind="stable")
        for k, c in self.columns.items():
            c.replace(merged[k][order])

    def drop_front(self, cut: int) -> None:
        """Forget the readings before node ``cut``; count from it."""
        first = int(np.searchsorted(self.columns["i0"].array(), cut))
        for col in self.columns.values():
            col.drop_front(first)
        self.columns["i0"].shift(-cut)
        self.columns["i1"].shift(-cut)

    def keep(self, n_intervals: int) -> None:
        """Keep the readings of the first ``n_intervals`` intervals."""
        n = int(np.searchsorted(self.columns["i0"].array(), n_intervals))
        for col in self.columns.values():
            col.keep(n)

    def merged(self, last, p: int):
        """The readings from node ``p`` on as a copy of the sensor's newest grid ``last``; its other per-reading
        arrays (those it does not name) back to their defaults."""
        rows = self.columns["i0"].array() >= p
        values = {k: c.array()[rows] for k, c in self.columns.items()}
        values["i0"] = values["i0"] - p
        values["i1"] = values["i1"] - p
        n_last = len(last.i0)
        for f in dataclasses.fields(last):
            v = getattr(last, f.name)
            if f.name not in values and isinstance(v, np.ndarray) and v.ndim and len(v) == n_last \
                    and f.default is not dataclasses.MISSING:
                values[f.name] = f.default
        return dataclasses.replace(last, **values)


def _pair_grids(iv: Intervals) -> list[tuple]:
    """``(name, grid, rows)`` of the sensors whose measurements on the grid of ``iv`` are readings over node pairs
    (the camera's increments): a dataclass with ``i0``, ``i1`` and ``ROWS``, the names of its per-reading arrays
    the monitor keeps."""
    out = []
    for name, grid in iv.sensors.items():
        rows = getattr(type(grid), "ROWS", None)
        if rows is not None and dataclasses.is_dataclass(grid) and hasattr(grid, "i0") and hasattr(grid, "i1"):
            out.append((name, grid, tuple(rows)))
    return out


def _parts(container) -> list[tuple]:
    """``(key, value)`` of a sensor's measurements on the grid: a dataclass's fields by name, a tuple's items by
    position, a dict's by key (nothing for any other container)."""
    if dataclasses.is_dataclass(container) and not isinstance(container, type):
        return [(f.name, getattr(container, f.name)) for f in dataclasses.fields(container)]
    if isinstance(container, tuple) and not hasattr(container, "_fields"):
        return list(enumerate(container))
    if isinstance(container, tuple):  # a named tuple
        return list(zip(container._fields, container))
    if isinstance(container, dict):
        return list(container.items())
    return []


def _with_parts(container, values: dict):
    """A copy of ``container`` (as :func:`_parts` reads it) with the parts ``values`` replaced."""
    if dataclasses.is_dataclass(container):
        out = copy.copy(container)
        for key, v in values.items():
            setattr(out, key, v)
        return out
    if isinstance(container, tuple) and hasattr(container, "_fields"):
        return container._replace(**values)
    if isinstance(container, tuple):
        return tuple(values.get(i, v) for i, v in enumerate(container))
    return {**container, **values}


def _split(iv: Intervals) -> tuple[dict, dict]:
    """Per-node and per-interval arrays of a two-node interval, of the grid (keys ``(None, field)``) and of every
    registered sensor's measurements on it (``(sensor, part)``: the fields of its container, such as the
    :attr:`Sensor.grid <fusion_vo.sensors.registry.Sensor.grid>` dataclass it registers, or the items of a
    tuple or a dict of arrays it keeps in ``iv.sensors``); readings over node pairs (:func:`_pair_grids`) aside."""
    nodes, intervals = {}, {}
    parts = [(None, [(f.name, getattr(iv, f.name)) for f in dataclasses.fields(iv)])]
    pairs = {name for name, _, _ in _pair_grids(iv)}
    parts += [(s.name, _parts(iv.sensors[s.name])) for s in registry.sensors()
              if s.name not in pairs and s.name in iv.sensors]
    for owner, items in parts:
        for key, v in items:
            if (owner is None and key == "t") or not isinstance(v, np.ndarray):
                continue
            if len(v) == 2:
                nodes[(owner, key)] = v
            elif len(v) == 1:
                intervals[(owner, key)] = v
    return nodes, intervals


__all__ = ["LiveHeadingMonitor", "MonitorState"]
