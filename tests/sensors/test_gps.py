"""The GPS measurement model: prediction, Jacobians, gate, robust weight, GTSAM factor, world alignment."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from fusion_vo.geometry import se2
from fusion_vo.measurements import GpsData
from fusion_vo.robust import robust_weight
from fusion_vo.sensors import gps
from fusion_vo.backends.factors import ModelFactor

LEVER = np.array([-0.35, 0.12, 0.8])


def antenna_factor(key, z, lever, cov=np.eye(2), robust=None):
    """A fix as the graph adds it: the antenna model's factor on one pose (a CustomFactor)."""
    return ModelFactor(gps.ANTENNA, np.asarray(z, float), {"pose": (key,)}, np.asarray(cov, float), {},
                       {"lever_arm": np.asarray(lever, float)[:2]}, None, robust).custom_factor()


def numeric_jacobian(f, x, eps=1e-6):
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(len(x)):
        d = np.zeros_like(x)
        d[i] = eps
        cols.append((f(x + d) - f(x - d)) / (2 * eps))
    return np.column_stack(cols)


@pytest.mark.parametrize("pose", [(0.0, 0.0, 0.0), (3.0, -2.0, 2.5), (-1.0, 4.0, -1.2)])
def test_prediction_is_pose_plus_rotated_lever_arm(pose):
    T = se2.to_matrix(pose)
    expected = (T @ np.array([LEVER[0], LEVER[1], 1.0]))[:2]
    np.testing.assert_allclose(gps.predict(pose, LEVER), expected, atol=1e-12)


@pytest.mark.parametrize("pose", [(0.0, 0.0, 0.0), (3.0, -2.0, 2.5), (-1.0, 4.0, -1.2)])
def test_world_jacobian_matches_numerical_differentiation(pose):
    num = numeric_jacobian(lambda p: gps.predict(p, LEVER), pose)
    np.testing.assert_allclose(gps.jacobian(pose, LEVER), num, atol=1e-8)


@pytest.mark.parametrize("pose", [(0.5, 1.0, 0.3), (3.0, -2.0, 2.5)])
def test_gtsam_factor_jacobian_matches_numerical_differentiation_on_the_manifold(pose):
    key = gtsam.symbol("x", 0)
    z = np.array([1.0, 2.0])
    factor = antenna_factor(key, z, LEVER)
    p0 = gtsam.Pose2(*pose)
    values = gtsam.Values()
    values.insert(key, p0)
    A, b = factor.linearize(values).jacobian()  # whitened by a unit model: A = H, b = -error

    def err(delta):
        v = gtsam.Values()
        v.insert(key, p0.retract(delta))
        return factor.unwhitenedError(v)

    np.testing.assert_allclose(A, numeric_jacobian(err, np.zeros(3)), atol=1e-7)
    np.testing.assert_allclose(-b, gps.predict(pose, LEVER) - z, atol=1e-12)


def test_factor_without_lever_arm_agrees_with_gtsams_translation_prior():
    key = gtsam.symbol("x", 0)
    model = gtsam.noiseModel.Isotropic.Sigma(2, 0.5)
    z = np.array([2.0, -1.0])
    ours = antenna_factor(key, z, [0.0, 0.0], np.eye(2) * 0.25)
    native = gtsam.PoseTranslationPrior2D(key, gtsam.Pose2(z[0], z[1], 0.0), model)
    values = gtsam.Values()
    values.insert(key, gtsam.Pose2(0.4, 0.3, 1.1))
    A1, b1 = ours.linearize(values).jacobian()
    A2, b2 = native.linearize(values).jacobian()
    np.testing.assert_allclose(A1, A2, atol=1e-9)
    np.testing.assert_allclose(b1, b2, atol=1e-9)


def test_robust_weights():
    """The fixes' weights are the one robust weight of every reading (fusion_vo.robust)."""
    assert robust_weight(1.0, "huber", 2.0) == 1.0
    assert robust_weight(8.0, "huber", 2.0) == pytest.approx(0.25)
    assert robust_weight(2.0, "cauchy", 2.0) == pytest.approx(0.5)
    assert robust_weight(40.0, "cauchy", 2.0) < 0.003
    assert robust_weight(40.0, "none", 2.0) == 1.0 and robust_weight(40.0, None, 2.0) == 1.0
    for distance in (1.0, np.array([1.0, 3.0])):
        with pytest.raises(ValueError):
            robust_weight(distance, "tukey", 2.0)
    with pytest.raises(ValueError):
        gps.GpsNoise(kernel="tukey")


def test_gate_rejects_and_counts_a_20_m_jump_and_accepts_a_normal_fix():
    model = gps.GpsModel(LEVER)
    pose = np.array([10.0, 5.0, 0.7])
    cov = np.diag([0.3**2, 0.3**2])
    truth = gps.predict(pose, LEVER)
    ok = model.check(pose, truth + [0.2, -0.3], cov, t=1.0)
    assert ok.accepted and ok.d2 == pytest.approx((0.2**2 + 0.3**2) / 0.3**2)
    assert ok.weight == pytest.approx(1.0 / (1.0 + ok.d2 / 4.0))  # Cauchy, k = 2
    np.testing.assert_allclose(ok.R, cov / ok.weight)
    jump = model.check(pose, truth + [20.0, 0.0], cov, t=2.0)
    assert not jump.accepted and jump.weight == 0.0
    assert (model.n_used, model.n_rejected, model.rejected_t) == (1, 1, [2.0])
    # with a large pose uncertainty the same jump is plausible and passes the gate, down-weighted
    loose = model.check(pose, truth + [20.0, 0.0], cov, pose_covariance=np.diag([100.0, 100.0, 0.1]))
    assert loose.accepted and loose.d2 < 5.0 and loose.weight == pytest.approx(1.0 / (1.0 + loose.d2 / 4.0))


def _graph_with_fixes(jump: float, kernel: str):
    """A 21-pose straight drive with odometry and a fix at every pose; fix 10 jumps by ``jump`` metres."""
    rng = np.random.default_rng(3)
    n = 21
    truth = np.column_stack([np.arange(n) * 0.5, np.zeros(n), np.zeros(n)])
    model = gps.GpsModel(LEVER, gps.GpsNoise(kernel=kernel))
    cov = np.eye(2) * 0.1**2
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    odo = gtsam.noiseModel.Diagonal.Sigmas([0.01, 0.01, 0.002])
    for i in range(n):
        values.insert(i, gtsam.Pose2(*truth[i]))
        if i:
            graph.add(gtsam.BetweenFactorPose2(i - 1, i, gtsam.Pose2(0.5, 0.0, 0.0), odo))
        z = gps.predict(truth[i], LEVER) + rng.normal(0, 0.1, 2)
        if i == 10:
            z = z + [0.0, jump]
        robust = None if kernel == "none" else (kernel, model.noise.kernel_width)
        graph.add(antenna_factor(i, z, LEVER, model.covariance(cov), robust))
    result = gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()
    return np.array([[result.atPose2(i).x(), result.atPose2(i).y()] for i in range(n)])


def test_robust_factor_ignores_a_20_m_jump_that_moves_a_plain_gaussian_factor():
    clean = _graph_with_fixes(0.0, "cauchy")
    jumped = _graph_with_fixes(20.0, "cauchy")
    assert np.max(np.linalg.norm(jumped - clean, axis=1)) < 0.01  # the jump moves nothing (< 1 cm)
    plain = _graph_with_fixes(20.0, "none")
    assert np.max(np.linalg.norm(plain - clean, axis=1)) > 0.5  # without the kernel it drags the track


def _fixes(t, enu, sigma=0.05, lever=LEVER):
    n = len(t)
    return GpsData(t=np.asarray(t, float), enu=np.column_stack([enu, np.zeros(n)]),
                   covariance=np.tile(np.eye(2) * sigma**2, (n, 1, 1)), geodetic=np.zeros((n, 3)),
                   status=np.zeros(n, int), datum=(0.0, 0.0, 0.0), lever_arm=np.asarray(lever, float),
                   horizontal_sigma=sigma)


def test_alignment_recovers_heading_and_offset_of_enu():
    rng = np.random.default_rng(1)
    t = np.linspace(0, 20, 401)
    track = np.column_stack([np.cos(0.2 * t) * 3 - 3, np.sin(0.2 * t) * 3, 0.2 * t])  # local frame
    true_yaw, true_off = math.radians(37.0), np.array([12.0, -4.0])
    enu_poses = gps.Alignment(true_yaw, true_off, 0.0, 0).apply(track)
    tf = t[::10]
    z = gps.predict(gps.interpolate_poses(t, enu_poses, tf), LEVER) + rng.normal(0, 0.05, (len(tf), 2))
    fit = gps.align_to_fixes(t, track, _fixes(tf, z))
    assert fit is not None
    assert abs(math.degrees(fit.yaw - true_yaw)) < 0.5
    np.testing.assert_allclose(fit.offset, true_off, atol=0.05)
    assert fit.rms < 0.1
    np.testing.assert_allclose(fit.apply(track)[:, :2], enu_poses[:, :2], atol=0.1)


def test_alignment_waits_until_the_antenna_has_moved():
    t = np.linspace(0, 5, 51)
    still = np.zeros((51, 3))
    z = np.tile(gps.predict([0, 0, 0], LEVER), (51, 1)) + np.random.default_rng(0).normal(0, 0.05, (51, 2))
    assert gps.align_to_fixes(t, still, _fixes(t, z)) is None
