"""Removing the image motion that roll and pitch cause, using the gyro (as flow sensors do).

A camera that tilts between two frames sees the floor shift by about ``f ω Δt`` pixels without
moving: the rotation is not a translation of the robot. PX4 subtracts the gyro's roll and pitch rates
times the focal length from its flow sensors' output; here the same is done exactly on the rectified
similarity, before :class:`fusion_vo.geometry.ground.GroundGeometry` turns it into body motion.

Model
-----
Between the two frames the body rotates by ``ΔR_B`` (roll and pitch only, from the gyro, integrated
over the frame interval). The virtual nadir camera V of the rectification is fixed to the body, so a
floor direction seen along ``d`` in V at the first frame is seen along ``R_VB ΔR_B^T R_BV d`` at the
second: a pure rotation moves rectified pixels by the homography

.. math::  H = K_V R_{VB} \\Delta R_B^T R_{BV} K_V^{-1}

The measured similarity is ``S_meas ≈ H ∘ S``; the rotation-free motion is ``S = H^{-1} ∘ S_meas``,
with ``H^{-1}`` replaced by the similarity that fits it best (least squares over a grid covering the
image). Yaw is the robot's own turning and is left in: a turn in place, whatever the lever arm,
has zero roll and pitch and is returned unchanged.

Gyro biases in roll and pitch would otherwise be read as a constant drift; a platform cannot keep
rotating in roll or pitch, so the mean roll and pitch rates of the whole recording are taken as the
biases and removed.

Where the correction is fitted
----------------------------------
A tilt moves the rays far off the axis by more than ``f ω Δt`` (``f (1 + x²/f²) ω Δt`` at ``x``), so the
best similarity of ``H^{-1}`` depends on which points it is fitted to. The frontends fit their
similarity robustly, which leaves out the far field where a tilt is least like a similarity; the
correction is therefore fitted on the points within ``max_off_axis`` (the tangent of the angle off the
virtual camera's axis, 1: 45 degrees). For an ordinary lens that is the whole image; for a fisheye it
leaves out the rim, where the rectified image is stretched most and a fit over the whole image
over-corrects the tilt (``docs/decisions/0032-derotation-within-45-degrees.md``).

What is left is not known to better than a fraction of the rotation's image motion (where the frontend's
points were, rolling shutter, the lens model), so :meth:`GyroDerotation.derotate` adds
``(uncertainty · flow)²`` to the variance of the similarity's translation, ``flow`` being the rotation's
image motion at the principal point. ``uncertainty = 0.2`` brings the mean NIS of the visual increments
against the truth on ``real_fisheye_checker`` from 35 (the frontend's covariance alone) to about 7.

Where the gyro has no sample for longer than ``max_gap`` (a pause in the recording), nothing is known
of the rotation; the integral does not grow there (a rocking platform is level on average), rather than
holding the rate of the last sample over the whole gap.
"""

from __future__ import annotations

import math

import numpy as np

from frontends.similarity import fit_least_squares
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.measurements import ImuData

_EYE = np.eye(3)


class GyroDerotation:
    """Corrects rectified similarities for the roll and pitch measured by a gyro.

    Parameters
    ----------
    imu : ImuData
        Gyro samples [rad/s] in the IMU frame, with the IMU's ``T_BS``.
    geometry : GroundGeometry
        The ground geometry of the camera (its rectifier and ``T_BS``).
    remove_bias : bool
        Subtract the recording's mean roll and pitch rates (see the module description).
    max_gap : float
        Two gyro samples further apart than this [s] add no rotation (default 0.25).
    max_off_axis : float
        The correction is fitted on the image points whose rays are at most this far off the virtual
        camera's axis (tangent of the angle; default 1, 45 degrees).
    uncertainty : float
        Standard deviation of what the correction leaves, as a fraction of the rotation's image motion
        at the principal point (default 0.2; module description).
    """

    def __init__(self, imu: ImuData, geometry: GroundGeometry, remove_bias: bool = True, max_gap: float = 0.25,
                 max_off_axis: float = 1.0, uncertainty: float = 0.2):
        w_B = np.asarray(imu.gyro, dtype=np.float64) @ np.asarray(imu.T_BS, dtype=np.float64)[:3, :3].T
        w_B = w_B.copy()
        w_B[:, 2] = 0.0  # yaw stays: it is the robot's own motion
        if remove_bias and len(w_B):
            w_B[:, :2] -= w_B[:, :2].mean(axis=0)
        self.t = np.asarray(imu.t, dtype=np.float64)
        self._w = w_B
        # running integral of the body rates (small angles between consecutive frames)
        dt = np.diff(self.t)
        mid = 0.5 * (w_B[1:] + w_B[:-1]) * np.where(dt > max_gap, 0.0, dt)[:, None]
        self._cum = np.vstack([np.zeros(3), np.cumsum(mid, axis=0)])
        rect = geometry.rectifier
        self.f = rect.f
        self.c = rect.c
        self.R_BV = rect.R_BV
        cam = geometry.camera
        w, h = cam.width, cam.height
        gx, gy = np.meshgrid(np.linspace(0, w - 1, 16), np.linspace(0, h - 1, 10))
        grid = rect.to_rectified(np.column_stack([gx.ravel(), gy.ravel()]))
        near = np.linalg.norm((grid - self.c) / self.f, axis=1) <= max_off_axis
        if np.count_nonzero(near) < 12:  # a lens wider than the whole grid's spacing: a grid on the disc
            u, v = np.meshgrid(np.linspace(-1.0, 1.0, 9), np.linspace(-1.0, 1.0, 9))
            disc = np.column_stack([u.ravel(), v.ravel()])
            grid = disc[np.linalg.norm(disc, axis=1) <= 1.0] * (max_off_axis * self.f) + self.c
        else:
            grid = grid[near]
        self._grid = grid
        self._lo, self._hi = self._grid.min(axis=0), self._grid.max(axis=0)
        self.uncertainty = float(uncertainty)
        self._angles: dict[float, np.ndarray] = {}

    def _angle(self, t: float) -> np.ndarray:
        """The integrated body rates at ``t`` (linear interpolation); the last two times are remembered,
        since each frame's time is asked for again as the start of the next interval."""
        cached = self._angles.get(t)
        if cached is None:
            cached = np.array([np.interp(t, self.t, self._cum[:, k]) for k in range(3)])
            if len(self._angles) >= 2:
                self._angles.pop(next(iter(self._angles)))
            self._angles[t] = cached
        return cached

    def rotation(self, t0: float, t1: float) -> np.ndarray:
        """The body's roll-and-pitch rotation ``ΔR_B`` from ``t0`` to ``t1`` (3x3)."""
        from scipy.spatial.transform import Rotation  # loaded with the first frame (a recording with an IMU)

        if len(self.t) < 2 or t0 < self.t[0] or t1 > self.t[-1]:
            return np.eye(3)
        start = self._angle(t0)  # first: it is usually the previous interval's end, still remembered
        return Rotation.from_rotvec(self._angle(t1) - start).as_matrix()

    def correction(self, t0: float, t1: float, matrix: np.ndarray | None = None) -> np.ndarray:
        """The 3x3 similarity ``H^{-1}`` (best fit) that removes the rotation's image motion.

        ``H^{-1}`` is a homography; its best similarity depends on where the points are, so it is
        fitted on the rectified grid moved by the measured similarity ``matrix`` (the points of the
        second frame), keeping those still in view.
        """
        dR = self.rotation(t0, t1)
        if np.all(np.abs(dR - _EYE) <= 1e-12 + 1e-5 * _EYE):  # np.allclose(dR, I, atol=1e-12) in a fifth of the time
            return np.eye(3)
        pts = self._grid
        if matrix is not None:
            m = np.asarray(matrix, dtype=np.float64)
            moved = pts @ m[:, :2].T + m[:, 2]
            inside = np.all((moved >= self._lo) & (moved <= self._hi), axis=1)
            if np.count_nonzero(inside) >= 6:
                pts = moved[inside]
        # H^{-1} = K R_VB dR R_BV K^{-1}: a pixel seen at the second frame back to where it was
        M = self.R_BV.T @ dR @ self.R_BV
        d = np.column_stack([(pts - self.c) / self.f, np.ones(len(pts))]) @ M.T
        back = d[:, :2] / d[:, 2:3] * self.f + self.c
        a, b = fit_least_squares(pts[:, 0] + 1j * pts[:, 1], back[:, 0] + 1j * back[:, 1])
        return np.array([[a.real, -a.imag, b.real], [a.imag, a.real, b.imag], [0.0, 0.0, 1.0]])

    def apply(self, matrix: np.ndarray, t0: float, t1: float) -> np.ndarray:
        """The rotation-free similarity ``H^{-1} ∘ S`` of a measured 2x3 similarity over ``[t0, t1]``."""
        S = np.vstack([np.asarray(matrix, dtype=np.float64), [0.0, 0.0, 1.0]])
        return (self.correction(t0, t1, matrix) @ S)[:2]

    def derotate(self, matrix: np.ndarray, covariance: np.ndarray, t0: float,
                 t1: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`apply`, and the covariance of ``(tx, ty, angle, log s)`` with the correction's
        uncertainty added to the translation (module description)."""
        S = np.vstack([np.asarray(matrix, dtype=np.float64), [0.0, 0.0, 1.0]])
        C = self.correction(t0, t1, matrix)
        cov = np.array(covariance, dtype=np.float64)
        if self.uncertainty > 0:
            flow = C[:2, :2] @ self.c + C[:2, 2] - self.c
            var = (self.uncertainty * float(math.hypot(*flow))) ** 2
            cov[0, 0] += var
            cov[1, 1] += var
        return (C @ S)[:2], cov

    def flow_px(self, t0: float, t1: float) -> float:
        """Size of the rotation's image motion at the principal point [rectified px] (diagnostics)."""
        C = self.correction(t0, t1)
        p = C[:2, :2] @ self.c + C[:2, 2] - self.c
        return float(math.hypot(*p))
