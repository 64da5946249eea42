"""Corner detectors: Harris-Stephens, Shi-Tomasi and FAST, with the three classic steps.

1. *Corner operator.* With the structure tensor ``M`` of a ``block_size`` neighbourhood
   (eigenvalues ``l1, l2``), Harris scores ``R = det M - k (trace M)^2 = l1 l2 - k (l1 + l2)^2``
   and Shi-Tomasi scores ``R = min(l1, l2)``. FAST scores the segment test on a 16-pixel circle.
2. *Threshold.* A corner needs ``R >= min_quality * max R`` and ``R >= min_metric`` (absolute;
   OpenCV normalises the derivatives so that ``R`` is that of the image scaled to [0, 1], as in the
   thesis' MATLAB block). FAST uses its intensity threshold instead.
3. *Non-maximum suppression.* A corner must be the maximum of its ``neighbourhood`` (rows x cols, odd);
   FAST additionally keeps one corner per ``neighbourhood``-sized cell.

The operator may run on a reduced image (``level``) for speed; see :func:`detect_corners`.

The ``max_corners`` strongest survivors are returned, optionally refined to sub-pixel positions by
``cv2.cornerSubPix`` (gradient orthogonality).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

DETECTORS = ("harris", "shi_tomasi", "fast")


@dataclass
class DetectorSettings:
    """Corner detector parameters (see :class:`frontends.features.FeatureConfig`)."""

    method: str = "shi_tomasi"
    max_corners: int = 150
    min_quality: float = 0.01
    min_metric: float = 0.0
    neighbourhood: tuple[int, int] = (15, 15)
    harris_k: float = 0.04
    block_size: int = 3
    fast_threshold: int = 20
    border: int = 16
    subpixel: bool = False
    level: int = 1


def _strongest(pts: np.ndarray, scores: np.ndarray, count: int) -> np.ndarray:
    order = np.argsort(-scores, kind="stable")[:count]
    return pts[order]


def _one_per_cell(pts: np.ndarray, scores: np.ndarray, cell: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Keep the strongest point of every ``cell`` (rows x cols) block."""
    if len(pts) == 0:
        return pts, scores
    order = np.argsort(-scores, kind="stable")
    pts, scores = pts[order], scores[order]
    key = (pts[:, 1] // cell[0]).astype(np.int64) * 100003 + (pts[:, 0] // cell[1]).astype(np.int64)
    _, first = np.unique(key, return_index=True)
    return pts[first], scores[first]


def detect_corners(image: np.ndarray, settings: DetectorSettings) -> np.ndarray:
    """Detect corners in a ``uint8`` image; returns ``N x 2`` float32 ``(x, y)`` positions.

    With ``settings.level = L > 0`` the corner operator runs on the image reduced ``2^L`` times
    (``cv2.pyrDown``; its pixel ``i`` is centred on full-resolution pixel ``2^L i``), which is ``4^L``
    times cheaper; the neighbourhood and border are then in reduced pixels too, and the positions are
    scaled back to full resolution (and refined there when ``subpixel`` is set).
    """
    s = settings
    full = image
    for _ in range(s.level):
        image = cv2.pyrDown(image)
    h, w = image.shape
    if s.method == "fast":
        fast = cv2.FastFeatureDetector_create(threshold=int(s.fast_threshold), nonmaxSuppression=True)
        kps = fast.detect(image)
        if not kps:
            return np.zeros((0, 2), np.float32)
        pts = np.array([k.pt for k in kps], np.float32)
        scores = np.array([k.response for k in kps], np.float32)
        pts, scores = _one_per_cell(pts, scores, s.neighbourhood)
    else:
        if s.method == "harris":
            response = cv2.cornerHarris(image, s.block_size, 3, s.harris_k)
        elif s.method == "shi_tomasi":
            response = cv2.cornerMinEigenVal(image, s.block_size, 3)
        else:
            raise ValueError(f"unknown detector {s.method!r} (choose from {', '.join(DETECTORS)})")
        kernel = np.ones(s.neighbourhood, np.uint8)
        peak = cv2.dilate(response, kernel)
        top = float(response.max())
        if top <= 0.0:
            return np.zeros((0, 2), np.float32)
        limit = max(s.min_quality * top, s.min_metric)
        keep = (response >= peak) & (response >= limit) & (response > 0)
        ys, xs = np.nonzero(keep)
        pts = np.stack([xs, ys], axis=1).astype(np.float32)
        scores = response[ys, xs]
    b = -(-s.border // (1 << s.level))
    inside = (pts[:, 0] >= b) & (pts[:, 0] < w - b) & (pts[:, 1] >= b) & (pts[:, 1] < h - b)
    pts = _strongest(pts[inside], scores[inside], s.max_corners) * float(1 << s.level)
    if s.subpixel and len(pts):
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 10, 0.01)
        pts = cv2.cornerSubPix(full, pts.reshape(-1, 1, 2).copy(), (3, 3), (-1, -1), criteria).reshape(-1, 2)
    return np.ascontiguousarray(pts, dtype=np.float32)
