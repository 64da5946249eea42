"""Rows of one output stream, sorted and de-duplicated before they are written.

Each stream is sorted by time; a sample whose stamp equals an earlier one of the same stream is dropped
(the first one in bag order is kept) and counted. The stream's rate is the inverse of the median
interval between the written timestamps.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from fusion_vo.recording.rosbag.summary import StreamSummary


class Rows:
    """Samples of one stream in bag order; sorted and de-duplicated on :meth:`finish`."""

    def __init__(self, summary: StreamSummary):
        self.summary = summary
        self.t: list[int] = []
        self.values: list[tuple] = []

    def add(self, t: int, values: tuple) -> None:
        self.t.append(t)
        self.values.append(values)

    def finish(self) -> tuple[np.ndarray, list[tuple]]:
        t = np.asarray(self.t, dtype=np.int64)
        order = np.argsort(t, kind="stable")
        t = t[order]
        keep = np.ones(len(t), dtype=bool)
        keep[1:] = t[1:] != t[:-1]
        self.summary.duplicates += int((~keep).sum())
        idx = order[keep]
        t = t[keep]
        _measure(self.summary, t)
        return t, [self.values[i] for i in idx]


def _measure(summary: StreamSummary, t: np.ndarray) -> None:
    summary.written = len(t)
    if len(t):
        summary.t_first_ns, summary.t_last_ns = int(t[0]), int(t[-1])
    if len(t) > 1:
        dt = np.median(np.diff(t)) * 1e-9
        summary.rate_hz = (round(float(1.0 / dt), 3) or None) if dt > 0 else None


def finite(values: Sequence[float]) -> bool:
    return all(math.isfinite(v) for v in values)


def matrix_entry(T: np.ndarray) -> dict:
    return {"cols": 4, "rows": 4, "data": [round(float(v), 9) + 0.0 for v in T.ravel()]}
