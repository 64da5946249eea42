"""The reported pose covariances are honest: NEES of a few Monte-Carlo drives near 3 (benchmarks/consistency.py
runs 25 seeds against the chi-square band)."""

import sys
from pathlib import Path

import numpy as np

from fusion_vo.backends.graph import world_covariances

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))


def test_average_nees_of_every_backend_is_near_three():
    from consistency import run

    nees = run(seeds=4, duration=20.0)
    for name, v in nees.items():
        mean = float(np.nanmean(v))
        # 3 is consistent; a covariance 2.7 times too small in each direction gives about 22
        assert 1.0 < mean < 6.0, (name, mean)


def test_graph_covariances_are_rotated_into_the_world_frame():
    local = np.diag([4.0, 1.0, 0.5])[None]
    world = world_covariances(np.array([np.pi / 2]), local)[0]
    np.testing.assert_allclose(world, np.diag([1.0, 4.0, 0.5]), atol=1e-12)
    turned = world_covariances(np.array([np.pi / 4]), np.array([[[1.0, 0.0, 0.2], [0.0, 0.0, 0.0], [0.2, 0.0, 1.0]]]))[0]
    np.testing.assert_allclose(turned[:2, :2], 0.5 * np.ones((2, 2)), atol=1e-12)
    np.testing.assert_allclose(turned[:2, 2], 0.2 / np.sqrt(2.0) * np.ones(2), atol=1e-12)
