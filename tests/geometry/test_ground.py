"""Ground geometry round trips: random robot motions and camera mounts -> projected floor points ->
pixel similarity -> recovered body motion."""

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frontends.base import similarity_params
from fusion_vo.geometry import se2
from fusion_vo.geometry.camera import R_BS_DOWN_FORWARD, CameraModel
from fusion_vo.geometry.ground import GroundGeometry, GroundRectifier, floor_covariance


def rot_xyz(rx, ry, rz):
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def make_camera(lever_x, lever_y, height, tilt_x, tilt_y, distortion):
    T = np.eye(4)
    T[:3, :3] = R_BS_DOWN_FORWARD @ rot_xyz(tilt_x, tilt_y, 0.0)
    T[:3, 3] = [lever_x, lever_y, height]
    return CameraModel(640, 360, 420.0, 415.0, 321.0, 178.0, "radial-tangential", distortion, T)


def body_to_world(pose):
    T = np.eye(4)
    T[:2, :2] = [[math.cos(pose[2]), -math.sin(pose[2])], [math.sin(pose[2]), math.cos(pose[2])]]
    T[:2, 3] = pose[:2]
    return T


def project_floor(cam, pose, pts_w):
    T_WS = body_to_world(pose) @ cam.T_BS
    T_SW = np.linalg.inv(T_WS)
    P = np.column_stack([pts_w, np.zeros(len(pts_w)), np.ones(len(pts_w))]) @ T_SW.T
    assert np.all(P[:, 2] > 0)
    return cam.project(P[:, :3])


def floor_points_in_view(cam, pose, rng, n=60):
    """Floor points (world) that the camera sees at ``pose``: back-project random pixels."""
    px = rng.uniform([40, 40], [600, 320], size=(n, 2))
    rays = np.column_stack([cam.normalize(px), np.ones(n)])
    T_WS = body_to_world(pose) @ cam.T_BS
    d = rays @ T_WS[:3, :3].T
    o = T_WS[:3, 3]
    s = -o[2] / d[:, 2]
    return (o[None, :] + s[:, None] * d)[:, :2]


def fit_similarity(a, b):
    M, _ = cv2.estimateAffinePartial2D(a.astype(np.float64), b.astype(np.float64), method=cv2.LMEDS)
    return M


@settings(max_examples=60, deadline=None)
@given(
    dx=st.floats(-0.02, 0.02), dy=st.floats(-0.01, 0.01), dyaw=st.floats(-0.08, 0.08),
    lever_x=st.floats(-0.3, 0.4), lever_y=st.floats(-0.1, 0.1), height=st.floats(0.05, 0.3),
    tilt_x=st.floats(-0.1, 0.1), tilt_y=st.floats(-0.1, 0.1), k1=st.floats(-0.1, 0.05),
    seed=st.integers(0, 2**16),
)
def test_round_trip_recovers_body_motion(dx, dy, dyaw, lever_x, lever_y, height, tilt_x, tilt_y, k1, seed):
    rng = np.random.default_rng(seed)
    cam = make_camera(lever_x, lever_y, height, tilt_x, tilt_y, [k1, 0.01, 0.0005, -0.0003])
    geo = GroundGeometry(cam)
    pose0 = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-math.pi, math.pi)])
    delta = np.array([dx, dy, dyaw])
    pose1 = se2.compose(pose0, delta)
    pts_w = floor_points_in_view(cam, pose0, rng)
    u0 = geo.rectifier.to_rectified(project_floor(cam, pose0, pts_w))
    u1 = geo.rectifier.to_rectified(project_floor(cam, pose1, pts_w))
    M = fit_similarity(u0, u1)
    p = similarity_params(M)
    assert abs(p[3]) < 1e-6  # planar motion at constant height: no scale
    est, _ = geo.body_increment(p)
    tol = 1e-6 + 1e-4 * height  # numerical undistortion is exact to ~1e-8 normalised units
    assert np.allclose(est[:2], delta[:2], atol=tol), (est, delta)
    assert abs(se2.wrap_angle(est[2] - delta[2])) < 1e-6


def test_turn_in_place_with_camera_ahead_is_pure_rotation():
    cam = make_camera(0.25, 0.0, 0.1, 0.0, 0.0, [0, 0, 0, 0])
    geo = GroundGeometry(cam)
    rng = np.random.default_rng(1)
    pose0 = np.zeros(3)
    pose1 = np.array([0.0, 0.0, 0.05])
    pts = floor_points_in_view(cam, pose0, rng)
    M = fit_similarity(geo.rectifier.to_rectified(project_floor(cam, pose0, pts)),
                       geo.rectifier.to_rectified(project_floor(cam, pose1, pts)))
    est, _ = geo.body_increment(similarity_params(M))
    # the image itself moves by about 0.25 m * 0.05 rad = 12.5 mm sideways; the body does not translate
    assert abs(M[0, 2]) + abs(M[1, 2]) > 10
    assert np.allclose(est[:2], 0.0, atol=1e-7) and est[2] == pytest.approx(0.05, abs=1e-6)


def test_height_change_is_scale_not_motion():
    cam = make_camera(0.25, 0.0, 0.1, 0.0, 0.0, [0, 0, 0, 0])
    geo = GroundGeometry(cam)
    S = geo.similarity_from_body([0.01, 0.0, 0.0], height_ratio=1.02)
    p = similarity_params(S)
    assert p[3] == pytest.approx(-math.log(1.02))
    est, _ = geo.body_increment(p)
    assert np.allclose(est, [0.01, 0.0, 0.0], atol=1e-12)


def test_rectifier_round_trip_and_identity():
    cam = make_camera(0.25, 0.0, 0.1, 0.05, -0.03, [-0.05, 0.01, 0.001, -0.0005])
    r = GroundRectifier(cam)
    px = np.random.default_rng(0).uniform([0, 0], [640, 360], size=(100, 2))
    assert np.allclose(r.to_image(r.to_rectified(px)), px, atol=1e-6)
    plain = GroundRectifier(CameraModel(640, 360, 400, 400, 320, 180))
    assert plain.trivial and np.array_equal(plain.to_rectified(px), px)


def test_covariance_matches_monte_carlo():
    cam = make_camera(0.2, 0.03, 0.12, 0.02, 0.0, [0, 0, 0, 0])
    geo = GroundGeometry(cam, min_sigma_xy=0, min_sigma_yaw=0)
    p = np.array([12.0, -35.0, 0.04, 0.002])
    C = np.diag([0.04, 0.03, 2e-7, 1e-7])
    C[0, 2] = C[2, 0] = 1e-5
    _, P = geo.body_increment(p, C)
    rng = np.random.default_rng(3)
    samples = rng.multivariate_normal(p, C, size=4000)
    outs = np.array([geo.body_increment(s)[0] for s in samples])
    emp = np.cov(outs.T)
    assert np.allclose(np.sqrt(np.diag(emp)), np.sqrt(np.diag(P)), rtol=0.08)


def test_floors_applied_afterwards_equal_the_floored_increment():
    """The floors are the last step of an increment's covariance: a covariance computed without them and floored
    afterwards (what benchmarks/scale_defaults.py does with cached increments) is the floored one, the diagonal
    raised only where it was below the floor and the correlations kept."""
    cam = make_camera(0.25, 0.02, 0.1, 0.05, -0.03, [0, 0, 0, 0])
    p = np.array([30.0, -60.0, 0.03, 0.001])
    for C in (np.diag([1e-4, 1e-4, 1e-9, 1e-9]), np.diag([1e-1, 1e-1, 1e-7, 1e-7])):
        _, raw = GroundGeometry(cam, min_sigma_xy=0, min_sigma_yaw=0).body_increment(p, C)
        _, floored = GroundGeometry(cam, min_sigma_xy=2e-5, min_sigma_yaw=3e-4).body_increment(p, C)
        again = floor_covariance(raw, 2e-5, 3e-4)
        assert np.array_equal(again, floored)
        raised = np.diag(raw) < np.array([2e-5, 2e-5, 3e-4]) ** 2
        assert np.array_equal(np.diag(again) != np.diag(raw), raised)
        assert np.array_equal(again[~np.eye(3, dtype=bool)], raw[~np.eye(3, dtype=bool)])
    assert not np.shares_memory(floor_covariance(raw, 0, 0), raw)


def test_height_uncertainty_enters_the_translation_covariance():
    """A measured height (a range finder's) with standard deviation σ_h: the increment's covariance gains the
    spread of the translation over heights drawn from N(h, σ_h²) (it scales with the height; yaw does not)."""
    cam = make_camera(0.25, 0.02, 0.1, 0.05, -0.03, [0, 0, 0, 0])
    geo = GroundGeometry(cam, min_sigma_xy=0, min_sigma_yaw=0)
    p = np.array([30.0, -60.0, 0.03, 0.001])  # a few cm of motion and a turn
    C = np.diag([1e-4, 1e-4, 1e-9, 1e-9])
    sigma_h = 5e-4
    _, P0 = geo.body_increment(p, C, 0.1)
    _, P = geo.body_increment(p, C, 0.1, sigma_h)
    heights = np.random.default_rng(4).normal(0.1, sigma_h, 4000)
    spread = np.cov(np.array([geo.body_increment(p, None, h)[0] for h in heights]).T)
    added = P - P0
    assert np.allclose(added[2], 0.0) and np.allclose(added[:, 2], 0.0)
    assert np.allclose(np.sqrt(np.diag(added)[:2]), np.sqrt(np.diag(spread)[:2]), rtol=0.06)
    assert added[0, 0] > 10 * P0[0, 0]  # here it dominates what the pixels say


def test_camera_not_looking_down_is_rejected():
    T = np.eye(4)
    T[:3, 3] = [0, 0, 0.1]  # camera z along body z: looking up
    with pytest.raises(ValueError, match="straight down"):
        GroundGeometry(CameraModel(640, 360, 400, 400, 320, 180, T_BS=T))


@pytest.mark.parametrize("coeffs", [[-0.3, 0.1, 0.001, -0.002], [-0.03, 0.01, 0.0005, -0.0003, 0.004],
                                    [0.2, -0.5, -0.01, 0.02, 0.3]])
def test_distortion_is_opencv_projectpoints_to_the_last_bit(coeffs):
    cam = CameraModel(fu=412.5, fv=409.0, cu=321.7, cv=177.2, width=640, height=360,
                      distortion_model="radial-tangential", distortion=coeffs)
    xy = np.random.default_rng(3).uniform(-1.0, 1.0, (2000, 2))
    expected, _ = cv2.projectPoints(np.column_stack([xy, np.ones(len(xy))]).reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                    cam.K, cam.distortion)
    got = cam.denormalize(xy)
    assert got.shape == (2000, 2) and np.array_equal(got, expected.reshape(-1, 2))
    near = np.abs(xy).max(axis=1) < 0.5  # where OpenCV's iterative undistortion converges for every model here
    assert np.allclose(cam.normalize(got[near]), xy[near], atol=1e-6)  # and normalize still inverts it
