"""The camera's pose over the floor from one image of a chessboard lying on it.

The board frame F lies on the floor (z_F up) with its first inner corner at ``board_origin`` in the body
frame and its x axis turned by ``board_yaw`` from body x::

    T_BF = [R_z(yaw), (x0, y0, 0)]

The perspective-n-point solution gives the board's pose in the camera, ``X_S = R_SF X_F + t_SF``, from the
undistorted normalised corners (so any lens model of :class:`CameraModel` works), hence::

    T_BS = T_BF · T_SF^-1

whose translation is the lever arm (x, y) and the height (z), and whose rotation gives the tilt. The
tilt is reported two ways: the angle of the optical axis from straight down, ``acos(-R_BS[2, 2])``, and
the mount angles of ``R_BS = R_BS0 · R_x(tilt_x) · R_y(tilt_y) · R_z(spin)`` with ``R_BS0`` the level
camera whose image-up points forward (:data:`fusion_vo.geometry.camera.R_BS_DOWN_FORWARD`).

Uncertainty
-----------
With ``J`` the Jacobian of the normalised reprojection residuals with respect to the pose ``p = (rvec,
tvec)`` and ``σ²`` the residual variance (``2N - 6`` degrees of freedom)::

    Σ_p = σ² (J^T J)^-1,     Σ_q = G Σ_p G^T

where ``G = ∂q/∂p`` (by central differences) for every reported quantity ``q`` (height, tilts, lever arm).
A chessboard admits several corner orderings (a half turn, quarter turns if square, and mirrored
numberings, which put the camera below the floor and are dropped); the one whose camera orientation is
closest to the prior ``R_BS`` (the existing mount) is chosen.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np

from fusion_vo.calibration.chessboard import Board, board_orderings
from fusion_vo.errors import InputError
from fusion_vo.geometry.camera import R_BS_DOWN_FORWARD, CameraModel

logger = logging.getLogger(__name__)

#: names of the quantities derived from the pose, in the order of :attr:`FloorResult.values`
QUANTITIES = ("height", "lever_x", "lever_y", "tilt_deg", "tilt_x_deg", "tilt_y_deg", "spin_deg")


@dataclass
class FloorResult:
    """The camera mount measured from a floor chessboard.

    Attributes
    ----------
    T_BS : ndarray, shape (4, 4)
        Camera pose in the body frame.
    values, std : dict
        Each quantity of :data:`QUANTITIES` and its standard deviation: ``height`` [m], ``lever_x``,
        ``lever_y`` [m], ``tilt_deg`` (optical axis from vertical), ``tilt_x_deg``, ``tilt_y_deg`` and
        ``spin_deg`` (mount angles, see the module docstring) [deg].
    rms : float
        RMS reprojection error [px].
    n_corners : int
    """

    T_BS: np.ndarray
    values: dict[str, float]
    std: dict[str, float]
    rms: float
    n_corners: int

    @property
    def height(self) -> float:
        return self.values["height"]

    @property
    def tilt_deg(self) -> float:
        return self.values["tilt_deg"]

    def summary(self) -> str:
        v, s = self.values, self.std
        return "\n".join([
            f"Camera over the floor ({self.n_corners} corners, RMS reprojection error {self.rms:.4f} px):",
            f"  Height:       {v['height']:.5f} +- {s['height']:.5f} m",
            f"  Lever arm:    x = {v['lever_x']:.5f} +- {s['lever_x']:.5f} m,  "
            f"y = {v['lever_y']:.5f} +- {s['lever_y']:.5f} m",
            f"  Tilt:         {v['tilt_deg']:.4f} +- {s['tilt_deg']:.4f} deg from vertical "
            f"(about camera x {v['tilt_x_deg']:.4f} +- {s['tilt_x_deg']:.4f}, "
            f"about camera y {v['tilt_y_deg']:.4f} +- {s['tilt_y_deg']:.4f})",
            f"  Spin:         {v['spin_deg']:.4f} +- {s['spin_deg']:.4f} deg (image-up from body x)",
        ])


def board_pose_in_body(board_origin: tuple[float, float] = (0.0, 0.0), board_yaw_deg: float = 0.0) -> np.ndarray:
    """``T_BF`` of a board lying on the floor at ``board_origin`` [m], turned by ``board_yaw_deg``."""
    a = math.radians(board_yaw_deg)
    T = np.eye(4)
    T[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    T[:2, 3] = board_origin
    return T


def mount_quantities(T_BS: np.ndarray) -> np.ndarray:
    """The values of :data:`QUANTITIES` for a mount ``T_BS``."""
    R = T_BS[:3, :3]
    M = R_BS_DOWN_FORWARD.T @ R  # = R_x(a) R_y(b) R_z(c)
    b = math.asin(max(-1.0, min(1.0, M[0, 2])))
    a = math.atan2(-M[1, 2], M[2, 2])
    c = math.atan2(-M[0, 1], M[0, 0])
    tilt = math.acos(max(-1.0, min(1.0, -R[2, 2])))
    return np.array([T_BS[2, 3], T_BS[0, 3], T_BS[1, 3], math.degrees(tilt), math.degrees(a), math.degrees(b),
                     math.degrees(c)])


def _pose_to_T_BS(pose: np.ndarray, T_BF: np.ndarray) -> np.ndarray:
    T_SF = np.eye(4)
    T_SF[:3, :3] = cv2.Rodrigues(pose[:3])[0]
    T_SF[:3, 3] = pose[3:]
    return T_BF @ np.linalg.inv(T_SF)


def _rotation_angle(R: np.ndarray) -> float:
    return math.acos(max(-1.0, min(1.0, (np.trace(R) - 1) / 2)))


def floor_pose(corners: np.ndarray, camera: CameraModel, board: Board, board_origin: tuple[float, float] = (0.0, 0.0),
               board_yaw_deg: float = 0.0, prior_R_BS: np.ndarray | None = None) -> FloorResult:
    """The camera mount from the detected corners of a board lying on the floor.

    Parameters
    ----------
    corners : ndarray, shape (cols*rows, 2)
        Detected inner corners [raw px], in :meth:`Board.object_points` order (up to the board's symmetry).
    camera : CameraModel
        Intrinsics and distortion (its ``T_BS`` is the prior orientation unless ``prior_R_BS`` is given).
    board : Board
    board_origin : (x, y) of the board's first inner corner in the body frame [m].
    board_yaw_deg : direction of the board's x axis (along its rows) from body x [deg].
    prior_R_BS : the approximately known camera orientation that picks among the board's orderings.
    """
    corners = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if len(corners) != board.n_corners:
        raise InputError(f"expected {board.n_corners} corners, got {len(corners)}")
    prior = camera.R_BS if prior_R_BS is None else np.asarray(prior_R_BS, dtype=np.float64)
    T_BF = board_pose_in_body(board_origin, board_yaw_deg)
    obj = board.object_points()
    f = math.sqrt(camera.fu * camera.fv)
    best = None
    for perm in board_orderings(board, mirrored=True):
        norm = camera.normalize(corners[perm])
        ok, rvec, tvec = cv2.solvePnP(obj, norm, np.eye(3), None, flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            continue
        rvec, tvec = cv2.solvePnPRefineLM(obj, norm, np.eye(3), None, rvec, tvec,
                                          (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-14))
        pose = np.concatenate([rvec.ravel(), tvec.ravel()])
        T_BS = _pose_to_T_BS(pose, T_BF)
        if T_BS[2, 3] <= 0:  # a mirrored numbering: the camera would look up from below the floor
            continue
        angle = _rotation_angle(prior.T @ T_BS[:3, :3])
        if best is None or angle < best[0]:
            best = (angle, pose, norm, T_BS)
    if best is None:
        raise InputError("the board's pose could not be solved from its corners")
    angle, pose, norm, T_BS = best
    logger.info("board ordering %.1f deg from the prior camera orientation", math.degrees(angle))

    proj, jac = cv2.projectPoints(obj, pose[:3], pose[3:], np.eye(3), None)
    res = proj.reshape(-1, 2) - norm
    J = jac[:, :6]
    dof = max(1, 2 * len(obj) - 6)
    sigma2 = float(np.sum(res**2)) / dof
    cov_p = sigma2 * np.linalg.inv(J.T @ J)
    G = np.empty((len(QUANTITIES), 6))
    for k in range(6):
        h = 1e-7 * max(1.0, abs(pose[k]))
        dp = np.zeros(6)
        dp[k] = h
        G[:, k] = (mount_quantities(_pose_to_T_BS(pose + dp, T_BF)) - mount_quantities(_pose_to_T_BS(pose - dp, T_BF))) / (2 * h)
    cov_q = G @ cov_p @ G.T
    values = mount_quantities(T_BS)
    rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1)))) * f
    return FloorResult(T_BS=T_BS, values=dict(zip(QUANTITIES, map(float, values))),
                       std=dict(zip(QUANTITIES, map(float, np.sqrt(np.clip(np.diag(cov_q), 0, None))))),
                       rms=rms, n_corners=len(obj))
