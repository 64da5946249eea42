"""The heading-consistency monitor run causally, node by node, for streaming use.

:func:`~fusion_vo.backends.monitor.check_heading_sources` judges a whole recording at once. A live
stack cannot wait for the end: :class:`LiveHeadingMonitor` keeps the node intervals of the last
``15 * monitor_window`` seconds (the longest window the check uses), runs the same check on them every
``monitor_window / 2`` seconds of data, and a component the check drops in the newest interval is
dropped from the intervals that follow until a later check no longer drops it there. The AHRS heading,
once dropped, stays dropped (its offset is no longer known; the batch check, which sees the whole
recording, may trust it again where its absolute heading agrees). Each span in which
a component was dropped becomes an :class:`~fusion_vo.backends.monitor.Episode`.

Decisions only use data up to the interval they are applied to, so they can differ from the batch
check's (which also sees what comes after): a lie is used until the check has seen enough of it. Until
the gyro's bias can be measured (ten intervals at rest or with a heading reference), the gyro neither
judges the other sources nor is judged: a constant bias is the backends' to estimate, not a lie.
"""

from __future__ import annotations

import bisect
import copy
import dataclasses
import logging

import numpy as np

from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.monitor import Episode, check_heading_sources, heading_changes
from fusion_vo.backends.timeline import Intervals
from fusion_vo.sensors import registry
from fusion_vo.sensors.visual import CameraGrid, camera_grid

logger = logging.getLogger(__name__)


def _components() -> dict:
    """The heading sources the live monitor decides for (those that can be cleared from an interval), in the
    registry's order: key -> ``(sensor name, source)``."""
    return {h.key: (sensor.name, h) for sensor, h in registry.heading_sources() if h.clear is not None}


@dataclasses.dataclass(frozen=True)
class MonitorState:
    """What a rewind restores: the dropped components, the open spans and the intervals kept."""

    dropped: frozenset
    open_spans: tuple
    n_closed: int
    next_check: float
    n_intervals: int
    rest_bias: float | None


class LiveHeadingMonitor:
    """Causal, windowed :func:`~fusion_vo.backends.monitor.check_heading_sources` over node intervals.

    Parameters
    ----------
    config : FusionConfig
        ``monitor``, ``monitor_window`` and the check's other settings.
    """

    def __init__(self, config: FusionConfig):
        self.config = config
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
        self._vis = {"pos": _Column(0), "delta": _Column(np.zeros(3)), "cov": _Column(np.zeros((3, 3)))}
        self._uses: set[str] = set()
        self._last: Intervals | None = None
        self._dropped_before = 0  # intervals trimmed from the front
        self._rest_bias: float | None = None  # the gyro's bias at the last standstill

    # ------------------------------------------------------------------ intervals
    def add(self, iv: Intervals) -> None:
        """Keep one two-node interval (raw, before any masking); it must start where the last one ended."""
        if not self.enabled:
            return
        cam = camera_grid(iv)
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
        for d, c in zip(cam.delta, cam.cov):
            self._vis["pos"].append(pos)
            self._vis["delta"].append(d)
            self._vis["cov"].append(c)
        self._uses |= set(iv.counts)
        self._last = iv
        self._trim()

    def update(self, index: int, iv: Intervals) -> None:
        """Interval number ``index`` (counting every interval ever added), rebuilt with late data."""
        pos = index - self._dropped_before
        if not self.enabled or pos < 0 or pos >= len(self._t) - 1:
            return
        cam = camera_grid(iv)
        nodes, intervals = _split(iv)
        for name, v in nodes.items():
            if name in self._node:
                self._node[name].set(pos + 1, v[1])
        for name, v in intervals.items():
            if name in self._interval:
                self._interval[name].set(pos, v[0])
        rows = self._vis["pos"].array()
        keep = rows != pos
        new = {"pos": np.full(len(cam.delta), pos), "delta": np.asarray(cam.delta).reshape(-1, 3),
               "cov": np.asarray(cam.cov).reshape(-1, 3, 3)}
        merged = {k: np.concatenate([c.array()[keep], new[k]]) for k, c in self._vis.items()}
        order = np.argsort(merged["pos"], kind="stable")
        for k, c in self._vis.items():
            c.replace(merged[k][order])
        self._uses |= set(iv.counts)

    def _trim(self) -> None:
        cut = bisect.bisect_left(self._t, self._t[-1] - self.span) - 1
        if cut < 64:  # trim in batches
            return
        del self._t[:cut]
        for col in self._node.values():
            col.drop_front(cut)
        for col in self._interval.values():
            col.drop_front(cut)
        first = int(np.searchsorted(self._vis["pos"].array(), cut))  # rows are in position order
        for col in self._vis.values():
            col.drop_front(first)
        self._vis["pos"].shift(-cut)
        self._dropped_before += cut

    def _merged(self) -> Intervals:
        """The kept intervals as one :class:`Intervals`: the array fields of the grid and of every sensor's
        measurements from their columns, everything else as the newest interval has it, the camera's increments
        from their rows (each over one interval)."""
        last = self._last
        columns = {**self._node, **self._interval}
        kw = {f.name: getattr(last, f.name) for f in dataclasses.fields(Intervals)
              if not isinstance(getattr(last, f.name), np.ndarray)}
        kw.update({key[1]: col.array() for key, col in columns.items() if key[0] is None})
        kw["t"] = np.array(self._t)
        kw["counts"] = {name: None for name in self._uses}
        kw["notes"], kw["episodes"] = [], []
        kw["sensors"] = sensors = {}
        for name, grid in last.sensors.items():
            if dataclasses.is_dataclass(grid) and any(key[0] == name for key in columns):
                grid = copy.copy(grid)
                for f in dataclasses.fields(grid):
                    if (name, f.name) in columns:
                        setattr(grid, f.name, columns[(name, f.name)].array())
            sensors[name] = grid
        pos = self._vis["pos"].array().astype(int)
        sensors["camera"] = CameraGrid(pos, pos + 1, self._vis["delta"].array(), self._vis["cov"].array(),
                                       frame_error=last.sensors["camera"].frame_error,
                                       noise=last.sensors["camera"].noise)
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

    def _close(self, name: str, t_end: float) -> None:
        start, nis, against = self._open.pop(name)
        self.dropped.discard(name)
        sensor, h = _components()[name]
        self.episodes.append(Episode(sensor, h.component, start, t_end, nis, against))

    def apply(self, iv: Intervals, dropped=None) -> None:
        """Mask the dropped components in ``iv`` (in place; default: the current decisions)."""
        dropped = self.dropped if dropped is None else dropped
        for key, (_, h) in _components().items():
            if key in dropped:
                h.clear(iv)

    def all_episodes(self, t_end: float) -> list[Episode]:
        """Closed spans and the open ones, ending at ``t_end``."""
        components = _components()
        open_eps = [Episode(components[n][0], components[n][1].component, s, t_end, nis, who)
                    for n, (s, nis, who) in self._open.items()]
        return sorted(self.episodes + open_eps, key=lambda e: e.start)

    # ------------------------------------------------------------------ rewind
    def state(self) -> MonitorState:
        return MonitorState(frozenset(self.dropped), tuple((k, tuple(v)) for k, v in self._open.items()),
                            len(self.episodes), self._next_check, self._dropped_before + max(len(self._t) - 1, 0),
                           self._rest_bias)

    def restore(self, state: MonitorState) -> None:
        """Back to ``state`` (taken after an earlier interval); later intervals are forgotten."""
        self.dropped = set(state.dropped)
        self._open = {k: list(v) for k, v in state.open_spans}
        del self.episodes[state.n_closed:]
        self._next_check = state.next_check
        self._rest_bias = state.rest_bias
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
        n_vis = int(np.searchsorted(self._vis["pos"].array(), keep))  # rows are in position order
        for col in self._vis.values():
            col.keep(n_vis)


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


def _split(iv: Intervals) -> tuple[dict, dict]:
    """Per-node and per-interval array fields of a two-node interval, of the grid (keys ``(None, field)``) and of
    the measurements of each sensor that registers their container (``(sensor, field)``,
    :attr:`Sensor.grid <fusion_vo.sensors.registry.Sensor.grid>`); the camera's increments aside."""
    nodes, intervals = {}, {}
    parts = [(None, iv)] + [(s.name, iv.sensors[s.name]) for s in registry.sensors()
                            if s.grid is not None and s.name != "camera" and s.name in iv.sensors]
    for owner, part in parts:
        for f in dataclasses.fields(part):
            v = getattr(part, f.name)
            if (owner is None and f.name == "t") or not isinstance(v, np.ndarray):
                continue
            if len(v) == 2:
                nodes[(owner, f.name)] = v
            elif len(v) == 1:
                intervals[(owner, f.name)] = v
    return nodes, intervals


__all__ = ["LiveHeadingMonitor", "MonitorState"]
