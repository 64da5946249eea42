"""Camera intrinsics from chessboard views.

Model: a board corner ``X_F`` seen in view ``k`` projects to ``u = pi(K, d, R_k X_F + t_k)`` where ``pi``
is the pinhole projection followed by the lens distortion ``d``:

``radial-tangential`` (OpenCV ``calibrateCamera``, ``k3`` fixed at 0 unless three radial terms are
asked for)::

    r^2 = x^2 + y^2,   x' = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)   (y' likewise)

``equidistant`` (OpenCV ``fisheye``)::

    theta = atan(r),   theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8),
    x' = x theta_d / r

and ``u = fu x' + cu``, ``v = fv y' + cv``. The intrinsics ``(fu, fv, cu, cv, d)`` and the view poses
are found by minimising the squared reprojection error over all corners (Zhang's method, as in the
MATLAB toolbox the thesis used). The standard deviation of each parameter comes from the Gauss-Newton
covariance of that fit::

    Sigma = sigma^2 (J^T J)^-1,   sigma^2 = sum |r|^2 / (2 N - P)

with ``J`` the Jacobian of the residuals over all ``P`` parameters (intrinsics and view poses). OpenCV
returns it for the pinhole model; for the fisheye model it is computed here by finite differences.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from fusion_vo.calibration.chessboard import Board, detect_corners, read_image
from fusion_vo.errors import InputError
from fusion_vo.geometry.camera import CameraModel

logger = logging.getLogger(__name__)

#: ``--model`` names and the distortion model each one writes
MODELS = {"pinhole": "radial-tangential", "fisheye": "equidistant"}
#: fewest views with a detected board that a calibration accepts
MIN_VIEWS = 3

_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


@dataclass
class View:
    """One calibration image: its name and the detected board corners (``N x 2`` pixels)."""

    name: str
    corners: np.ndarray


@dataclass
class IntrinsicsResult:
    """Outcome of an intrinsic calibration.

    Attributes
    ----------
    distortion_model : str
        ``"radial-tangential"`` or ``"equidistant"``.
    image_size : tuple of int
        ``(width, height)`` [px].
    K : ndarray, shape (3, 3)
        Camera matrix.
    distortion : ndarray
        ``(k1, k2, p1, p2)``, ``(k1, k2, p1, p2, k3)`` or ``(k1, k2, k3, k4)``.
    std : dict
        Standard deviation of each parameter by name (``fu``, ``fv``, ``cu``, ``cv``, ``k1`` ...).
    rms : float
        RMS reprojection error over all corners, ``sqrt(mean(|r|^2))`` [px].
    pixel_error : ndarray, shape (2,)
        Standard deviation of the reprojection error along u and v [px] (the toolbox's "pixel error").
    per_view_rms : dict
        RMS reprojection error of each view by name [px].
    skipped : list of str
        Views in which the board was not found.
    rvecs, tvecs : list of ndarray
        Board pose in each used view.
    """

    distortion_model: str
    image_size: tuple[int, int]
    K: np.ndarray
    distortion: np.ndarray
    std: dict[str, float]
    rms: float
    pixel_error: np.ndarray
    per_view_rms: dict[str, float]
    skipped: list[str] = field(default_factory=list)
    rvecs: list[np.ndarray] = field(default_factory=list)
    tvecs: list[np.ndarray] = field(default_factory=list)

    @property
    def parameter_names(self) -> list[str]:
        if self.distortion_model == "radial-tangential":
            dist = ["k1", "k2", "p1", "p2", "k3"][: len(self.distortion)]
        else:
            dist = ["k1", "k2", "k3", "k4"]
        return ["fu", "fv", "cu", "cv"] + dist

    def to_camera(self, base: CameraModel | None = None) -> CameraModel:
        """A :class:`CameraModel` with these intrinsics; mounting and rate are taken from ``base``."""
        fu, fv, cu, cv = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        kwargs = {} if base is None else {"T_BS": base.T_BS.copy(), "rate_hz": base.rate_hz}
        return CameraModel(
            width=int(self.image_size[0]), height=int(self.image_size[1]), fu=fu, fv=fv, cu=cu, cv=cv,
            distortion_model=self.distortion_model, distortion=self.distortion.copy(), **kwargs,
        )

    def summary(self) -> str:
        """The result in the layout of the calibration toolbox (value +- standard deviation)."""
        s = self.std
        d = self.distortion
        dn = self.parameter_names[4:]
        lines = [
            f"Calibration results ({self.distortion_model}, {len(self.per_view_rms)} views, "
            f"{self.image_size[0]}x{self.image_size[1]} px):",
            f"  Focal length:     fc = [{self.K[0, 0]:.5f} {self.K[1, 1]:.5f}] +- [{s['fu']:.5f} {s['fv']:.5f}]",
            f"  Principal point:  cc = [{self.K[0, 2]:.5f} {self.K[1, 2]:.5f}] +- [{s['cu']:.5f} {s['cv']:.5f}]",
            "  Distortion:       kc = [" + " ".join(f"{v:.5f}" for v in d) + "] +- ["
            + " ".join(f"{s[n]:.5f}" for n in dn) + f"]   ({', '.join(dn)})",
            f"  Pixel error:      err = [{self.pixel_error[0]:.5f} {self.pixel_error[1]:.5f}]   "
            f"(RMS {self.rms:.5f} px)",
        ]
        worst = sorted(self.per_view_rms.items(), key=lambda kv: -kv[1])[:3]
        lines.append("  Worst views:      " + ", ".join(f"{n} ({e:.3f} px)" for n, e in worst))
        if self.skipped:
            lines.append(f"  Skipped ({len(self.skipped)}, board not found): " + ", ".join(self.skipped))
        return "\n".join(lines)


def detect_views(paths: Sequence[str | Path], board: Board) -> tuple[list[View], list[str], tuple[int, int]]:
    """Detect the board in image files.

    Returns the views with a detection, the names of the images without one, and the common image
    size. Raises :class:`InputError` when images are unreadable or differ in size.
    """
    if not paths:
        raise InputError("no calibration images given")
    sizes: dict[tuple[int, int], list[str]] = {}
    views: list[View] = []
    skipped: list[str] = []
    for p in paths:
        img = read_image(p)
        size = (int(img.shape[1]), int(img.shape[0]))
        sizes.setdefault(size, []).append(str(p))
        if len(sizes) > 1:
            continue  # reported below, once every size is known
        corners = detect_corners(img, board)
        if corners is None:
            logger.info("%s: board not found, skipped", p)
            skipped.append(str(p))
        else:
            views.append(View(str(p), corners))
    if len(sizes) > 1:
        raise InputError("calibration images differ in size: " + _describe_sizes(sizes))
    return views, skipped, next(iter(sizes))


def calibrate_images(paths: Sequence[str | Path], board: Board, model: str = "pinhole",
                     min_views: int = MIN_VIEWS, radial_terms: int = 2) -> IntrinsicsResult:
    """Detect the board in every image and calibrate; see :func:`calibrate_views`."""
    views, skipped, size = detect_views(paths, board)
    if not views:
        raise InputError(f"no {board.cols}x{board.rows} chessboard (inner corners) found in any of the "
                         f"{len(skipped)} images: {_name_list(skipped)}")
    if len(views) < min_views:
        raise InputError(f"the board was found in only {len(views)} image(s) ({_name_list([v.name for v in views])}); "
                         f"at least {min_views} are needed. Not found in: {_name_list(skipped) or 'none'}")
    result = calibrate_views(views, board, size, model, min_views, radial_terms)
    result.skipped = skipped
    return result


def calibrate_views(views: Sequence[View], board: Board, image_size: tuple[int, int], model: str = "pinhole",
                    min_views: int = MIN_VIEWS, radial_terms: int = 2) -> IntrinsicsResult:
    """Calibrate from detected corners.

    Parameters
    ----------
    views : detections, each with ``board.n_corners`` corners in :func:`Board.object_points` order.
    board : the board.
    image_size : ``(width, height)`` [px].
    model : ``"pinhole"`` (radial-tangential distortion) or ``"fisheye"`` (equidistant).
    min_views : fewest views accepted.
    radial_terms : ``2`` (``k1, k2``; ``k3`` fixed at 0, the default) or ``3`` (also ``k3``: for strong
        barrel lenses, with views that reach the image corners) for the ``pinhole`` model.
    """
    if model not in MODELS:
        raise InputError(f"unknown camera model '{model}' (use {' or '.join(MODELS)})")
    if radial_terms not in (2, 3) or (model == "fisheye" and radial_terms != 2):
        raise InputError(f"radial terms: 2 or 3, for the pinhole model only (got {radial_terms} for {model})")
    if len(views) < min_views:
        raise InputError(f"{len(views)} view(s) given, at least {min_views} are needed: "
                         f"{_name_list([v.name for v in views]) or 'none'}")
    for v in views:
        if v.corners.shape != (board.n_corners, 2):
            raise InputError(f"expected {board.n_corners} corners, got {len(v.corners)}", v.name)
    obj = board.object_points()
    if model == "pinhole":
        K, dist, rvecs, tvecs, std = _calibrate_pinhole(views, obj, image_size, radial_terms)
        project = _project_pinhole
    else:
        K, dist, rvecs, tvecs, std = _calibrate_fisheye(views, obj, image_size)
        project = _project_fisheye
    residuals = {}
    for v, r, t in zip(views, rvecs, tvecs):
        residuals[v.name] = project(obj, r, t, K, dist) - v.corners
    allres = np.concatenate(list(residuals.values()))
    result = IntrinsicsResult(
        distortion_model=MODELS[model], image_size=(int(image_size[0]), int(image_size[1])), K=K, distortion=dist,
        std={}, rms=float(np.sqrt(np.mean(np.sum(allres**2, axis=1)))), pixel_error=allres.std(axis=0),
        per_view_rms={n: float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) for n, r in residuals.items()},
        rvecs=list(rvecs), tvecs=list(tvecs),
    )
    result.std = dict(zip(result.parameter_names, (float(s) for s in std)))
    logger.info("calibrated %d views: RMS %.4f px", len(views), result.rms)
    return result


# ---------------------------------------------------------------------------------------------- models
def _project_pinhole(obj, rvec, tvec, K, dist) -> np.ndarray:
    pts, _ = cv2.projectPoints(obj.reshape(-1, 1, 3), rvec, tvec, K, dist)
    return pts.reshape(-1, 2)


def _project_fisheye(obj, rvec, tvec, K, dist) -> np.ndarray:
    pts, _ = cv2.fisheye.projectPoints(obj.reshape(-1, 1, 3), np.asarray(rvec, float).reshape(3, 1),
                                       np.asarray(tvec, float).reshape(3, 1), K, dist)
    return pts.reshape(-1, 2)


def _calibrate_pinhole(views, obj, image_size, radial_terms: int = 2):
    objs = [obj.astype(np.float32)] * len(views)
    imgs = [v.corners.astype(np.float32).reshape(-1, 1, 2) for v in views]
    flags = cv2.CALIB_FIX_K3 if radial_terms == 2 else 0
    try:
        out = cv2.calibrateCameraExtended(objs, imgs, tuple(image_size), None, None, flags=flags, criteria=_CRITERIA)
    except cv2.error as exc:
        raise InputError(f"calibration failed ({exc.err}); the views may not constrain the camera "
                         f"(vary the board's tilt and position): {_name_list([v.name for v in views])}") from None
    _, K, dist, rvecs, tvecs, std_intr, _, _ = out
    n = 4 if radial_terms == 2 else 5
    dist = dist.ravel()[:n].astype(np.float64)
    std = std_intr.ravel()[: 4 + n]  # fx, fy, cx, cy, k1, k2, p1, p2 (, k3)
    return K, dist, [r.ravel() for r in rvecs], [t.ravel() for t in tvecs], std


def _calibrate_fisheye(views, obj, image_size):
    objs = [obj.reshape(1, -1, 3).astype(np.float64)] * len(views)
    imgs = [v.corners.reshape(1, -1, 2).astype(np.float64) for v in views]
    # OpenCV 4 keeps the fisheye flags in cv2.fisheye, OpenCV 5 in cv2
    flag = lambda name: getattr(cv2.fisheye, name, None) or getattr(cv2, name)  # noqa: E731
    flags = flag("CALIB_RECOMPUTE_EXTRINSIC") | flag("CALIB_FIX_SKEW")
    try:
        _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(objs, imgs, tuple(image_size), None, None, flags=flags,
                                                      criteria=_CRITERIA)
    except cv2.error as exc:
        raise InputError(f"fisheye calibration failed ({exc.err}); the views may not constrain the camera: "
                         f"{_name_list([v.name for v in views])}") from None
    rvecs = [np.asarray(r, float).ravel() for r in rvecs]
    tvecs = [np.asarray(t, float).ravel() for t in tvecs]
    dist = D.ravel().astype(np.float64)
    std = reprojection_std(_project_fisheye, K, dist, rvecs, tvecs, obj, [v.corners for v in views])
    return K, dist, rvecs, tvecs, std


def reprojection_std(project: Callable, K: np.ndarray, dist: np.ndarray, rvecs, tvecs, obj: np.ndarray,
                     corners: Sequence[np.ndarray], step: float = 1e-6) -> np.ndarray:
    """Standard deviations of ``(fu, fv, cu, cv, d...)`` from the Gauss-Newton covariance.

    The Jacobian of the reprojection residuals over the intrinsics and every view's pose is taken by
    central differences; the view poses are eliminated with the Schur complement.
    """
    n_d = len(dist)

    def intr_vec():
        return np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], dist])

    def unpack(p):
        Kp = np.array([[p[0], 0.0, p[2]], [0.0, p[1], p[3]], [0.0, 0.0, 1.0]])
        return Kp, p[4:4 + n_d]

    p0 = intr_vec()
    n_i = len(p0)
    A = np.zeros((n_i, n_i))  # intrinsics block of J^T J after eliminating the poses
    sq, n_res = 0.0, 0
    for rvec, tvec, uv in zip(rvecs, tvecs, corners):
        def res(p, pose):
            Kp, dp = unpack(p)
            return (project(obj, pose[:3], pose[3:], Kp, dp) - uv).ravel()

        pose0 = np.concatenate([rvec, tvec])
        r0 = res(p0, pose0)
        sq += float(r0 @ r0)
        n_res += len(r0)
        Ji = np.empty((len(r0), n_i))
        for k in range(n_i):
            h = step * max(1.0, abs(p0[k]))
            dp = np.zeros(n_i)
            dp[k] = h
            Ji[:, k] = (res(p0 + dp, pose0) - res(p0 - dp, pose0)) / (2 * h)
        Jp = np.empty((len(r0), 6))
        for k in range(6):
            dq = np.zeros(6)
            dq[k] = step
            Jp[:, k] = (res(p0, pose0 + dq) - res(p0, pose0 - dq)) / (2 * step)
        Hpp = Jp.T @ Jp
        Hip = Ji.T @ Jp
        A += Ji.T @ Ji - Hip @ np.linalg.solve(Hpp, Hip.T)
    n_par = n_i + 6 * len(rvecs)
    sigma2 = sq / max(1, n_res - n_par)
    cov = sigma2 * np.linalg.pinv(A)
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))


def _describe_sizes(sizes: dict[tuple[int, int], list[str]]) -> str:
    return "; ".join(f"{w}x{h}: {_name_list(names)}" for (w, h), names in sizes.items())


def _name_list(names: Sequence[str], limit: int = 12) -> str:
    names = list(names)
    text = ", ".join(names[:limit])
    if len(names) > limit:
        text += f" and {len(names) - limit} more"
    return text
