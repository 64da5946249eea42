"""Corner correspondences between two frames, for looking at what a frontend sees.

The correspondences are found with the frontends' own building blocks and settings, in the way each
frontend finds them when it has no motion prediction:

* ``features``: corners (:func:`frontends.detectors.detect_corners`) with descriptors in both frames,
  matched by descriptor distance (:func:`frontends.matching.match_descriptors`);
* ``klt``: Shi-Tomasi corners of the previous frame tracked into the current one by pyramidal
  Lucas-Kanade (:func:`frontends.tracking.track_points`).

The matches are then split into inliers and outliers by the frontend's robust similarity estimator
(:func:`frontends.similarity.estimate_similarity`) in rectified coordinates.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

from frontends.base import IdentityMap, PointMap
from frontends.descriptors import distance_matrix, orb_descriptors, patch_descriptors
from frontends.detectors import DetectorSettings, detect_corners
from frontends.features import FeatureConfig
from frontends.frame_check import check_frame
from frontends.klt import KltConfig, global_shift
from frontends.matching import match_descriptors
from frontends.similarity import estimate_similarity
from frontends.tracking import track_points

logger = logging.getLogger(__name__)


@dataclass
class FrameMatches:
    """Corresponding corners of a previous and a current frame.

    Attributes
    ----------
    previous, current : ndarray, shape (n, 2)
        Pixel positions (raw image coordinates) in the previous and current frame.
    inliers : ndarray of bool, shape (n,)
        Matches consistent with the similarity the robust estimator found.
    matrix : ndarray, shape (2, 3)
        That similarity (rectified coordinates; identity when the estimate failed).
    status : str
        The estimator's verdict (``ok``, ``too_few`` or ``degenerate``).
    """

    previous: np.ndarray
    current: np.ndarray
    inliers: np.ndarray
    matrix: np.ndarray
    status: str

    @property
    def n_inliers(self) -> int:
        return int(np.count_nonzero(self.inliers))


def to_grey8(image: np.ndarray) -> np.ndarray:
    """A frame as the frontends see it: 2-D ``uint8`` (16-bit and colour frames converted)."""
    checked = check_frame(image, None, 0.0)
    if checked.image is None:
        raise ValueError(checked.reason or "unusable frame")
    return checked.image


def _feature_matches(prev: np.ndarray, cur: np.ndarray, config: FeatureConfig):
    detector = config.detector_settings()
    orb = (cv2.ORB_create(nfeatures=config.max_corners, edgeThreshold=16, patchSize=31)
           if config.descriptor == "orb" else None)

    def describe(img):
        pts = detect_corners(img, detector)
        if orb is not None:
            desc, idx = orb_descriptors(img, pts, orb)
        else:
            desc, idx = patch_descriptors(img, pts, config.patch_radius)
        return pts[idx].astype(np.float64), desc

    p0, d0 = describe(prev)
    p1, d1 = describe(cur)
    dist = distance_matrix(d0, d1, config.descriptor)
    i0, i1 = match_descriptors(dist, config.matcher, config.distance_limit, config.ratio, config.mutual)
    return p0[i0], p1[i1], config.robust_options(config.threshold), config.seed


def _klt_matches(prev: np.ndarray, cur: np.ndarray, config: KltConfig):
    detector = DetectorSettings(method="shi_tomasi", max_corners=config.max_tracks,
                                min_quality=config.quality_level, block_size=config.block_size,
                                border=config.border + config.window // 2, level=1)
    p0 = detect_corners(prev, detector).astype(np.float64).reshape(-1, 2)
    if not len(p0):  # a textureless frame: nothing to track (OpenCV rejects an empty point array)
        return p0, p0.copy(), config.robust_options(), config.seed
    tracked = track_points(prev, cur, p0, np.eye(2, 3), config.retry_pyramid_levels, config.lk_settings())
    if len(tracked.index) < config.min_inliers and config.global_fallback:
        # as the frontend does when the motion is too large to track from where the points were: from the
        # frames' shift by phase correlation
        shift, _ = global_shift(prev, cur, config)
        if shift is not None:
            guess = np.array([[1.0, 0.0, shift[0]], [0.0, 1.0, shift[1]]])
            moved = track_points(prev, cur, p0, guess, config.retry_pyramid_levels, config.lk_settings())
            if len(moved.index) > len(tracked.index):
                tracked = moved
    return p0[tracked.index], tracked.points, config.robust_options(), config.seed


def find_matches(previous: np.ndarray, current: np.ndarray, frontend: str = "features",
                 config: dict | None = None, point_map: PointMap | None = None) -> FrameMatches:
    """Match the corners of two frames the way ``frontend`` does and classify them.

    Parameters
    ----------
    previous, current : ndarray
        Grey frames (any depth; converted as the frontends convert them).
    frontend : str
        ``"features"`` or ``"klt"``.
    config : dict, optional
        Frontend settings (as for :func:`frontends.make_frontend`).
    point_map : PointMap, optional
        Raw pixels -> rectified coordinates (identity when omitted).

    Returns
    -------
    FrameMatches

    Raises
    ------
    ValueError
        For an unknown frontend, invalid settings or an unusable frame.
    """
    prev, cur = to_grey8(previous), to_grey8(current)
    if prev.shape != cur.shape:
        raise ValueError(f"frames differ in size: {prev.shape} and {cur.shape}")
    if frontend in ("features", "feature"):
        p0, p1, options, seed = _feature_matches(prev, cur, FeatureConfig.from_dict(config or {}))
    elif frontend == "klt":
        p0, p1, options, seed = _klt_matches(prev, cur, KltConfig.from_dict(config or {}))
    else:
        raise ValueError(f"unknown frontend {frontend!r} (choose 'klt' or 'features')")
    point_map = point_map or IdentityMap()
    if len(p0) == 0:
        return FrameMatches(p0.reshape(0, 2), p1.reshape(0, 2), np.zeros(0, bool), np.eye(2, 3), "too_few")
    fit = estimate_similarity(point_map.to_rectified(p0), point_map.to_rectified(p1), options,
                              np.random.default_rng(seed))
    inliers = fit.inliers if fit.inliers.size == len(p0) else np.zeros(len(p0), bool)
    logger.debug("%s: %d matches, %d inliers (%s)", frontend, len(p0), int(inliers.sum()), fit.status)
    return FrameMatches(p0, p1, inliers, fit.matrix, fit.status)
