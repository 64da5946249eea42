"""Robust similarity estimation: minimal solver, RANSAC, LMedS, refinement and covariance."""

import math

import numpy as np
import pytest

from frontends.base import similarity_matrix, similarity_params
from frontends.similarity import (
    RobustOptions,
    apply_similarity,
    estimate_similarity,
    scale_motion,
)

TRUE = (30.0, -12.0, math.radians(3.0), math.log(1.02))


def _data(n=120, noise=0.2, outliers=0.3, seed=1):
    rng = np.random.default_rng(seed)
    m = similarity_matrix(*TRUE)
    src = rng.uniform([0, 0], [640, 360], size=(n, 2))
    dst = apply_similarity(m, src) + rng.normal(0.0, noise, (n, 2))
    bad = rng.random(n) < outliers
    dst[bad] += rng.uniform(-60, 60, (bad.sum(), 2))
    return src, dst, bad


@pytest.mark.parametrize("method", ["ransac", "lmeds"])
def test_recovers_similarity_with_outliers(method):
    src, dst, bad = _data()
    fit = estimate_similarity(src, dst, RobustOptions(method=method), np.random.default_rng(0))
    assert fit.ok
    err = fit.params - np.array(TRUE)
    assert np.all(np.abs(err[:2]) < 0.15)
    assert abs(err[2]) < math.radians(0.01) and abs(err[3]) < 2e-4
    # outliers displaced by more than the threshold are all rejected, nearly all inliers kept
    big = bad & (np.hypot(*(dst - apply_similarity(similarity_matrix(*TRUE), src)).T) > 2.0)
    assert not np.any(fit.inliers & big)
    assert fit.n_inliers >= 0.95 * np.count_nonzero(~bad)
    assert 0.15 < fit.sigma < 0.25


def test_lmeds_handles_forty_percent_outliers():
    src, dst, _ = _data(outliers=0.4, seed=3)
    fit = estimate_similarity(src, dst, RobustOptions(method="lmeds"), np.random.default_rng(0))
    assert fit.ok and abs(fit.params[2] - TRUE[2]) < math.radians(0.02)


def test_exact_data_has_floored_covariance():
    src, dst, _ = _data(noise=0.0, outliers=0.0)
    opts = RobustOptions(min_sigma=0.02)
    fit = estimate_similarity(src, dst, opts)
    assert np.allclose(fit.params, TRUE, atol=1e-9)
    assert fit.sigma == pytest.approx(0.02)
    assert np.all(np.diag(fit.covariance) > 0) and np.all(np.isfinite(fit.covariance))
    assert fit.iterations <= 64  # all inliers: the adaptive search stops after the first batch


def test_seeded_generator_is_deterministic():
    src, dst, _ = _data()
    a = estimate_similarity(src, dst, rng=np.random.default_rng(7))
    b = estimate_similarity(src, dst, rng=np.random.default_rng(7))
    assert np.array_equal(a.params, b.params) and np.array_equal(a.inliers, b.inliers)


def test_degenerate_and_too_few():
    src = np.column_stack([np.linspace(0, 600, 30), np.full(30, 100.0)])  # collinear
    dst = src + [5.0, 1.0]
    assert estimate_similarity(src, dst).status == "degenerate"
    assert estimate_similarity(src[:3], dst[:3]).status == "too_few"
    nan = dst.copy()
    nan[:] = np.nan
    assert estimate_similarity(src, nan).status == "too_few"


def test_covariance_is_honest():
    """Normalised squared error over many noisy trials averages the dimension (4)."""
    rng = np.random.default_rng(11)
    m = similarity_matrix(*TRUE)
    nees = []
    for _ in range(300):
        src = rng.uniform([0, 0], [640, 360], size=(60, 2))
        dst = apply_similarity(m, src) + rng.normal(0.0, 0.3, (60, 2))
        fit = estimate_similarity(src, dst, RobustOptions(threshold=2.0), rng)
        e = fit.params - np.array(TRUE)
        nees.append(e @ np.linalg.solve(fit.covariance, e))
    assert 3.0 < np.mean(nees) < 5.5


def test_prior_deviation():
    src, dst, _ = _data(outliers=0.0)
    fit = estimate_similarity(src, dst, prior=similarity_matrix(*TRUE))
    assert fit.prior_deviation < 0.2
    off = similarity_matrix(TRUE[0] + 5.0, *TRUE[1:])
    assert estimate_similarity(src, dst, prior=off).prior_deviation == pytest.approx(5.0, abs=0.2)


def test_scale_motion_is_a_matrix_power():
    m = similarity_matrix(12.0, -3.0, 0.05, 0.01)
    m3 = np.vstack([m, [0, 0, 1]])
    assert np.allclose(scale_motion(m, 2.0), (m3 @ m3)[:2])
    half = np.vstack([scale_motion(m, 0.5), [0, 0, 1]])
    assert np.allclose((half @ half)[:2], m)
    assert np.allclose(similarity_params(scale_motion(m, 0.0)), 0.0, atol=1e-12)


class _Radial:
    """Division-style radial distortion: rectified = c + (p - c)(1 + k r^2), r the distorted radius."""

    def __init__(self, k=2e-7, c=(320.0, 180.0)):
        self.k, self.c = k, np.asarray(c)

    def to_rectified(self, pts):
        d = np.asarray(pts, float) - self.c
        return self.c + d * (1.0 + self.k * (d**2).sum(axis=1, keepdims=True))

    def to_image(self, pts):
        u = np.asarray(pts, float) - self.c
        d = u.copy()
        for _ in range(20):  # fixed point of d (1 + k |d|^2) = u
            d = u / (1.0 + self.k * (d**2).sum(axis=1, keepdims=True))
        return self.c + d


def test_point_map_round_trip_and_estimate_on_rectified_points():
    pm = _Radial()
    rng = np.random.default_rng(2)
    raw = rng.uniform([0, 0], [640, 360], size=(80, 2))
    assert np.allclose(pm.to_image(pm.to_rectified(raw)), raw, atol=1e-9)
    m = similarity_matrix(*TRUE)
    raw_dst = pm.to_image(apply_similarity(m, pm.to_rectified(raw)))
    fit = estimate_similarity(pm.to_rectified(raw), pm.to_rectified(raw_dst))
    assert np.allclose(fit.params, TRUE, atol=1e-7)
    naive = estimate_similarity(raw, raw_dst, RobustOptions(threshold=5.0))
    assert abs(naive.params[3] - TRUE[3]) > 1e-4  # ignoring the distortion biases the estimate
