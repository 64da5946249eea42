"""Camera model: pinhole intrinsics, lens distortion and the camera's pose in the body frame.

A camera point ``X_S = (x, y, z)`` (OpenCV frame: x right, y down, z along the optical axis) projects to
normalised coordinates ``(x/z, y/z)``, is distorted by the lens model and mapped to pixels by ``K``::

    K = [[fu, 0, cu], [0, fv, cv], [0, 0, 1]]

Distortion models (as in ``cam0/sensor.yaml``):

``radial-tangential``  OpenCV's ``(k1, k2, p1, p2[, k3])``;
``equidistant``        OpenCV's fisheye model ``(k1, k2, k3, k4)``;
``division``           the one-parameter division model ``(lambda,)``: a distorted normalised point
                       ``x_d`` comes from ``x_d / (1 + lambda |x_d|^2)`` (barrel: ``lambda < 0``); what
                       ``--uncalibrated`` estimates from the frames themselves
                       (:mod:`fusion_vo.calibration.lens_from_motion`);
``none``               no distortion.

``T_BS`` maps camera coordinates to body coordinates: ``X_B = R_BS X_S + t_BS``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from fusion_vo.config.files import load_yaml, write_yaml_atomic
from fusion_vo.errors import InputError

DISTORTION_MODELS = ("radial-tangential", "equidistant", "division", "none")

#: camera looking straight down with image-up pointing forward (x_S = -y_B, y_S = -x_B, z_S = -z_B)
R_BS_DOWN_FORWARD = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass
class CameraModel:
    """Intrinsics, distortion and mounting of one camera.

    Attributes
    ----------
    width, height : int
        Image size [px].
    fu, fv, cu, cv : float
        Focal lengths and principal point [px].
    distortion_model : str
        One of :data:`DISTORTION_MODELS`.
    distortion : ndarray
        Distortion coefficients of that model.
    T_BS : ndarray, shape (4, 4)
        Camera pose in the body frame.
    rate_hz : float
        Nominal frame rate (informative; real timestamps are always used).
    """

    width: int
    height: int
    fu: float
    fv: float
    cu: float
    cv: float
    distortion_model: str = "none"
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(4))
    T_BS: np.ndarray = field(default_factory=lambda: default_T_BS())
    rate_hz: float = 20.0

    def __post_init__(self) -> None:
        self.distortion = np.asarray(self.distortion, dtype=np.float64).ravel()
        self.T_BS = np.asarray(self.T_BS, dtype=np.float64).reshape(4, 4)
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(f"unknown distortion model {self.distortion_model!r}")
        self._distorted = self.distortion_model != "none" and bool(np.any(self.distortion != 0))

    # ------------------------------------------------------------------ matrices
    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fu, 0.0, self.cu], [0.0, self.fv, self.cv], [0.0, 0.0, 1.0]])

    @property
    def R_BS(self) -> np.ndarray:
        return self.T_BS[:3, :3]

    @property
    def t_BS(self) -> np.ndarray:
        return self.T_BS[:3, 3]

    @property
    def has_distortion(self) -> bool:
        """Whether the lens model changes any point (fixed when the model is built)."""
        return self._distorted

    # ------------------------------------------------------------------ points
    def normalize(self, pixels: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates ``(x/z, y/z)`` of raw pixel positions (N x 2)."""
        pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        if not self.has_distortion:
            out = (pts.reshape(-1, 2) - [self.cu, self.cv]) / [self.fu, self.fv]
            return out
        if self.distortion_model == "equidistant":
            out = cv2.fisheye.undistortPoints(pts, self.K, self.distortion[:4])
        elif self.distortion_model == "division":
            xd = (pts.reshape(-1, 2) - [self.cu, self.cv]) / [self.fu, self.fv]
            denom = 1.0 + self.distortion[0] * np.sum(xd * xd, axis=1, keepdims=True)
            # beyond the model's horizon (1 + lambda r^2 <= 0) the ray is undefined
            return np.where(denom > 1e-6, xd / np.maximum(denom, 1e-6), np.nan)
        else:
            out = cv2.undistortPoints(
                pts, self.K, self.distortion, None, None, None,
                (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-10),
            )
        return out.reshape(-1, 2)

    def denormalize(self, normalized: np.ndarray) -> np.ndarray:
        """Raw (distorted) pixel positions of normalised coordinates (N x 2)."""
        xy = np.asarray(normalized, dtype=np.float64).reshape(-1, 2)
        if not self.has_distortion:
            return xy * [self.fu, self.fv] + [self.cu, self.cv]
        if self.distortion_model == "equidistant":
            out = cv2.fisheye.distortPoints(xy.reshape(-1, 1, 2), self.K, self.distortion[:4])
            return out.reshape(-1, 2)
        if self.distortion_model == "division":
            # r_d solves lambda r_u r_d^2 - r_d + r_u = 0; the root that tends to r_u as lambda -> 0
            disc = 1.0 - 4.0 * self.distortion[0] * np.sum(xy * xy, axis=1, keepdims=True)
            xd = 2.0 * xy / (1.0 + np.sqrt(np.where(disc >= 0, disc, np.nan)))
            return xd * [self.fu, self.fv] + [self.cu, self.cv]
        return self._distort_radtan(xy)

    def _distort_radtan(self, xy: np.ndarray) -> np.ndarray:
        """Pixels of normalised points (N x 2) through the radial-tangential model.

        The polynomial of ``cv2.projectPoints`` with the same order of operations, so the results are
        the same to the last bit, without its Jacobians with respect to every parameter, which
        ``projectPoints`` always computes from Python. On the dense fallback's remap grid of a 640 x 360
        frame this takes about 22 ms of CPU against ``projectPoints``' 100 ms, on a few points as long
        (commit 159b4c1, measured by the retired benchmark that
        ``git show 159b4c1:benchmarks/bench_tracker.py`` prints).
        """
        k1, k2, p1, p2 = self.distortion[:4]
        k3 = self.distortion[4] if len(self.distortion) > 4 else 0.0
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        r4 = r2 * r2
        r6 = r4 * r2
        a1 = 2 * x * y
        a2 = r2 + 2 * x * x
        a3 = r2 + 2 * y * y
        cdist = 1 + k1 * r2 + k2 * r4 + k3 * r6
        xd = x * cdist + p1 * a1 + p2 * a2
        yd = y * cdist + p1 * a3 + p2 * a1
        return np.column_stack([xd * self.fu + self.cu, yd * self.fv + self.cv])

    def project(self, points_S: np.ndarray) -> np.ndarray:
        """Pixel positions of camera-frame points (N x 3, z > 0)."""
        p = np.asarray(points_S, dtype=np.float64).reshape(-1, 3)
        return self.denormalize(p[:, :2] / p[:, 2:3])

    def pixel_rays(self, supersample: int = 1) -> np.ndarray:
        """Undistorted normalised coordinates ``(x/z, y/z)`` of the ray through every (sub-)pixel.

        Parameters
        ----------
        supersample : int
            ``s`` samples per pixel along each axis, at offsets ``(k + 0.5) / s - 0.5`` (k = 0..s-1)
            from the pixel centre; ``s = 1`` is the pixel centre itself.

        Returns
        -------
        ndarray, shape (height * s, width * s, 2), float64
            Computed with :meth:`normalize`, so ``denormalize`` maps them back to the sample positions.
        """
        s = int(supersample)
        if s < 1:
            raise ValueError("supersample must be >= 1")
        offsets = (np.arange(s) + 0.5) / s - 0.5
        us = (np.arange(self.width)[:, None] + offsets[None, :]).ravel()
        vs = (np.arange(self.height)[:, None] + offsets[None, :]).ravel()
        uu, vv = np.meshgrid(us, vs)
        return self.normalize(np.column_stack([uu.ravel(), vv.ravel()])).reshape(len(vs), len(us), 2)

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict:
        return {
            "sensor_type": "camera",
            "rate_hz": float(self.rate_hz),
            "resolution": [int(self.width), int(self.height)],
            "camera_model": "pinhole",
            "intrinsics": [float(self.fu), float(self.fv), float(self.cu), float(self.cv)],
            "distortion_model": self.distortion_model,
            "distortion_coefficients": [float(v) for v in self.distortion],
            "T_BS": {"cols": 4, "rows": 4, "data": [float(v) for v in self.T_BS.ravel()]},
        }

    def write_yaml(self, path: str | Path) -> None:
        """Write ``path`` (atomically); the keys of a file already there that the model does not hold
        (``height_sigma``, ``camera_noise``, ``bit_depth``, ...) are kept."""
        data = self.to_dict()
        if Path(path).is_file():
            try:
                old = load_yaml(path)
            except InputError:  # a file that is no YAML mapping is replaced whole
                old = {}
            data.update({key: value for key, value in old.items() if key not in data})
        write_yaml_atomic(path, data)


def default_T_BS() -> np.ndarray:
    """The pose of a camera that ``cam0/sensor.yaml`` does not mount: 0.25 m ahead of the axle, 0.1 m above the
    floor, looking straight down with image-up forward (:data:`R_BS_DOWN_FORWARD`)."""
    T = np.eye(4)
    T[:3, :3] = R_BS_DOWN_FORWARD
    T[:3, 3] = [0.25, 0.0, 0.1]
    return T
