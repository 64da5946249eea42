"""The robust kernels (fusion_vo.robust): weight and loss equal to GTSAM's own mEstimators, and the factory's objects."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from fusion_vo.robust import ROBUST_KERNELS, mestimator, robust_loss, robust_weight

GTSAM = {"huber": gtsam.noiseModel.mEstimator.Huber, "cauchy": gtsam.noiseModel.mEstimator.Cauchy}
WIDTHS = (0.3, 1.345, 2.3849, 3.2905, 7.0)


def distances(k: float) -> np.ndarray:
    """Distances from 0 to a thousand widths, both signs, the width itself and its neighbours."""
    d = np.concatenate([[0.0, k, np.nextafter(k, 0.0), np.nextafter(k, np.inf)], k * np.geomspace(1e-3, 1e3, 200),
                        np.random.default_rng(0).uniform(0.0, 20.0 * k, 200)])
    return np.concatenate([d, -d[1:]])


@pytest.mark.parametrize("kernel", ["huber", "cauchy"])
@pytest.mark.parametrize("k", WIDTHS)
def test_weight_and_loss_are_gtsams(kernel, k):
    """w(d) and ρ(d), vectorised and scalar, are GTSAM's mEstimator.weight and .loss to 1e-12 relative."""
    est = GTSAM[kernel].Create(k)
    d = distances(k)
    w_gtsam = np.array([est.weight(float(x)) for x in d])
    np.testing.assert_allclose(robust_weight(d, kernel, k), w_gtsam, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose([robust_weight(float(x), kernel, k) for x in d], w_gtsam, rtol=1e-12, atol=0.0)
    assert all(isinstance(robust_weight(float(x), kernel, k), float) for x in d[:5])
    # GTSAM's Cauchy loss is 0.5 k² log(1 + d²/k²), whose 1 + x rounds for d ≪ k (relative error ~1e-16 k²/d²);
    # ours is the exact log1p: compare where GTSAM's own rounding is below 1e-12 (d ≥ 0.02 k), closely below it
    loss_gtsam = np.array([est.loss(float(x)) for x in d])
    exact = np.abs(d) >= 0.02 * k if kernel == "cauchy" else np.ones(len(d), bool)
    np.testing.assert_allclose(robust_loss(d, kernel, k)[exact], loss_gtsam[exact], rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(robust_loss(d, kernel, k), loss_gtsam, rtol=1e-6, atol=0.0)
    assert robust_loss(0.7 * k, kernel, k).shape == ()


def test_kernels_by_hand():
    """The equations of the module docstring at a few distances (Huber 1.345, Cauchy 2), and the Gaussian."""
    d = np.array([0.5, 3.0])
    np.testing.assert_allclose(robust_weight(d, "huber", 1.345), [1.0, 1.345 / 3.0], rtol=1e-15)
    np.testing.assert_allclose(robust_loss(d, "huber", 1.345), [0.125, 1.345 * 3.0 - 0.5 * 1.345**2], rtol=1e-15)
    np.testing.assert_allclose(robust_weight(d, "cauchy", 2.0), [4.0 / 4.25, 4.0 / 13.0], rtol=1e-15)
    np.testing.assert_allclose(robust_loss(d, "cauchy", 2.0), 2.0 * np.log([1.0625, 3.25]), rtol=1e-15)
    for none in (None, "none"):
        np.testing.assert_array_equal(robust_weight(d, none, 1.0), [1.0, 1.0])
        assert robust_weight(-40.0, none, 1.0) == 1.0
        np.testing.assert_allclose(robust_loss(-d, none, 1.0), 0.5 * d**2, rtol=1e-15)
    assert set(ROBUST_KERNELS) == {"huber", "cauchy", "none"}


@pytest.mark.parametrize("kernel", ["huber", "cauchy"])
@pytest.mark.parametrize("k", WIDTHS)
def test_mestimator_is_gtsams_of_the_width(kernel, k):
    """The factory gives GTSAM's mEstimator of that name and width: serialised (its width, and Cauchy's k²) as one
    made directly, not as one of a width 1e-9 wider, with that one's weights and losses."""
    est = mestimator(kernel, k)
    assert isinstance(est, GTSAM[kernel])
    reference = GTSAM[kernel].Create(k)
    assert est.serialize() == reference.serialize() != GTSAM[kernel].Create(k * (1.0 + 1e-9)).serialize()
    for x in distances(k)[::7]:
        assert est.weight(float(x)) == reference.weight(float(x))
        assert est.loss(float(x)) == reference.loss(float(x))


def test_none_and_unknown_kernels():
    assert mestimator("none", 1.0) is None and mestimator(None, 1.0) is None
    for bad in ("tukey", "Huber", ""):
        with pytest.raises(ValueError):
            mestimator(bad, 1.0)
        for distance in (1.0, np.array([1.0, 3.0])):
            with pytest.raises(ValueError):
                robust_weight(distance, bad, 1.0)
            with pytest.raises(ValueError):
                robust_loss(distance, bad, 1.0)
