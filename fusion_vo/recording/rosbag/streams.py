"""Rows of one output stream and the text files they are written to.

Each stream is sorted by time; a sample whose stamp equals an earlier one of the same stream is dropped
(the first one in bag order is kept) and counted. The stream's rate is the inverse of the median
interval between the written timestamps.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np
import yaml

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
        summary.rate_hz = round(float(1.0 / dt), 3) if dt > 0 else None


def write_csv(path: Path, header: str, t: np.ndarray, rows: Sequence[Sequence], fmt: str | Sequence[str]) -> None:
    """Write ``timestamp,v1,v2,...`` rows; ``fmt`` is one %-format for all values or one per column."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        f.write(header + "\n")
        for ti, row in zip(t, rows):
            fmts = [fmt] * len(row) if isinstance(fmt, str) else fmt
            f.write(f"{int(ti)}," + ",".join(fm % v for fm, v in zip(fmts, row)) + "\n")


def finite(values: Sequence[float]) -> bool:
    return all(math.isfinite(v) for v in values)


def yaml_text(comments: Sequence[str], data: dict) -> str:
    head = "".join(f"# {c}\n" for c in comments)
    return head + yaml.safe_dump(data, sort_keys=False, default_flow_style=None)


def matrix_entry(T: np.ndarray) -> dict:
    return {"cols": 4, "rows": 4, "data": [round(float(v), 9) + 0.0 for v in T.ravel()]}
