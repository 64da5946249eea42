"""``benchmarks/fusion_vs_best.py``: the camera's error statistics behind the oracle variant and the summary over seeds."""

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from fusion_vs_best import correlated_floor, noise_statistics, scaled, seed_summary, with_floor  # noqa: E402


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


def test_scaled_covariance_keeps_correlations():
    @dataclasses.dataclass
    class Increment:
        covariance: np.ndarray

    cov = np.array([[4.0, 1.0, 0.0], [1.0, 1.0, 0.5], [0.0, 0.5, 1.0]])
    (out,) = scaled([Increment(cov)], np.array([0.5, 2.0, 3.0]))
    np.testing.assert_allclose(np.diag(out.covariance), [1.0, 4.0, 9.0])
    d, d0 = np.sqrt(np.diag(out.covariance)), np.sqrt(np.diag(cov))
    np.testing.assert_allclose(out.covariance / np.outer(d, d), cov / np.outer(d0, d0))


def test_correlated_floor_keeps_correlation_coefficients_and_raises_only_small_sigmas():
    """The "floor keeps correlations" variant: σ below the floor raised to it, σ above it kept, correlation
    coefficients those of the unfloored covariance; the default floor raises the diagonal alone."""
    @dataclasses.dataclass
    class Increment:
        covariance: np.ndarray
        ok: bool = True

    sd = np.array([1.3e-6, 4e-6, 5e-5])  # x, y under the 2e-5 floor, yaw above it
    rho = np.array([[1.0, 0.1, 0.0], [0.1, 1.0, -0.9], [0.0, -0.9, 1.0]])
    cov = rho * np.outer(sd, sd)
    out = correlated_floor(cov, (2e-5, 2e-5))
    s = np.sqrt(np.diag(out))
    np.testing.assert_allclose(s, [2e-5, 2e-5, 5e-5])
    np.testing.assert_allclose(out / np.outer(s, s), rho, atol=1e-12)
    (diag_floor,) = with_floor([Increment(cov)], 1.0, (2e-5, 2e-5))
    (kept,) = with_floor([Increment(cov)], 1.0, (2e-5, 2e-5, "correlated"))
    np.testing.assert_allclose(kept.covariance, out)
    np.testing.assert_allclose(np.diag(diag_floor.covariance), np.diag(out))
    assert diag_floor.covariance[1, 2] == cov[1, 2]  # the diagonal floor leaves the covariance: ρ falls to -0.18
    # a component of zero variance gets the floor alone, without correlations
    zero = correlated_floor(np.diag([0.0, 1e-12, 0.0]), (2e-5, 1e-5))
    np.testing.assert_allclose(zero, np.diag([4e-10, 4e-10, 1e-10]))


def test_seed_summary_compares_with_the_best_input_per_seed():
    rows = [
        {"ate": {"vo": 1.0, "wheel": 5.0, "ekf": 1.1, "ekf_smoothed": 1.0, "gtsam": 0.9, "gtsam_online": 1.2},
         "best": 1.0},
        {"ate": {"vo": 4.0, "wheel": 2.0, "ekf": 1.8, "ekf_smoothed": 2.0, "gtsam": 2.2, "gtsam_online": 2.0},
         "best": 2.0},
    ]
    means, versus_best, smoothers = seed_summary(rows)
    assert means == ("mean ATE [mm] vo 2.500, wheel 3.500, best 1.500, ekf 1.450, ekf_smoothed 1.500, "
                     "gtsam 1.550, gtsam_online 1.600")
    # ekf: +10 % and -10 % -> 0 %, at most the best on one seed; gtsam: -10 %, +10 %; iSAM2: +20 %, 0 %
    assert "ekf +0.0 % on average, at most on 1 of 2" in versus_best
    assert "ekf_smoothed +0.0 % on average, at most on 2 of 2" in versus_best
    assert "gtsam_online +10.0 % on average, at most on 1 of 2" in versus_best
    # RTS vs EKF: 1.0/1.1 - 1 = -9.09 %, 2.0/1.8 - 1 = +11.1 % -> +1.0 %
    assert smoothers.startswith("RTS vs EKF +1.0 % on average, at most on 1 of 2")
    # batch vs iSAM2: 0.9/1.2 - 1 = -25 %, 2.2/2.0 - 1 = +10 % -> -7.5 %
    assert "batch vs iSAM2 -7.5 % on average, at most on 1 of 2" in smoothers
    # a drive without motion (the wheels exact, best input 0) is left out of the comparison with the best input
    still = {"ate": {"vo": 0.02, "wheel": 0.0, "ekf": 0.01, "ekf_smoothed": 0.01, "gtsam": 0.01, "gtsam_online": 0.01},
             "best": 0.0}
    assert "ekf +0.0 % on average, at most on 1 of 2" in seed_summary([*rows, still])[1]
