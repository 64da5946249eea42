"""The block-tridiagonal batch solver, its fallback to GTSAM's optimizer, and iSAM2's marginalisation of old nodes agree with GTSAM's own."""

import dataclasses

import numpy as np
import pytest

from fusion_vo.backends import FusionConfig, SensorStreams, chain, fuse, graph
from fusion_vo.backends import isam as G
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


@pytest.fixture(scope="module")
def streams():
    s = synthetic_streams(SyntheticOptions(duration=12.0, visual_scale=1.02), seed=3)
    return SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)


def _random_chain(rng, sizes, reach=None):
    """A random SPD block-tridiagonal matrix with blocks of ``sizes`` and a right-hand side: rows tie each
    block to the next, dense, or (``reach``) only the last ``reach`` columns of a block to the next block,
    as the graph's cuts do."""
    n = sum(sizes)
    A = np.zeros((n + 5, n))
    starts = np.concatenate([[0], np.cumsum(sizes)])
    r = 0
    for k in range(len(sizes)):
        hi = starts[min(k + 2, len(sizes))]
        for _ in range(sizes[k] + 3):
            if r >= len(A):
                A = np.vstack([A, np.zeros((1, n))])
            A[r, starts[k]:hi] = rng.normal(size=hi - starts[k])
            if reach is not None and r % 2:  # every other row within the block only
                A[r, starts[k + 1]:] = 0.0
            r += 1
        if reach is not None and k + 1 < len(sizes):  # nothing left of the last `reach` columns reaches across
            rows = np.flatnonzero(A[:, starts[k + 1]:hi].any(axis=1))
            A[np.ix_(rows, np.arange(starts[k], starts[k + 1] - reach))] = 0.0
    return A.T @ A, rng.normal(size=n), starts


@pytest.mark.parametrize("reach", [None, 2])
def test_block_sweeps_solve_and_invert_a_block_tridiagonal_system(reach):
    rng = np.random.default_rng(0)
    sizes = [4, 6, 3, 5, 4]
    H, g, starts = _random_chain(rng, sizes, reach)
    n = len(g)
    lay = chain.Layout(np.arange(n), np.ones(n, dtype=np.int64), np.arange(n), n, starts, max(sizes))
    rows, cols = np.nonzero(H)
    slots = lay.slots(rows, cols)
    flat = np.zeros((2 * len(sizes) - 1) * max(sizes) ** 2)
    keep = slots >= 0
    flat[slots[keep]] = H[rows[keep], cols[keep]]
    system = chain.System(lay, flat, g)
    if reach is not None:  # the couplings reach across from the last columns of each block only
        assert np.all(system.tail == np.array(sizes[:-1]) - reach)
    factors = system.factor()
    np.testing.assert_allclose(system.solve(factors), np.linalg.solve(H, g), rtol=1e-9, atol=1e-12)
    damped = system.solve(system.factor(0.7))
    np.testing.assert_allclose(damped, np.linalg.solve(H + 0.7 * np.eye(n), g), rtol=1e-9, atol=1e-12)
    cov = np.linalg.inv(H)
    columns = np.array([0, 4, 10, 13, 18])  # 2x2 blocks inside the blocks
    blocks = system.marginal_blocks(factors, columns, 2)
    for c, b in zip(columns, blocks):
        np.testing.assert_allclose(b, cov[c:c + 2, c:c + 2], rtol=1e-9, atol=1e-12)
    bad = chain.System(lay, np.zeros_like(flat), g)  # all zero: not positive definite
    with pytest.raises(chain.Indeterminate):
        bad.factor()


def test_layout_refuses_a_long_loop_and_splits_a_chain():
    n = 300
    keys = np.arange(n, dtype=np.int64)
    dims = np.full(n, 3)
    consecutive = (keys[:-1], keys[1:])
    lay = chain.layout(keys, dims, keys.astype(float), [consecutive])
    assert lay.n_blocks > 1 and lay.size <= chain.MAX_BLOCK
    assert np.all(np.diff(lay.starts) % 3 == 0)  # no variable straddles two blocks
    with pytest.raises(chain.NotAChain):
        chain.layout(keys, dims, keys.astype(float), [consecutive, (keys[:1], keys[-1:])])


def test_a_graph_that_is_not_a_chain_gets_gtsam_optimizer_with_the_same_solution(streams, monkeypatch):
    """The fallback (GTSAM's ``LevenbergMarquardtOptimizer``) takes the chain loop's steps: the same solution to
    the two loops' different first damping (GTSAM's 1e-5, about 1e-9 m here). Its covariances are GTSAM's
    ``Marginals`` linearised at the solution, the chain's at the point before the last step, a step of a few
    micrometres: they differ by about 6e-4 of the largest entry (the same point gives the same marginals to
    1e-9: ``test_solver_equals_gtsam.py``)."""
    config = FusionConfig.from_dict({"graph": {"online": False}})
    ours = fuse(streams, "gtsam", config)
    used = []
    solve = graph.gtsam_levenberg_marquardt

    def refuse(*args, **kwargs):
        raise chain.NotAChain("compare with GTSAM's optimizer")

    def spy(*args, **kwargs):
        used.append(True)
        return solve(*args, **kwargs)

    monkeypatch.setattr(chain, "ChainProblem", refuse)
    monkeypatch.setattr(graph, "gtsam_levenberg_marquardt", spy)
    theirs = fuse(streams, "gtsam", config)
    assert used
    a, b = ours.trajectories["gtsam"].xyyaw, theirs.trajectories["gtsam"].xyyaw
    assert np.abs(a - b).max() < 1e-8
    ca, cb = ours.covariances["gtsam"], theirs.covariances["gtsam"]
    np.testing.assert_allclose(ca, cb, rtol=0, atol=2e-3 * np.abs(cb).max())
    for key, value in theirs.calibration["gtsam"].items():
        if key.endswith("_sigma"):
            assert ours.calibration["gtsam"][key] == pytest.approx(value, rel=1e-2)
        else:
            assert ours.calibration["gtsam"][key] == pytest.approx(value, rel=1e-8, abs=1e-9)


def test_isam2_marginalising_old_nodes_keeps_every_estimate(streams, monkeypatch):
    retired = []
    complete = G.Retired.complete

    def spy(self, values):
        retired.append(len(self.values))
        return complete(self, values)

    monkeypatch.setattr(G.Retired, "complete", spy)
    monkeypatch.setattr(G.Retired.__init__, "__defaults__", (40,))
    short = fuse(streams, "gtsam", FusionConfig())
    assert retired and retired[-1] > 100  # most of the 240 nodes left the tree
    monkeypatch.setattr(G.Retired.__init__, "__defaults__", (10**9,))
    full = fuse(streams, "gtsam", FusionConfig())
    a, b = short.trajectories["gtsam_online"].xyyaw, full.trajectories["gtsam_online"].xyyaw
    assert np.abs(a - b).max() < 1e-9
    np.testing.assert_allclose(short.covariances["gtsam_online"], full.covariances["gtsam_online"], rtol=1e-9,
                               atol=1e-15)
    # the batch starts from iSAM2's final estimate, which re-eliminating the tree before each
    # marginalisation (``Retired._make_leaves``) moves in its last digits, and stops at its tolerance
    a, b = short.trajectories["gtsam"].xyyaw, full.trajectories["gtsam"].xyyaw
    assert np.abs(a - b).max() < 1e-5
    d = np.abs(short.covariances["gtsam"] - full.covariances["gtsam"]).max()
    assert d < 1e-4 * np.abs(full.covariances["gtsam"]).max()


def test_isam2_marginalises_a_long_drive_of_wheels_and_gyro_alone():
    """Without a camera or heading reference the calibration segments' variables sit beside the poses in
    the Bayes tree; marginalising old nodes used to fail half-way there (seed 1 after 1200 nodes) and leave
    a tree that crashed the process. The online track must come out, close to the batch's."""
    s = synthetic_streams(SyntheticOptions(duration=120, ahrs_sigma=0.02), seed=1)
    imu = dataclasses.replace(s.imu, noise={}, orientation=None)
    streams = SensorStreams(visual=None, camera_height=s.camera_height, wheel=s.wheel, imu=imu)
    result = fuse(streams, "gtsam", FusionConfig.from_dict({"imu": {"gyro_noise_density": 2e-3}}))
    online, batch = result.trajectories["gtsam_online"].xyyaw, result.trajectories["gtsam"].xyyaw
    assert len(online) == len(batch) == 2401
    # a filter and its smoother on 120 s of dead reckoning: within a few per cent of the 20 m driven
    assert np.hypot(*(online[-1, :2] - batch[-1, :2])) < 1.0
