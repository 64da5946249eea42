"""Reading a run's TUM track and its ATE against the recording's ground truth (for the consistency tests)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def read_tum(path: Path) -> np.ndarray:
    """``t x y`` of a TUM file."""
    return np.loadtxt(path, comments="#", ndmin=2)[:, :3]


def ate(track: np.ndarray, rec: Path) -> float:
    """RMS position error [m] of ``t x y`` rows against the recording's ground truth after the least-squares
    rotation and translation on the plane."""
    gt = np.loadtxt(rec / "state_groundtruth_estimate0" / "data.csv", delimiter=",", comments="#", ndmin=2)
    t_gt = gt[:, 0] * 1e-9
    keep = (track[:, 0] >= t_gt[0]) & (track[:, 0] <= t_gt[-1])
    p = track[keep, 1:3]
    g = np.column_stack([np.interp(track[keep, 0], t_gt, gt[:, i]) for i in (1, 2)])
    pc, gc = p - p.mean(0), g - g.mean(0)
    u, _, vt = np.linalg.svd(pc.T @ gc)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, d]) @ u.T
    e = pc @ r.T - gc
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
