"""Synthetic calibration data for the tests: chessboards rendered with the project's floor renderer.

The board frame F is the renderer's world: the board lies in the plane z_F = 0 with its inner corners at
``(i * square, j * square)`` and a white margin of one square; the camera looks at it from z_F > 0.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from fusion_vo.calibration.chessboard import Board
from fusion_vo.geometry.camera import R_BS_DOWN_FORWARD, CameraModel
from fusion_vo.simulation.floor import Floor
from fusion_vo.simulation.render import Renderer

TEXELS_PER_SQUARE = 24


def board_floor(board: Board, dark: float = 30.0, light: float = 220.0, border: float = 110.0) -> Floor:
    """A :class:`Floor` holding ``board`` (plus a one-square white margin) with its corner 0 at the origin."""
    n = TEXELS_PER_SQUARE
    k = np.arange((board.cols + 3) * n)  # texel columns from -2 squares
    a = np.floor(k / n).astype(int) - 2  # square index along x: -2 .. cols
    k = np.arange((board.rows + 3) * n)
    b = np.floor(k / n).astype(int) - 2
    A, B = np.meshgrid(a, b)
    inside = (A >= -1) & (A <= board.cols - 1) & (B >= -1) & (B <= board.rows - 1)
    tex = np.where(inside & ((A + B) % 2 == 0), dark, light).astype(np.float32)
    s = board.square / n
    # texel (0, 0) is centred half a texel inside the texture's outer edge at -2 squares
    origin = (-2 * board.square + s / 2, -2 * board.square + s / 2)
    return Floor(tex, s, origin=origin, wrap=False, border_value=border)


def render_views(camera: CameraModel, board: Board, poses: list[np.ndarray], rng: np.random.Generator,
                 noise: float = 1.5, supersample: int = 3) -> list[np.ndarray]:
    """Render ``board`` from camera poses ``T_FS`` (camera-to-board), with Gaussian noise [grey levels]."""
    renderer = Renderer(camera, board_floor(board), supersample)
    out = []
    for T in poses:
        img = renderer.radiance(T).astype(np.float64)
        img = cv2.GaussianBlur(img, (0, 0), 0.5) + rng.normal(0.0, noise, img.shape)
        out.append(np.clip(np.rint(img), 0, 255).astype(np.uint8))
    return out


def _rot(axis: int, angle: float) -> np.ndarray:
    return cv2.Rodrigues(np.eye(3)[axis] * angle)[0]


def random_view(camera: CameraModel, board: Board, rng: np.random.Generator,
                distance: tuple[float, float] = (0.3, 0.5), max_tilt_deg: float = 40.0,
                margin_px: float = 20.0) -> np.ndarray:
    """A camera pose ``T_FS`` from which the whole board (with its margin) is inside the image."""
    outline = np.array([[-1, -1, 0], [board.cols, -1, 0], [board.cols, board.rows, 0], [-1, board.rows, 0]],
                       dtype=np.float64) * board.square
    centre = np.array([(board.cols - 1) / 2, (board.rows - 1) / 2, 0.0]) * board.square
    for _ in range(2000):
        tilt = np.deg2rad(rng.uniform(-max_tilt_deg, max_tilt_deg, 2))
        R = R_BS_DOWN_FORWARD @ _rot(0, tilt[0]) @ _rot(1, tilt[1]) @ _rot(2, rng.uniform(-math.pi, math.pi))
        z = rng.uniform(*distance)
        aim = centre + np.append(rng.uniform(-0.3, 0.3, 2) * board.square * np.array([board.cols, board.rows]), 0)
        t = aim - R @ np.array([0.0, 0.0, z])  # the optical axis passes through the aim point
        if t[2] < 0.1:
            continue
        pts = (outline - t) @ R  # board outline in camera coordinates
        if np.any(pts[:, 2] < 0.05):
            continue
        uv = camera.project(pts)
        if (uv.min(axis=0) > margin_px).all() and uv[:, 0].max() < camera.width - margin_px and \
                uv[:, 1].max() < camera.height - margin_px:
            T = np.eye(4)
            T[:3, :3] = R
            T[:3, 3] = t
            return T
    raise RuntimeError("no board pose fits the image")


def floor_view_pose(T_BS: np.ndarray, board_origin: tuple[float, float], board_yaw: float) -> np.ndarray:
    """Camera pose ``T_FS`` for a camera mounted at ``T_BS`` and a board at ``board_origin``, ``board_yaw`` [rad]
    in the body frame (robot standing still)."""
    T_BF = np.eye(4)
    T_BF[:3, :3] = _rot(2, board_yaw)
    T_BF[:2, 3] = board_origin
    return np.linalg.inv(T_BF) @ T_BS
