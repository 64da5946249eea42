"""The camera's increments against ground truth (:mod:`fusion_vo.evaluation.increments`): their errors, the
variance ratio and lag-1 correlation of those errors."""

from types import SimpleNamespace

import numpy as np

from fusion_vo.evaluation.increments import increment_errors, noise_statistics
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData, VisualIncrement


def test_increment_errors_are_the_body_frame_differences_from_the_truth():
    """A circle driven at 0.2 m/s and 0.5 rad/s: exact increments have no error, a known error added in the
    body frame comes back, a failed increment is left out and one after it does not share a frame."""
    t = np.linspace(0.0, 4.0, 401)
    truth = PoseData(t, np.column_stack([0.4 * np.sin(0.5 * t), 0.4 * (1 - np.cos(0.5 * t)), 0.5 * t]))
    rec = SimpleNamespace(groundtruth=lambda: truth)
    frames = np.arange(0.0, 4.0, 0.05)
    pose = {round(f, 3): truth.xyyaw[np.argmin(np.abs(t - f))] for f in frames}
    cov = np.diag([1e-8, 1e-8, 1e-8])
    added = np.array([1e-4, -2e-4, 3e-4])
    increments = []
    for k, (a, b) in enumerate(zip(frames[:-1], frames[1:])):
        delta = se2.between(pose[round(a, 3)], pose[round(b, 3)]) + (added if k == 5 else 0.0)
        increments.append(VisualIncrement(a, b, delta, cov, status="rejected" if k == 10 else "ok"))
    errors, covariances, chained = increment_errors(rec, increments)
    assert errors.shape == (len(increments) - 1, 3) and covariances.shape == (len(increments) - 1, 3, 3)
    np.testing.assert_allclose(errors[5], added, atol=1e-9)
    np.testing.assert_allclose(np.delete(errors, 5, axis=0), 0.0, atol=1e-9)
    assert not chained[0] and not chained[10] and chained[1:10].all() and chained[11:].all()


def test_noise_statistics_recover_variance_ratio_and_lag1_correlation():
    """Errors e_k = a_k - a_{k-1} + w_k per component: variance 2 s_a² + s_w², lag-1 correlation
    -s_a² / (2 s_a² + s_w²) between increments that share a frame, none across a break."""
    rng = np.random.default_rng(0)
    n = 20000
    s_a, s_w = np.array([1.0, 2.0, 0.5]), np.array([1.0, 0.5, 1.0])
    a = rng.normal(size=(n + 1, 3)) * s_a
    errors = a[1:] - a[:-1] + rng.normal(size=(n, 3)) * s_w
    chained = np.ones(n, dtype=bool)
    chained[0] = False
    stated = np.array([0.5, 2.0, 1.0])  # stated standard deviations
    covariances = np.tile(np.diag(stated**2), (n, 1, 1))
    ratio, lag1 = noise_statistics(errors, covariances, chained)
    variance = 2 * s_a**2 + s_w**2
    np.testing.assert_allclose(ratio, variance / stated**2, rtol=0.05)
    np.testing.assert_allclose(lag1, -s_a**2 / variance, atol=0.03)
    # where no two increments share a frame the errors are independent pairs: no correlation to report
    breaks = np.zeros(n, dtype=bool)
    _, lag1 = noise_statistics(errors, covariances, breaks)
    assert np.all(np.isnan(lag1))
    # pairs across a break are not counted: shuffled blocks of two keep only the within-block pairs
    order = rng.permutation(n // 2)
    blocks = errors[: n // 2 * 2].reshape(-1, 2, 3)[order].reshape(-1, 3)
    chained = np.tile([False, True], n // 2)
    _, lag1 = noise_statistics(blocks, covariances[: len(blocks)], chained)
    np.testing.assert_allclose(lag1, -s_a**2 / variance, atol=0.04)
