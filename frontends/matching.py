"""Descriptor matching strategies on a distance matrix ``D`` (rows: previous frame, columns: current).

threshold
    every pair with ``D_ij < t`` (a corner may get several matches).
nearest
    ``j = argmin_j D_ij`` if ``D_ij < t`` (at most one match per previous corner).
ratio
    nearest-neighbour distance ratio: the nearest ``j1`` is kept if ``D_ij1 < t`` and
    ``D_ij1 < r D_ij2`` with ``j2`` the second nearest (Lowe's test).

With ``mutual`` a pair is kept only if each corner is also the other's nearest neighbour. Pairs that a
spatial gate forbids (``D = inf``) are never matched.
"""

from __future__ import annotations

import numpy as np

MATCHERS = ("threshold", "nearest", "ratio")


def match_descriptors(
    dist: np.ndarray, method: str, max_distance: float, ratio: float = 0.8, mutual: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Return index arrays ``(i0, i1)`` of matched rows and columns of ``dist``."""
    n0, n1 = dist.shape
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    if n0 == 0 or n1 == 0:
        return empty
    if method == "threshold":
        i0, i1 = np.nonzero(dist < max_distance)
    elif method in ("nearest", "ratio"):
        i0 = np.arange(n0)
        if method == "ratio" and n1 >= 2:
            # the nearest, then the nearest of the rest: a fifth of the time of a partition on these sizes
            i1 = np.argmin(dist, axis=1)
            best = dist[i0, i1]
            rest = dist.copy()
            rest[i0, i1] = np.inf
            second = rest.min(axis=1)
            ok = (best < max_distance) & (best < ratio * second)
        else:
            i1 = np.argmin(dist, axis=1)
            best = dist[i0, i1]
            ok = best < max_distance
        i0, i1 = i0[ok], i1[ok]
    else:
        raise ValueError(f"unknown matcher {method!r} (choose from {', '.join(MATCHERS)})")
    if mutual and len(i0):
        back = np.argmin(dist, axis=0)
        fwd = np.argmin(dist, axis=1)
        ok = (back[i1] == i0) & (fwd[i0] == i1)
        i0, i1 = i0[ok], i1[ok]
    return i0.astype(np.int64), i1.astype(np.int64)


def gate_distances(dist: np.ndarray, predicted: np.ndarray, pts1: np.ndarray, radius: float) -> np.ndarray:
    """Set ``D_ij = inf`` where current corner ``j`` lies farther than ``radius`` from prediction ``i``."""
    dx = predicted[:, 0, None] - pts1[None, :, 0]  # per axis: a sum over a last axis of length 2 is slow
    dy = predicted[:, 1, None] - pts1[None, :, 1]
    return np.where(dx * dx + dy * dy > radius * radius, dist.dtype.type(np.inf), dist)
