"""The simulated camera: intrinsics, lens distortion and its mount on the robot.

A point ``X_S = (x, y, z)`` in the camera frame S (OpenCV: x right, y down, z along the optical axis)
projects to the normalised image point ``(x/z, y/z)``, which the lens distorts and the intrinsics map
to pixels::

    u = fu * x_d + cu,    v = fv * y_d + cv

``radial-tangential`` (OpenCV ``k1, k2, p1, p2``), with ``r^2 = x^2 + y^2``::

    x_d = x (1 + k1 r^2 + k2 r^4) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (1 + k1 r^2 + k2 r^4) + p1 (r^2 + 2 y^2) + 2 p2 x y

``equidistant`` (OpenCV fisheye ``k1..k4``), with ``theta = atan(r)``::

    theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8),   (x_d, y_d) = theta_d / r (x, y)

Pixel centres are at integer coordinates (OpenCV's convention), so ``cu = 319.5`` is the centre of a
640 pixel wide image.

The mount ``T_BS`` maps camera coordinates to body coordinates. The untilted mount looks straight
down with image-up pointing forward (body x)::

    R_BS0 = [[ 0, -1,  0],
             [-1,  0,  0],
             [ 0,  0, -1]]

and a tilt rotates the camera about its own x and y axes: ``R_BS = R_BS0 · R_x(tilt_x) · R_y(tilt_y)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

#: camera-to-body rotation of a camera looking straight down with image-up = body forward
R_BS_DOWN = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])

DISTORTION_MODELS = ("radial-tangential", "equidistant")


@dataclass(frozen=True)
class CameraModel:
    """A pinhole camera with radial-tangential or equidistant lens distortion.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    fu, fv, cu, cv : float
        Focal lengths and principal point in pixels.
    distortion_model : str
        ``"radial-tangential"`` (coefficients ``k1, k2, p1, p2``) or ``"equidistant"``
        (``k1, k2, k3, k4``).
    distortion_coefficients : tuple of float
        The four coefficients of the model.
    """

    width: int = 640
    height: int = 360
    fu: float = 420.0
    fv: float = 420.0
    cu: float = 319.5
    cv: float = 179.5
    distortion_model: str = "radial-tangential"
    distortion_coefficients: tuple[float, ...] = field(default=(-0.03, 0.01, 0.0005, -0.0003))

    def __post_init__(self) -> None:
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(f"distortion_model must be one of {DISTORTION_MODELS}, not {self.distortion_model!r}")
        if len(self.distortion_coefficients) != 4:
            raise ValueError("distortion_coefficients must have 4 values")

    @property
    def K(self) -> np.ndarray:
        """The 3x3 intrinsic matrix."""
        return np.array([[self.fu, 0.0, self.cu], [0.0, self.fv, self.cv], [0.0, 0.0, 1.0]])

    @property
    def D(self) -> np.ndarray:
        """The distortion coefficients as a float64 array."""
        return np.asarray(self.distortion_coefficients, dtype=np.float64)

    def undistort(self, pixels: np.ndarray) -> np.ndarray:
        """Map raw (distorted) pixel coordinates ``(N, 2)`` to normalised image coordinates ``(N, 2)``."""
        pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        if self.distortion_model == "equidistant":
            out = cv2.fisheye.undistortPoints(pts, self.K, self.D)
        else:
            out = cv2.undistortPoints(pts, self.K, self.D)
        return out.reshape(-1, 2)

    def distort(self, normalised: np.ndarray) -> np.ndarray:
        """Map normalised image coordinates ``(N, 2)`` to raw pixel coordinates ``(N, 2)``."""
        xy = np.asarray(normalised, dtype=np.float64).reshape(-1, 2)
        return self.project(np.column_stack([xy, np.ones(len(xy))]))

    def project(self, points_S: np.ndarray) -> np.ndarray:
        """Project camera-frame points ``(N, 3)`` (z > 0) to raw pixel coordinates ``(N, 2)``."""
        pts = np.asarray(points_S, dtype=np.float64).reshape(-1, 1, 3)
        zero = np.zeros(3)
        if self.distortion_model == "equidistant":
            out, _ = cv2.fisheye.projectPoints(pts, zero, zero, self.K, self.D)
        else:
            out, _ = cv2.projectPoints(pts, zero, zero, self.K, self.D)
        return out.reshape(-1, 2)

    def pixel_rays(self, supersample: int = 1) -> np.ndarray:
        """Normalised coordinates ``(x/z, y/z)`` of the ray through every (sub-)pixel.

        Parameters
        ----------
        supersample : int
            ``s`` samples per pixel along each axis, at offsets ``(k + 0.5) / s - 0.5`` from the pixel
            centre.

        Returns
        -------
        ndarray, shape (height * s, width * s, 2), float64
        """
        s = int(supersample)
        offsets = (np.arange(s) + 0.5) / s - 0.5
        us = (np.arange(self.width)[:, None] + offsets[None, :]).ravel()
        vs = (np.arange(self.height)[:, None] + offsets[None, :]).ravel()
        uu, vv = np.meshgrid(us, vs)
        pix = np.column_stack([uu.ravel(), vv.ravel()])
        return self.undistort(pix).reshape(len(vs), len(us), 2)

    def to_yaml_dict(self, T_BS: np.ndarray, rate_hz: float) -> dict:
        """The ``cam0/sensor.yaml`` content of the recording layout for this camera."""
        return {
            "sensor_type": "camera",
            "rate_hz": float(rate_hz),
            "resolution": [int(self.width), int(self.height)],
            "camera_model": "pinhole",
            "intrinsics": [float(self.fu), float(self.fv), float(self.cu), float(self.cv)],
            "distortion_model": self.distortion_model,
            "distortion_coefficients": [float(c) for c in self.distortion_coefficients],
            "T_BS": {"cols": 4, "rows": 4, "data": [float(round(x, 12)) for x in np.asarray(T_BS).ravel()]},
        }


def rot_x(angle: float) -> np.ndarray:
    """Rotation matrix about x by ``angle`` radians."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> np.ndarray:
    """Rotation matrix about y by ``angle`` radians."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> np.ndarray:
    """Rotation matrix about z by ``angle`` radians."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def camera_mount(lever_arm: float, height: float, tilt_x_deg: float = 0.0, tilt_y_deg: float = 0.0,
                 lateral_offset: float = 0.0) -> np.ndarray:
    """``T_BS`` of a downward camera ``lever_arm`` ahead of the axle and ``height`` above the floor.

    Parameters
    ----------
    lever_arm : float
        Forward offset (body x) of the camera centre from the axle centre [m].
    height : float
        Height of the camera centre above the floor [m].
    tilt_x_deg, tilt_y_deg : float
        Rotation of the camera about its own x and y axes [degrees].
    lateral_offset : float
        Offset along body y (left) [m].

    Returns
    -------
    ndarray, shape (4, 4)
    """
    T = np.eye(4)
    T[:3, :3] = R_BS_DOWN @ rot_x(math.radians(tilt_x_deg)) @ rot_y(math.radians(tilt_y_deg))
    T[:3, 3] = [lever_arm, lateral_offset, height]
    return T


def body_pose(x: float, y: float, yaw: float) -> np.ndarray:
    """``T_WB`` (4x4) of a planar body pose."""
    T = np.eye(4)
    T[:3, :3] = rot_z(yaw)
    T[:3, 3] = [x, y, 0.0]
    return T
