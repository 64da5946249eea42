"""Where a KLT tracking attempt starts: the frame's own preparation, the set-up of an attempt from a guessed
motion (made here or ahead in another thread), and the coarse global shift by phase correlation.

A guess is a similarity in rectified coordinates. Through the point map it becomes an image-space affine
map ``A`` (least squares over the reference points it keeps in view): the tracker then warps the reference
by ``A`` and starts every point at ``A p0`` (:mod:`frontends.tracking`).
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass

import cv2
import numpy as np

from frontends.base import PointMap
from frontends.frame_check import Prepared
from frontends.klt_config import KltConfig
from frontends.similarity import apply_similarity
from frontends.tracking import WARP_HERE, fit_affine, warp_reference


@dataclass
class PreparedFrame(Prepared):
    """A frame prepared by :meth:`frontends.klt.KltFrontend.prepare`.

    Attributes
    ----------
    small : ndarray
        :func:`frontends.tracking.reduce_for_exposure` of its 8-bit version.
    """

    small: np.ndarray


@dataclass
class Setup:
    """Where an attempt starts: the reference points in view of the guess and the image-space motion.

    Attributes
    ----------
    p0 : ndarray, shape (k, 2)
        The reference points that the guess keeps in view (raw image coordinates, float64).
    src : ndarray, shape (k, 2)
        Their rectified coordinates.
    affine : ndarray, shape (2, 3)
        The guess as an image-space affine map (least squares through the point map).
    warped : ndarray or None or WARP_HERE
        :func:`frontends.tracking.warp_reference` of the reference by ``affine``, when it was made
        ahead; ``WARP_HERE`` when the tracker is to make it.
    """

    p0: np.ndarray
    src: np.ndarray
    affine: np.ndarray
    warped: object = WARP_HERE


def make_setup(point_map: PointMap, ref_pts: np.ndarray, ref_rect: np.ndarray, guess: np.ndarray,
               shape: tuple[int, int], border: int, min_inliers: int) -> Setup | None:
    """The :class:`Setup` of tracking ``ref_pts`` (rectified: ``ref_rect``) from the rectified similarity
    ``guess`` in frames of ``shape``; ``None`` when fewer than ``min_inliers`` points stay in view."""
    h, w = shape
    b = border
    init = point_map.to_image(apply_similarity(guess, ref_rect))
    inside = (init[:, 0] >= b) & (init[:, 0] <= w - 1 - b) & (init[:, 1] >= b) & (init[:, 1] <= h - 1 - b)
    if np.count_nonzero(inside) < min_inliers:
        return None
    p0 = ref_pts[inside].astype(np.float64)
    return Setup(p0, ref_rect[inside], fit_affine(p0, init[inside]))


@dataclass
class Ahead:
    """The predicted attempt of the next frame, set up in another thread
    (:meth:`frontends.klt.KltFrontend.set_executor`).

    It is used only when the frontend is in the state it was made for: the same reference image and
    points, and the same prediction (so the same next timestamp); it is then what the tracker would
    have computed itself, bit for bit.
    """

    ref_img: np.ndarray
    ref_pts: np.ndarray
    prediction: np.ndarray
    future: Future  # of (ref_rect, Setup or None)


def set_up_ahead(point_map: PointMap, ref_img: np.ndarray, ref_pts: np.ndarray, prediction: np.ndarray,
                 border: int, min_inliers: int, warp_tolerance: float) -> tuple[np.ndarray, Setup | None]:
    """What the tracker computes first for the predicted attempt: the rectified reference points and the
    attempt's :class:`Setup` with the reference warped."""
    ref_rect = point_map.to_rectified(ref_pts.astype(np.float64))
    setup = make_setup(point_map, ref_pts, ref_rect, prediction, ref_img.shape, border, min_inliers)
    if setup is not None:
        setup.warped = warp_reference(ref_img, setup.affine, warp_tolerance)
    return ref_rect, setup


def global_shift(ref: np.ndarray, img: np.ndarray, config: KltConfig,
                 hann: np.ndarray | None = None) -> tuple[tuple[float, float] | None, np.ndarray]:
    """Coarse translation (image px) of ``img`` against ``ref`` by phase correlation at ``config``'s
    ``global_downsample`` (None below ``min_global_response``), and the Hanning window used (pass it back in
    to reuse it for frames of the same size)."""
    f = config.global_downsample
    size = (img.shape[1] // f, img.shape[0] // f)
    a = cv2.resize(ref, size, interpolation=cv2.INTER_AREA).astype(np.float32)
    c = cv2.resize(img, size, interpolation=cv2.INTER_AREA).astype(np.float32)
    if hann is None or hann.shape != a.shape:
        hann = cv2.createHanningWindow(size, cv2.CV_32F)
    (dx, dy), response = cv2.phaseCorrelate(a, c, hann)
    if response < config.min_global_response:
        return None, hann
    return (dx * f, dy * f), hann
