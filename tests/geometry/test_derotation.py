"""Gyro de-rotation: roll and pitch between two frames are not read as motion; yaw is left alone."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from frontends.base import similarity_params
from frontends.similarity import fit_least_squares
from fusion_vo.geometry.camera import CameraModel
from fusion_vo.geometry.derotation import GyroDerotation
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.measurements import ImuData

DT = 0.05


def _camera() -> CameraModel:
    return CameraModel(640, 360, 420.0, 420.0, 319.5, 179.5)  # 0.25 m ahead of the axle, 0.1 m high


def _pixels(cam: CameraModel, R_WS: np.ndarray, t_WS: np.ndarray, X: np.ndarray) -> np.ndarray:
    return cam.project((X - t_WS) @ R_WS)  # R_WS^T (X - t) for every row


def _measured_similarity(cam, rotvec_B, move_xy, yaw=0.0):
    """The image similarity of a camera that moves by ``move_xy`` and turns by ``yaw`` about its own
    centre while the body rolls and pitches by ``rotvec_B``, fitted to projected floor points."""
    R_BS, t_BS = cam.R_BS, cam.t_BS
    dR = Rotation.from_rotvec(rotvec_B).as_matrix()
    Rz = Rotation.from_rotvec([0, 0, yaw]).as_matrix()
    R1 = Rz @ dR @ R_BS
    t1 = t_BS + np.array([move_xy[0], move_xy[1], 0.0])
    # floor points under a grid of pixels of the first frame, kept where both frames see them
    gu, gv = np.meshgrid(np.linspace(10, 629, 16), np.linspace(10, 349, 10))
    rays = np.column_stack([cam.normalize(np.column_stack([gu.ravel(), gv.ravel()])), np.ones(gu.size)]) @ R_BS.T
    X = t_BS - rays * (t_BS[2] / rays[:, 2:3])
    p0, p1 = _pixels(cam, R_BS, t_BS, X), _pixels(cam, R1, t1, X)
    keep = (p1[:, 0] > 0) & (p1[:, 0] < 639) & (p1[:, 1] > 0) & (p1[:, 1] < 359)
    p0, p1 = p0[keep], p1[keep]
    a, b = fit_least_squares(p0[:, 0] + 1j * p0[:, 1], p1[:, 0] + 1j * p1[:, 1])
    return np.array([[a.real, -a.imag, b.real], [a.imag, a.real, b.imag]])


def _gyro(rate_B) -> ImuData:
    t = np.arange(0.0, 1.0, 0.005)
    return ImuData(t, np.tile(np.asarray(rate_B, float), (len(t), 1)), np.zeros((len(t), 3)))


@pytest.mark.parametrize("rotvec", [[0.02, 0.0, 0.0], [0.0, -0.03, 0.0], [0.015, 0.02, 0.0]])
def test_roll_and_pitch_are_not_motion(rotvec):
    cam = _camera()
    geo = GroundGeometry(cam)
    move = (0.004, -0.002)
    S = _measured_similarity(cam, rotvec, move)
    # body motion the camera centre made: the camera is 0.25 m ahead, so the body moved the same (no yaw)
    raw, _ = geo.body_increment(similarity_params(S))
    derot = GyroDerotation(_gyro(np.asarray(rotvec) / DT), geo, remove_bias=False)
    fixed, _ = geo.body_increment(similarity_params(derot.apply(S, 0.2, 0.2 + DT)))
    assert np.linalg.norm(raw[:2] - move) > 1e-3  # uncorrected, the tilt reads as millimetres of motion
    assert np.linalg.norm(fixed[:2] - move) < 1e-4  # 95 % or more of the tilt error removed
    assert abs(fixed[2]) < 5e-4
    # the rotation alone moves the image by about f θ (more towards the edges of a wide view)
    assert 1.0 <= derot.flow_px(0.2, 0.2 + DT) / (420.0 * np.linalg.norm(rotvec)) < 1.3


def test_turn_in_place_stays_a_pure_rotation():
    cam = _camera()
    geo = GroundGeometry(cam)
    yaw = 0.04
    # a turn about the axle: the camera, 0.25 m ahead, sweeps an arc
    d = geo.similarity_from_body([0.0, 0.0, yaw])
    derot = GyroDerotation(_gyro([0.0, 0.0, yaw / DT]), geo, remove_bias=False)
    out, _ = geo.body_increment(similarity_params(derot.apply(d, 0.2, 0.2 + DT)))
    assert np.allclose(out, [0.0, 0.0, yaw], atol=1e-9)


def test_bias_of_roll_and_pitch_is_removed():
    cam = _camera()
    geo = GroundGeometry(cam)
    derot = GyroDerotation(_gyro([0.01, -0.02, 0.3]), geo)  # a constant roll or pitch rate is a bias
    assert np.allclose(derot.correction(0.2, 0.25), np.eye(3), atol=1e-12)
