"""Jacobians of the EKF motion model and of the graph's custom factors against finite differences."""

import gtsam
import numpy as np

from fusion_vo.backends import FusionConfig
from fusion_vo.backends.ekf import DIM, PlanarEkf
from fusion_vo.backends.graph import X, S, W, heading_change_factor, scaled_between_error, wheel_heading_error


def _predict(x, dt):
    ekf = PlanarEkf(FusionConfig())
    ekf.kf.x = np.asarray(x, dtype=float).reshape(DIM, 1)
    F = ekf.predict(dt)
    return ekf.x.copy(), F


def test_ekf_transition_jacobian():
    x = np.array([0.3, -0.2, 0.7, 0.4, 0.02, 0.8, 0.01, 1.02, 0.99, 0.05, 0.98])
    _, F = _predict(x, 0.05)
    eps = 1e-7
    num = np.zeros((DIM, DIM))
    for i in range(DIM):
        d = np.zeros(DIM)
        d[i] = eps
        num[:, i] = (_predict(x + d, 0.05)[0] - _predict(x - d, 0.05)[0]) / (2 * eps)
    np.testing.assert_allclose(F, num, atol=1e-7)


def test_ekf_wheel_block_jacobian_includes_the_wheel_scale():
    x0 = np.array([0.3, -0.2, 0.7, 0.4, 0.02, 0.8, 0.01, 1.02, 0.99, 0.05, 0.98])

    def block(x):
        ekf = PlanarEkf(FusionConfig())
        ekf.kf.x = np.asarray(x, dtype=float).reshape(DIM, 1)
        return ekf.wheel_block(np.zeros(3), np.eye(3))

    _, _, h, H, _, _ = block(x0)
    np.testing.assert_allclose(h, [0.98 * 0.4, 0.98 * 0.02, 0.99 * 0.8])
    eps = 1e-7
    num = np.zeros((3, DIM))
    for i in range(DIM):
        d = np.zeros(DIM)
        d[i] = eps
        num[:, i] = (block(x0 + d)[2] - block(x0 - d)[2]) / (2 * eps)
    np.testing.assert_allclose(H, num, atol=1e-7)


def test_ekf_prediction_follows_the_arc():
    x = np.zeros(DIM)
    x[3], x[5], x[7], x[8] = 1.0, np.pi / 2, 1.0, 1.0  # quarter circle of radius 2/π in one second
    pred, _ = _predict(x, 1.0)
    np.testing.assert_allclose(pred[:3], [2 / np.pi, 2 / np.pi, np.pi / 2], atol=1e-12)


def _numeric_jacobians(factor, values, keys):
    out = []
    base = values
    for key in keys:
        is_pose = chr(gtsam.Symbol(key).chr()) == "x"
        dim = 3 if is_pose else 1
        J = np.zeros((factor.dim(), dim))
        for i in range(dim):
            cols = []
            for sign in (1, -1):
                v = gtsam.Values(base)
                delta = gtsam.VectorValues()
                d = np.zeros(dim)
                d[i] = sign * 1e-6
                delta.insert(key, d)
                v = v.retract(delta)
                cols.append(factor.unwhitenedError(v))
            J[:, i] = (cols[0] - cols[1]) / 2e-6
        out.append(J)
    return out


def _values():
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose2(0.2, -0.1, 0.4))
    v.insert(X(1), gtsam.Pose2(0.25, -0.06, 0.47))
    v.insert(S(0), 1.03)
    v.insert(W(0), 0.98)
    return v


def test_visual_and_wheel_heading_factor_jacobians():
    v = _values()
    unit3 = gtsam.noiseModel.Unit.Create(3)
    unit1 = gtsam.noiseModel.Unit.Create(1)
    cases = [
        (gtsam.CustomFactor(unit3, [X(0), X(1), S(0)], scaled_between_error(np.array([0.05, 0.03, 0.06]))), 3),
        (gtsam.CustomFactor(unit1, [X(0), X(1), W(0)], wheel_heading_error(0.068)), 1),
    ]
    for factor, dim in cases:
        keys = list(factor.keys())
        jac = factor.linearize(v)
        A = jac.jacobian()[0]
        num = np.hstack(_numeric_jacobians(factor, v, keys))
        np.testing.assert_allclose(A, num, atol=1e-6)


def test_linear_gyro_factor_is_exact_away_from_its_linearisation_point():
    pi, pj = gtsam.Pose2(0, 0, 3.1), gtsam.Pose2(1, 0, -3.1)
    f = heading_change_factor(X(0), X(1), S(0), 0.1, -0.05, 0.01, pi, pj, 0.0)
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose2(0.3, 0.1, 3.0))
    v.insert(X(1), gtsam.Pose2(1.2, 0.0, -3.0))
    v.insert(S(0), 0.2)
    # d_ψ wraps across ±π: (-3.0 - 3.0) + 2π; error = d_ψ - Θ - gain·b
    e = (-3.0 - 3.0 + 2 * np.pi) - 0.1 + 0.05 * 0.2
    assert np.isclose(f.error(v), 0.5 * (e / 0.01) ** 2)
