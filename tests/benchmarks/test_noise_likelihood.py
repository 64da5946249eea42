"""The innovation log-likelihood of benchmarks/noise_likelihood.py: its sum, and its maximum near a known bias walk."""

import sys
from pathlib import Path

import numpy as np
from scipy.stats import multivariate_normal

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import noise_likelihood as nl  # noqa: E402

from fusion_vo.backends import ekf as ekf_mod  # noqa: E402


def test_likelihood_sums_gaussian_log_densities():
    rng = np.random.default_rng(3)
    total, expected = nl.Likelihood(), 0.0
    for m in (1, 3, 2):
        a = rng.standard_normal((m, m))
        S = a @ a.T + m * np.eye(m)
        y = rng.standard_normal(m)
        total.add(y.reshape(-1, 1), S)
        expected += multivariate_normal(np.zeros(m), S).logpdf(y)
    assert abs(total.value - expected) < 1e-9
    assert (total.rows, total.updates) == (6, 3)


def test_likelihood_prefers_the_true_bias_walk_and_restores_the_filter():
    update = ekf_mod.PlanarEkf.update
    streams = nl.generated(1e-3, 0, 120.0, "camera+wheels+gyro")
    options = {"imu": {"gyro_noise_density": 2e-3}}
    values = {w: nl.log_likelihood(streams, {"imu.gyro_random_walk": w}, options)[0] for w in (3e-5, 1e-3, 3e-2)}
    # 30 times too small or too large is outside the 95 % likelihood-ratio interval
    assert values[1e-3] > values[3e-5] + nl.LR_95
    assert values[1e-3] > values[3e-2] + nl.LR_95
    assert ekf_mod.PlanarEkf.update is update
