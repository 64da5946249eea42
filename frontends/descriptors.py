"""Descriptors of corner neighbourhoods and their distance matrices.

Normalised patches
    the ``(2r+1)^2`` intensities around a corner, made zero-mean and unit-norm, so that the Euclidean
    distance between two descriptors is ``sqrt(2 - 2 rho)`` with ``rho`` their normalised
    cross-correlation (insensitive to brightness and contrast changes). Range [0, 2].
ORB
    OpenCV's rotated-BRIEF 256-bit strings computed at the given corners (``cv2.ORB.compute``),
    compared by Hamming distance. Range [0, 256].
"""

from __future__ import annotations

import cv2
import numpy as np

DESCRIPTORS = ("patch", "orb")


def patch_descriptors(image: np.ndarray, pts: np.ndarray, radius: int) -> tuple[np.ndarray, np.ndarray]:
    """Zero-mean unit-norm patches around ``pts`` (rounded to whole pixels).

    Returns ``(descriptors (k, (2r+1)^2) float32, index (k,) of the points kept)``; points closer than
    ``radius`` to the border and flat patches are dropped.
    """
    h, w = image.shape
    xy = np.rint(pts).astype(np.int64)
    keep = (xy[:, 0] >= radius) & (xy[:, 0] < w - radius) & (xy[:, 1] >= radius) & (xy[:, 1] < h - radius)
    idx = np.flatnonzero(keep)
    off = np.arange(-radius, radius + 1)
    rows = xy[idx, 1][:, None, None] + off[None, :, None]
    cols = xy[idx, 0][:, None, None] + off[None, None, :]
    patches = image[rows, cols].reshape(len(idx), len(off) ** 2).astype(np.float32)  # also with no point
    patches -= patches.mean(axis=1, keepdims=True)
    norm = np.linalg.norm(patches, axis=1)
    ok = norm > 1e-3
    return patches[ok] / norm[ok, None], idx[ok]


def orb_descriptors(image: np.ndarray, pts: np.ndarray, orb: cv2.ORB) -> tuple[np.ndarray, np.ndarray]:
    """ORB descriptors at ``pts``; returns ``(descriptors (k, 32) uint8, index (k,) of the points kept)``."""
    kps = [cv2.KeyPoint(float(x), float(y), 31.0, 0.0, 0.0, 0, i) for i, (x, y) in enumerate(pts)]
    kps, desc = orb.compute(image, kps)
    if desc is None or not kps:
        return np.zeros((0, 32), np.uint8), np.zeros(0, np.int64)
    return desc, np.array([k.class_id for k in kps], np.int64)


def _gemm_t(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b.T`` in float32 through OpenCV (honours ``cv2.setNumThreads``, no BLAS thread pool)."""
    if len(a) == 0 or len(b) == 0:
        return np.zeros((len(a), len(b)), np.float32)
    return cv2.gemm(a, b, 1.0, None, 0.0, flags=cv2.GEMM_2_T)


def distance_matrix(d0: np.ndarray, d1: np.ndarray, kind: str) -> np.ndarray:
    """All pairwise descriptor distances (rows: ``d0``, columns: ``d1``) as float32."""
    if kind == "patch":
        corr = _gemm_t(np.ascontiguousarray(d0, np.float32), np.ascontiguousarray(d1, np.float32))
        return np.sqrt(np.maximum(2.0 - 2.0 * corr, 0.0))
    if kind == "orb":
        # Hamming distance = sum over bits of b0 (1 - b1) + (1 - b0) b1
        b0 = np.unpackbits(d0, axis=1).astype(np.float32)
        b1 = np.unpackbits(d1, axis=1).astype(np.float32)
        return _gemm_t(b0, 1.0 - b1) + _gemm_t(1.0 - b0, b1)
    raise ValueError(f"unknown descriptor {kind!r} (choose from {', '.join(DESCRIPTORS)})")
