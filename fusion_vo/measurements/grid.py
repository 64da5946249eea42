"""Putting streams of different rates in time order and onto a grid of node times.

The backends estimate the robot at node times ``T_0 < T_1 < … < T_K`` (:mod:`fusion_vo.backends.timeline`
chooses them); each sensor puts its samples onto that grid with these helpers.
"""

from __future__ import annotations

import numpy as np

from fusion_vo.measurements.counts import SensorCount


def time_order(t: np.ndarray) -> tuple[np.ndarray, int, int]:
    """Indices that put samples in time order without exact duplicates.

    Returns ``(index, n_reordered, n_duplicates)``; ``n_reordered`` counts samples whose timestamp is
    earlier than their predecessor's in the input.
    """
    t = np.asarray(t, dtype=np.float64)
    n_reordered = int(np.count_nonzero(np.diff(t) < 0))
    order = np.argsort(t, kind="stable")
    ts = t[order]
    keep = np.concatenate([[True], np.diff(ts) > 0]) if len(ts) else np.zeros(0, bool)
    return order[keep], n_reordered, int(np.count_nonzero(~keep))


def ordered_fields(obj, names, count: SensorCount):
    """Copy of the dataclass ``obj`` with array fields ``names`` in time order (counts updated)."""
    idx, n_re, n_dup = time_order(obj.t)
    count.reordered += n_re
    count.gated += n_dup
    if n_re == 0 and n_dup == 0:
        return obj
    kwargs = dict(obj.__dict__)
    for name in ("t",) + tuple(names):
        if kwargs.get(name) is not None:
            kwargs[name] = np.asarray(kwargs[name])[idx]
    return type(obj)(**kwargs)


def coverage(ts: np.ndarray, bad_sample_interval: np.ndarray, T: np.ndarray, max_gap: float) -> np.ndarray:
    """True for node intervals covered by samples ``ts`` without gaps > max_gap or bad sample intervals."""
    if len(ts) < 2:
        return np.zeros(len(T) - 1, bool)
    bad = bad_sample_interval | (np.diff(ts) > max_gap)
    cum = np.concatenate([[0], np.cumsum(bad)])
    lo = np.clip(np.searchsorted(ts, T[:-1], side="right") - 1, 0, len(ts) - 2)
    hi = np.clip(np.searchsorted(ts, T[1:], side="left") - 1, 0, len(ts) - 2)
    n_bad = cum[hi + 1] - cum[lo]
    inside = (T[:-1] >= ts[0] - 1e-9) & (T[1:] <= ts[-1] + 1e-9)
    return inside & (n_bad == 0)


def when(t: float, T: np.ndarray) -> str:
    """``t=...`` on the recording clock with the time since the first node."""
    return f"t={t:.2f} ({t - T[0]:.2f} s in)"


def node_indices(T: np.ndarray, t: np.ndarray) -> np.ndarray:
    """:func:`node_index` of every time in ``t`` at once; -1 where no node is within 1 us."""
    t = np.asarray(t, dtype=np.float64)
    i = np.clip(np.searchsorted(T, t), 0, len(T) - 1)
    prev = np.maximum(i - 1, 0)
    out = np.full(len(t), -1, dtype=np.int64)
    at_i = np.abs(T[i] - t) < 1e-6
    out[at_i] = i[at_i]
    at_prev = (i >= 1) & (np.abs(T[prev] - t) < 1e-6)  # the earlier of two matches, as node_index
    out[at_prev] = prev[at_prev]
    return out


def node_index(T: np.ndarray, t: float) -> int | None:
    i = int(np.clip(np.searchsorted(T, t), 0, len(T) - 1))
    for j in (i - 1, i):
        if 0 <= j < len(T) and abs(T[j] - t) < 1e-6:
            return j
    return None


def uncovered_runs(T: np.ndarray, covered: np.ndarray, min_length: float) -> list[tuple[float, float]]:
    """Time spans ``(start, end)`` of consecutive uncovered node intervals at least ``min_length`` long."""
    runs = []
    k = 0
    n = len(covered)
    while k < n:
        if covered[k]:
            k += 1
            continue
        j = k
        while j < n and not covered[j]:
            j += 1
        if T[j] - T[k] >= min_length:
            runs.append((float(T[k]), float(T[j])))
        k = j
    return runs


#: shortest span [s] without the camera's increments, and without another sensor's samples, that a note names
CAMERA_LOST, UNAVAILABLE = 0.2, 0.5


def outage_notes(label: str, T: np.ndarray, covered: np.ndarray) -> list[str]:
    """The notes for the spans of node intervals that ``label``'s data do not cover (``covered`` (K,) over the node
    times ``T`` (K+1,)): the camera lost for at least :data:`CAMERA_LOST` seconds, another sensor unavailable for at
    least :data:`UNAVAILABLE`."""
    if label == "camera":
        return [f"camera lost from {when(a, T)} to {when(b, T)}; the other sensors carried the estimate"
                for a, b in uncovered_runs(T, covered, CAMERA_LOST)]
    return [f"{label} unavailable from {when(a, T)} to {when(b, T)}" for a, b in uncovered_runs(T, covered, UNAVAILABLE)]
