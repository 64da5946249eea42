"""The lens distortion of an uncalibrated camera, estimated from the frames themselves.

Over a flat floor seen from above, the undistorted image of one frame maps onto the next by a
similarity. A lens that bends straight lines breaks that: the flow of a translation grows or shrinks
with the distance from the centre. So the distortion can be found without a calibration board, by
choosing the lens that makes the tracked points of many frame pairs fit their similarities best.

The lens is the one-parameter division model (``distortion_model: division``, see
:mod:`fusion_vo.geometry.camera`), ``x_u = x_d / (1 + lambda |x_d|^2)`` in normalised coordinates about
the image centre: one number that describes barrel lenses up to wide-angle and fisheye-like mappings
well enough for odometry (Fitzgibbon, "Simultaneous linear estimation of multiple view geometry and lens
distortion", CVPR 2001). The focal length is not estimated: ``lambda`` and the focal length only
matter together (``lambda / f^2`` in pixels), so the estimate fits whatever focal length the camera
model states.

Points are Shi-Tomasi corners tracked by pyramidal Lucas-Kanade forwards and backwards (OpenCV) in
``pairs`` consecutive frame pairs spread over the recording. For each candidate ``lambda``, each pair's
similarity is fitted to the undistorted points (iteratively reweighted least squares) and scored by the
reprojection error in the raw image, truncated at ``TRUNCATE_PX`` so that mismatches do not steer it.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import cv2
import numpy as np

from fusion_vo.geometry.camera import CameraModel
from fusion_vo.robust import robust_weight

logger = logging.getLogger(__name__)

#: reprojection errors beyond this [px] count as this (mismatched or occluded points)
TRUNCATE_PX = 2.0
#: fewest forward-backward-consistent tracks for a frame pair to count
MIN_TRACKS = 8
#: fewest frame pairs with enough tracks and motion for an estimate
MIN_PAIRS = 5
#: smallest median flow [px] for a frame pair to carry information on the lens
MIN_FLOW_PX = 2.0


@dataclass
class LensEstimate:
    """The division-model coefficient found and how well it explains the tracks.

    Attributes
    ----------
    lam : float
        ``lambda`` of the division model in normalised coordinates of the camera it was fitted for.
    pairs, points : int
        Frame pairs and tracked points used.
    rms_px, rms_px_without : float
        RMS reprojection error [px] (truncated) of the tracks with the estimated lens and without any.
    """

    lam: float
    pairs: int
    points: int
    rms_px: float
    rms_px_without: float


def _grey8(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint8:
        return img
    top = float(img.max()) or 1.0
    return np.clip(img.astype(np.float32) * (255.0 / top), 0, 255).astype(np.uint8)


def track_pair(prev: np.ndarray, cur: np.ndarray, max_corners: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Corners of ``prev`` and where they are in ``cur`` (N x 2 each), forward-backward consistent."""
    prev, cur = _grey8(prev), _grey8(cur)
    diag = float(np.hypot(*prev.shape[:2]))
    p0 = cv2.goodFeaturesToTrack(prev, max_corners, 0.01, max(5.0, diag / 60.0), blockSize=5)
    if p0 is None or len(p0) < MIN_TRACKS:
        return np.empty((0, 2)), np.empty((0, 2))
    lk = dict(winSize=(21, 21), maxLevel=3, criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01))
    p1, st, _ = cv2.calcOpticalFlowPyrLK(prev, cur, p0, None, **lk)
    if p1 is None:
        return np.empty((0, 2)), np.empty((0, 2))
    back, st2, _ = cv2.calcOpticalFlowPyrLK(cur, prev, p1, None, **lk)
    ok = (st.ravel() == 1) & (st2.ravel() == 1) & (np.linalg.norm((back - p0).reshape(-1, 2), axis=1) < 0.5)
    h, w = prev.shape[:2]
    q = p1.reshape(-1, 2)
    ok &= (q[:, 0] >= 0) & (q[:, 0] <= w - 1) & (q[:, 1] >= 0) & (q[:, 1] <= h - 1)
    return p0.reshape(-1, 2)[ok].astype(np.float64), q[ok].astype(np.float64)


def _fit_similarity(u0: np.ndarray, u1: np.ndarray, w: np.ndarray) -> tuple[complex, complex]:
    """Weighted least-squares ``u1 = a u0 + b`` in complex numbers (a = s e^{i theta})."""
    z0 = u0[:, 0] + 1j * u0[:, 1]
    z1 = u1[:, 0] + 1j * u1[:, 1]
    sw = w.sum()
    m0, m1 = (w * z0).sum() / sw, (w * z1).sum() / sw
    d0 = z0 - m0
    a = (w * np.conj(d0) * (z1 - m1)).sum() / max(float((w * np.abs(d0) ** 2).sum()), 1e-18)
    return a, m1 - a * m0


def pair_errors(cam: CameraModel, p0: np.ndarray, p1: np.ndarray, iterations: int = 4) -> np.ndarray:
    """Reprojection errors [px] of one pair's tracks under ``cam``'s lens and their best similarity."""
    u0, u1 = cam.normalize(p0), cam.normalize(p1)
    good = np.all(np.isfinite(u0), axis=1) & np.all(np.isfinite(u1), axis=1)
    err = np.full(len(p0), np.inf)
    if good.sum() < 3:
        return err
    u0, u1, q1 = u0[good], u1[good], p1[good]
    w = np.ones(len(u0))
    for _ in range(iterations):
        a, b = _fit_similarity(u0, u1, w)
        z = a * (u0[:, 0] + 1j * u0[:, 1]) + b
        pred = cam.denormalize(np.column_stack([z.real, z.imag]))
        e = np.linalg.norm(pred - q1, axis=1)
        e = np.where(np.isfinite(e), e, np.inf)
        w = robust_weight(e / TRUNCATE_PX, "cauchy", 1.0)
    err[good] = e
    return err


def estimate_division(cam: CameraModel, tracks: list[tuple[np.ndarray, np.ndarray]],
                      bounds: tuple[float, float] = (-1.0, 0.5)) -> LensEstimate | None:
    """The division-model ``lambda`` that best explains ``tracks`` (pairs of N x 2 pixel arrays).

    ``cam`` gives the focal length and principal point; its own distortion is ignored. Returns
    ``None`` when fewer than :data:`MIN_PAIRS` pairs have enough tracks and motion.
    """
    used = [(p0, p1) for p0, p1 in tracks
            if len(p0) >= MIN_TRACKS and np.median(np.linalg.norm(p1 - p0, axis=1)) >= MIN_FLOW_PX]
    if len(used) < MIN_PAIRS:
        return None
    # the model must stay defined (1 + lambda r^2 > 0) out to the image corners
    corners = np.array([[0, 0], [cam.width - 1, 0], [0, cam.height - 1], [cam.width - 1, cam.height - 1]], float)
    r2max = float(np.max(np.sum(((corners - [cam.cu, cam.cv]) / [cam.fu, cam.fv]) ** 2, axis=1)))
    lo = max(bounds[0], -0.9 / r2max)
    hi = bounds[1]
    points = sum(len(p0) for p0, _ in used)

    def cost(lam: float) -> float:
        model = dataclasses.replace(cam, distortion_model="division", distortion=np.array([lam]))
        total = 0.0
        for p0, p1 in used:
            e = np.minimum(pair_errors(model, p0, p1), TRUNCATE_PX)
            total += float(np.sum(e * e))
        return total / points

    from scipy.optimize import minimize_scalar  # only uncalibrated runs need scipy here

    grid = np.linspace(lo, hi, 31)
    costs = [cost(float(g)) for g in grid]
    k = int(np.argmin(costs))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    res = minimize_scalar(cost, bounds=(a, b), method="bounded", options={"xatol": 1e-4})
    lam = float(res.x) if res.fun <= costs[k] else float(grid[k])
    est = LensEstimate(lam, len(used), points, float(np.sqrt(cost(lam))), float(np.sqrt(cost(0.0))))
    logger.info("lens from motion: lambda %.4f from %d frame pairs, %d tracks; RMS reprojection %.2f px "
                "(%.2f px without distortion)", est.lam, est.pairs, est.points, est.rms_px, est.rms_px_without)
    return est


def recording_tracks(recording, pairs: int = 40) -> list[tuple[np.ndarray, np.ndarray]]:
    """Tracks of ``pairs`` consecutive frame pairs spread evenly over ``recording``'s frames."""
    n = len(recording)
    if n < 2:
        return []
    starts = np.unique(np.linspace(0, n - 2, min(pairs, n - 1)).round().astype(int))
    out = []
    for k in starts:
        frames = list(recording.frames(int(k), int(k) + 2))
        if len(frames) < 2 or frames[0].image is None or frames[1].image is None:
            continue
        if frames[0].image.shape != frames[1].image.shape:
            continue
        out.append(track_pair(frames[0].image, frames[1].image))
    return out


def lens_from_motion(recording, cam: CameraModel, pairs: int = 40) -> tuple[CameraModel, LensEstimate | None]:
    """``cam`` with the division-model lens estimated from ``recording``'s frames.

    Returns ``cam`` unchanged and ``None`` when the frames do not allow an estimate (too few tracks or
    too little motion), or when the estimated lens does not explain the tracks better than none.
    """
    est = estimate_division(cam, recording_tracks(recording, pairs))
    if est is None or not est.rms_px < 0.95 * est.rms_px_without:
        logger.warning("%s: the lens distortion could not be estimated from the frames; assuming none",
                       recording.path)
        return cam, None
    return dataclasses.replace(cam, distortion_model="division", distortion=np.array([est.lam])), est


#: the frames contradict a lens stated without distortion when a lens explains their tracks this much better
CONTRADICTION_RATIO = 0.7


def check_stated_lens(recording, cam: CameraModel, pairs: int = 40) -> tuple[CameraModel, LensEstimate | None]:
    """``cam`` (a calibration that states no distortion) checked against ``recording``'s frames.

    A ``sensor.yaml`` holding a focal length and no distortion is common (a data sheet's figure, a
    calibration that was never done), and a wide lens then biases every increment: on
    ``real_gravel_focal_only`` the visual track came out 6 % short and turned 4.9 degrees too little,
    while its covariance said nothing of it. When a division-model lens explains the frames' tracks with
    at most :data:`CONTRADICTION_RATIO` times the reprojection error of no distortion, that lens is
    returned with a warning naming the file; otherwise ``cam`` unchanged. A true pinhole gives a ratio of
    1 (``lambda`` 0), a barrel lens 0.17 (0.27 against 1.60 px on that recording).
    """
    est = estimate_division(cam, recording_tracks(recording, pairs))
    if est is None or not est.rms_px < CONTRADICTION_RATIO * est.rms_px_without:
        return cam, None
    logger.warning("%s states no lens distortion, but the frames show one: a division-model lens (lambda %.3f) "
                   "explains their tracks to %.2f px RMS against %.2f px without; using it (odometry: "
                   "{check_lens: false} keeps the file's model)", recording.path / "cam0" / "sensor.yaml",
                   est.lam, est.rms_px, est.rms_px_without)
    return dataclasses.replace(cam, distortion_model="division", distortion=np.array([est.lam])), est
