"""How the simulated camera is mounted on the robot, and the robot's pose in the world.

The mount ``T_BS`` maps camera coordinates to body coordinates (``datasets/README.md``). The untilted
mount looks straight down with image-up pointing forward (body x)::

    R_BS0 = [[ 0, -1,  0],
             [-1,  0,  0],
             [ 0,  0, -1]]

and a tilt rotates the camera about its own x and y axes: ``R_BS = R_BS0 · R_x(tilt_x) · R_y(tilt_y)``.
The camera centre sits ``lever_arm`` ahead of the axle, ``lateral_offset`` to the left and ``height``
above the floor. A planar body pose ``(x, y, yaw)`` is ``T_WB = [R_z(yaw), (x, y, 0)]``, and the camera
pose the renderer needs is ``T_WS = T_WB · T_BS``.

The lens and intrinsics are :class:`fusion_vo.geometry.camera.CameraModel`, the same model the
estimators use.
"""

from __future__ import annotations

import math

import numpy as np

from fusion_vo.geometry.camera import R_BS_DOWN_FORWARD


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
    T[:3, :3] = R_BS_DOWN_FORWARD @ rot_x(math.radians(tilt_x_deg)) @ rot_y(math.radians(tilt_y_deg))
    T[:3, 3] = [lever_arm, lateral_offset, height]
    return T


def body_pose(x: float, y: float, yaw: float) -> np.ndarray:
    """``T_WB`` (4x4) of a planar body pose."""
    T = np.eye(4)
    T[:3, :3] = rot_z(yaw)
    T[:3, 3] = [x, y, 0.0]
    return T
