"""The live monitor keeps the window it judges for every sensor alike: readings over node pairs (the camera's
increments, or a registered sensor's that declares its per-reading arrays in ``ROWS``) are kept, rebuilt, trimmed
and cut back at a rewind by position, with no sensor named."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from fusion_vo.backends import FusionConfig
from fusion_vo.backends.live_monitor import LiveHeadingMonitor
from fusion_vo.backends.timeline import Intervals

DT = 0.1


@dataclass
class TapeGrid:
    """Readings over node pairs of a registered sensor: a length each, and a per-reading array the monitor does
    not keep (``note``, back to its default in the window)."""

    ROWS: ClassVar[tuple] = ("length",)

    i0: np.ndarray
    i1: np.ndarray
    length: np.ndarray
    note: np.ndarray | None = None


def _interval(k: int, lengths) -> Intervals:
    """The two-node interval ``k`` with the tape readings ``lengths`` over it."""
    n = len(lengths)
    tape = TapeGrid(np.zeros(n, int), np.ones(n, int), np.asarray(lengths, float), np.arange(n, dtype=float))
    return Intervals(t=np.array([k * DT, (k + 1) * DT]), sensors={"tape": tape})


def _readings(k: int) -> list[float]:
    """Interval ``k`` has ``k % 3`` readings (none, one, two)."""
    return [1000.0 * k + j for j in range(k % 3)]


def _expected(merged: Intervals, lengths: dict[int, list[float]]) -> tuple[np.ndarray, np.ndarray]:
    """The readings from the window's first node on, with their first node counted from it."""
    k0 = int(round(merged.t[0] / DT))
    i0 = [k - k0 for k in sorted(lengths) if k >= k0 for _ in lengths[k]]
    values = [v for k in sorted(lengths) if k >= k0 for v in lengths[k]]
    return np.array(i0, int), np.array(values)


def test_readings_over_node_pairs_are_windowed_by_position_for_any_sensor():
    monitor = LiveHeadingMonitor(FusionConfig(), history=2.0)
    lengths = {}
    states = {}
    for k in range(700):  # 70 s: the window (15 monitor windows, 30 s) moves on and old rows are forgotten
        lengths[k] = _readings(k)
        monitor.add(_interval(k, lengths[k]))
        states[k] = monitor.state()
    lengths[690] = [-1.0, -2.0]  # rebuilt with late data: its readings replaced
    monitor.update(690, _interval(690, lengths[690]))

    merged = monitor._merged()
    tape = merged.sensors["tape"]
    assert merged.t[0] > 30.0 and len(merged.t) < 400, merged.t[0]  # (trimmed)
    i0, values = _expected(merged, lengths)
    assert np.array_equal(tape.i0, i0) and np.array_equal(tape.i1, i0 + 1)
    assert np.array_equal(tape.length, values)
    assert tape.note is None  # (not a kept row: its default)

    monitor.restore(states[680])  # a rewind to after interval 680: the later readings are gone
    merged = monitor._merged()
    kept = {k: v for k, v in lengths.items() if k <= 680}
    i0, values = _expected(merged, kept)
    assert abs(merged.t[-1] - 681 * DT) < 1e-9
    assert np.array_equal(merged.sensors["tape"].i0, i0) and np.array_equal(merged.sensors["tape"].length, values)
