"""Ground geometry: from a pixel similarity between two frames to the body's planar motion.

Frames (``datasets/README.md``): body B on the floor under the drive axle (x forward, y left, z up),
camera S (OpenCV), ``X_B = R_BS X_S + t_BS``; ``h = t_BS[2]`` is the camera's height above the floor.

Rectification
-------------
A tilted camera sees the floor through a homography, not a similarity. Every measured point is therefore
mapped to a *virtual nadir camera* V with the same centre, looking straight down (``z_V = -z_B``), its x
axis the horizontal direction of the real camera's x axis, focal length ``f = sqrt(fu fv)`` and the
real principal point ``c``::

    u' = f * r_x / r_z + c_x,    r = R_VS [x_n, y_n, 1]^T,

where ``(x_n, y_n)`` are the undistorted normalised coordinates of the raw pixel. In V the floor moves by
an exact similarity when the robot moves on a plane, and a rectified pixel ``u'`` is the floor point::

    q = A(u') = t_xy + (h / f) R2 (u' - c),     R2 = R_BV[:2, :2]   (a reflection: det R2 = -1)

Body motion
-----------
A floor point fixed in the world has body coordinates ``q_k`` and ``q_{k+1} = T^{-1} q_k``, with
``T = (dx, dy, dyaw)`` the pose of B(k+1) in B(k). The frontend's similarity ``S`` maps rectified points
of frame k to frame k+1, so ``T^{-1} = A S A^{-1}``, i.e. the robot's motion is the *conjugate* of the
image motion by the mounting (``T_B = T_BS T_S T_BS^{-1}``), never the image motion read off directly.
A robot turning in place with the camera ahead of the axle therefore gives a pure rotation.

The similarity's scale ``s`` is a height change (``h_{k+1} / h_k = 1 / s``), not a motion. The rigid
motion is taken about the floor point under the camera centre ``q_c = t_xy``: with ``φ = det(R2) θ``,
``g = A(S c)``::

    dyaw = -φ,    (dx, dy) = q_c - R(-φ) g

and the covariance of ``(dx, dy, dyaw)`` is ``J Σ J^T`` with ``Σ`` the frontend's covariance of
``(tx, ty, θ, log s)`` and ``J`` the analytic Jacobian of these expressions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from frontends.base import FrameMotion
from fusion_vo.geometry import se2
from fusion_vo.geometry.camera import CameraModel
from fusion_vo.measurements import MAX_CAMERA_HEIGHT_M, VisualIncrement


def _rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def nadir_rotation(R_BS: np.ndarray) -> np.ndarray:
    """``R_BV`` of the virtual nadir camera for a camera with orientation ``R_BS``."""
    x_s = R_BS[:, 0]
    x_h = np.array([x_s[0], x_s[1], 0.0])
    n = np.linalg.norm(x_h)
    if n < 1e-6:
        raise ValueError("the camera's x axis is vertical: it does not look at the floor")
    x_v = x_h / n
    z_v = np.array([0.0, 0.0, -1.0])
    y_v = np.cross(z_v, x_v)
    return np.column_stack([x_v, y_v, z_v])


class GroundRectifier:
    """Maps raw pixels to the virtual nadir camera's pixels and back (a :class:`frontends.PointMap`)."""

    def __init__(self, camera: CameraModel):
        self.camera = camera
        R_BS = camera.R_BS
        if R_BS[2, 2] > -0.5:
            raise ValueError(
                f"the camera looks {math.degrees(math.acos(max(-1.0, min(1.0, -R_BS[2, 2])))):.0f} deg away from "
                "straight down; a ground camera must see the floor (T_BS z axis pointing down)"
            )
        self.R_BV = nadir_rotation(R_BS)
        self.R_VS = self.R_BV.T @ R_BS
        self.f = math.sqrt(camera.fu * camera.fv)
        self.c = np.array([camera.cu, camera.cv])
        self._identity_rotation = np.allclose(self.R_VS, np.eye(3), atol=1e-12)
        self._check_usable()

    #: the smallest rectified width and height [px] of the raw frame that leaves an image to track in (as the
    #: dense frontend's rectifier needs)
    MIN_USABLE_PX = 16

    def _check_usable(self) -> None:
        """A ``ValueError`` when the intrinsics and distortion leave no usable image: a focal length or
        principal point that overflows, or a raw frame whose border maps to no rectified rectangle of at
        least :attr:`MIN_USABLE_PX` pixels each way (a principal point far outside the image, a distortion
        that folds the frame)."""
        cam = self.camera
        if not (math.isfinite(self.f) and np.all(np.isfinite(self.c))):
            raise ValueError(f"the intrinsics {[cam.fu, cam.fv, cam.cu, cam.cv]} overflow: no usable image")
        if self.trivial:
            return
        n, w, h = 64, cam.width, cam.height
        xs, ys = np.linspace(0, w - 1, n), np.linspace(0, h - 1, n)
        with np.errstate(all="ignore"):
            try:
                left = self.to_rectified(np.column_stack([np.zeros(n), ys]))
                right = self.to_rectified(np.column_stack([np.full(n, w - 1.0), ys]))
                top = self.to_rectified(np.column_stack([xs, np.zeros(n)]))
                bottom = self.to_rectified(np.column_stack([xs, np.full(n, h - 1.0)]))
            except (cv2.error, OverflowError, ValueError):
                left = right = top = bottom = np.full((n, 2), np.nan)
            width = float(np.min(right[:, 0]) - np.max(left[:, 0]))
            height = float(np.min(bottom[:, 1]) - np.max(top[:, 1]))
        if not (width > self.MIN_USABLE_PX and height > self.MIN_USABLE_PX):
            raise ValueError(
                f"the intrinsics and distortion leave no usable image: the {w}x{h} frame rectifies to no area of "
                f"{self.MIN_USABLE_PX}x{self.MIN_USABLE_PX} px (check intrinsics and distortion_coefficients)")

    @property
    def trivial(self) -> bool:
        """True when rectified pixels equal raw pixels (no distortion, no tilt, fu == fv)."""
        return (not self.camera.has_distortion) and self._identity_rotation and self.camera.fu == self.camera.fv

    def to_rectified(self, pts: np.ndarray) -> np.ndarray:
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        if self.trivial:
            return pts.copy()
        n = self.camera.normalize(pts)
        if self._identity_rotation:
            return n * self.f + self.c
        r = np.column_stack([n, np.ones(len(n))]) @ self.R_VS.T
        return r[:, :2] / r[:, 2:3] * self.f + self.c

    def to_image(self, pts: np.ndarray) -> np.ndarray:
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        if self.trivial:
            return pts.copy()
        v = (pts - self.c) / self.f
        if self._identity_rotation:
            return self.camera.denormalize(v)
        r = np.column_stack([v, np.ones(len(v))]) @ self.R_VS  # R_SV = R_VS^T
        return self.camera.denormalize(r[:, :2] / r[:, 2:3])


def floor_covariance(P: np.ndarray, min_sigma_xy: float, min_sigma_yaw: float) -> np.ndarray:
    """A body increment's covariance with its diagonal raised to the floors (a copy; off-diagonal terms kept).

    ``P[0, 0] = max(P[0, 0], σ_xy²)``, ``P[1, 1] = max(P[1, 1], σ_xy²)``, ``P[2, 2] = max(P[2, 2], σ_yaw²)``: the
    floors stand for what the frontend's residuals cannot show (floor relief, rolling, rendering), so no
    increment claims less (``docs/decisions/0037-camera-heading-floor-stays.md``).
    """
    out = np.array(P, dtype=np.float64, copy=True)
    out[0, 0] = max(out[0, 0], min_sigma_xy**2)
    out[1, 1] = max(out[1, 1], min_sigma_xy**2)
    out[2, 2] = max(out[2, 2], min_sigma_yaw**2)
    return out


@dataclass
class GroundGeometry:
    """Converts frontend similarities (in rectified pixels) into body-frame SE(2) increments.

    Parameters
    ----------
    camera : CameraModel
        Intrinsics, distortion and ``T_BS`` (lever arm, height, tilt).
    height : float, optional
        Camera height above the floor [m], in (0, :data:`~fusion_vo.measurements.MAX_CAMERA_HEIGHT_M`];
        defaults to ``T_BS[2, 3]``.
    min_sigma_xy : float
        Floor on the standard deviation of ``dx, dy`` [m] (unmodelled effects: floor relief, rolling).
    min_sigma_yaw : float
        Floor on the standard deviation of ``dyaw`` [rad] (:func:`floor_covariance`).
    """

    camera: CameraModel
    height: float | None = None
    min_sigma_xy: float = 2e-5
    min_sigma_yaw: float = 1.4e-5

    def __post_init__(self) -> None:
        self.rectifier = GroundRectifier(self.camera)
        if self.height is None:
            self.height = float(self.camera.t_BS[2])
        if not 0 < self.height <= MAX_CAMERA_HEIGHT_M:
            raise ValueError(f"camera height must be in (0, {MAX_CAMERA_HEIGHT_M:g}] m, not {self.height:g} "
                             "(T_BS z translation, or set 'height')")
        R2 = self.rectifier.R_BV[:2, :2]
        self._R2 = R2
        self._sigma = float(np.sign(np.linalg.det(R2)))
        self._qc = self.camera.t_BS[:2].copy()

    @property
    def metres_per_pixel(self) -> float:
        return self.height / self.rectifier.f

    def floor_point(self, rectified: np.ndarray, height: float | None = None) -> np.ndarray:
        """Body-frame floor coordinates of rectified pixels (N x 2)."""
        k = (height or self.height) / self.rectifier.f
        return self._qc + k * (np.asarray(rectified, dtype=np.float64).reshape(-1, 2) - self.rectifier.c) @ self._R2.T

    def body_increment(self, params: np.ndarray, cov: np.ndarray | None = None, height: float | None = None,
                       height_sigma: float = 0.0):
        """``(dx, dy, dyaw)`` and its covariance from similarity parameters ``(tx, ty, θ, log s)``.

        ``height_sigma`` [m] is the uncertainty of ``height`` (a range finder's reading): the translation
        scales with the height, so it adds ``σ_h² j jᵀ`` with ``j = ∂(dx, dy)/∂h`` to the covariance, an
        error proportional to the distance moved that the frontend's residuals cannot show.
        """
        tx, ty, th, lam = (float(v) for v in params)
        h = height or self.height
        k = h / self.rectifier.f
        c = self.rectifier.c
        es = math.exp(lam)
        Rt = _rot(th)
        Sc = es * (Rt @ c) + (tx, ty)
        g = self._qc + k * (self._R2 @ (Sc - c))
        phi = self._sigma * th
        Rm = _rot(-phi)
        d = self._qc - Rm @ g
        delta = np.array([d[0], d[1], float(se2.wrap_angle(-phi))])
        if cov is None:
            return delta, None
        J = np.zeros((3, 4))
        dg_dt = k * self._R2
        dg_dth = k * (self._R2 @ (es * (_rot(th + math.pi / 2) @ c)))
        dg_dlam = k * (self._R2 @ (es * (Rt @ c)))
        J[:2, :2] = -Rm @ dg_dt
        J[:2, 2] = -Rm @ dg_dth + self._sigma * (_rot(-phi + math.pi / 2) @ g)
        J[:2, 3] = -Rm @ dg_dlam
        J[2, 2] = -self._sigma
        P = J @ np.asarray(cov, dtype=np.float64) @ J.T
        if height_sigma > 0:
            j_h = -Rm @ (g - self._qc) / h  # d = q_c - R(-φ) g with g - q_c proportional to h
            P[:2, :2] += height_sigma**2 * np.outer(j_h, j_h)
        return delta, floor_covariance(0.5 * (P + P.T), self.min_sigma_xy, self.min_sigma_yaw)

    def similarity_from_body(self, delta, height_ratio: float = 1.0) -> np.ndarray:
        """The rectified-pixel similarity that a body increment produces (inverse of :meth:`body_increment`).

        ``height_ratio`` is ``h_{k+1} / h_k``; the image scales by its inverse about the nadir point.
        """
        dx, dy, dyaw = (float(v) for v in delta)
        phi = -dyaw
        th = self._sigma * phi
        k = self.height / self.rectifier.f
        c = self.rectifier.c
        # g = R(phi) (q_c - d)  is the floor point under the camera at k, seen from k+1
        g = _rot(phi) @ (self._qc - np.array([dx, dy]))
        Sc = c + self._R2.T @ (g - self._qc) / k
        s = 1.0 / height_ratio
        lin = s * _rot(th)
        t = Sc - lin @ c
        return np.column_stack([lin, t])

    def increment(self, motion: FrameMotion, height: float | None = None, height_sigma: float = 0.0) -> VisualIncrement:
        """A :class:`VisualIncrement` from a frontend's :class:`FrameMotion` (``height_sigma``: see
        :meth:`body_increment`)."""
        t0 = motion.prev_timestamp if motion.prev_timestamp is not None else motion.timestamp
        if not motion.ok:
            return VisualIncrement(t0, motion.timestamp, np.zeros(3), np.diag([np.inf] * 3), 1.0,
                                   motion.status.value, motion.n_inliers)
        p = motion.params
        delta, P = self.body_increment(p, motion.covariance, height, height_sigma)
        return VisualIncrement(t0, motion.timestamp, delta, P, float(math.exp(-p[3])), "ok", motion.n_inliers)


def twist(delta, dt: float) -> np.ndarray:
    """Body twist ``(vx, vy, yaw rate)`` that produces ``delta`` in ``dt`` seconds (SE(2) logarithm)."""
    if dt <= 0:
        raise ValueError("dt must be positive")
    return se2.log(delta) / dt
