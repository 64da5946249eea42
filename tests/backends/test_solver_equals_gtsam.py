"""The hand-written batch Levenberg–Marquardt equals GTSAM's ``LevenbergMarquardtOptimizer`` on the same graph.

The problem is the batch graph ``run_graph`` builds from a generated 3 s drive (61 poses, 15 gyro-bias and
calibration variables, visual, wheel and gyro factors, the project's own sensor-model factors), captured where
``run_graph`` hands it to its solver. GTSAM's optimizer gets the same factors, each sensor-model factor as a
``gtsam.CustomFactor`` around the same model (:meth:`fusion_vo.backends.factors.ModelFactor.custom_factor`), the
same start values, iteration limit and tolerance.

Tolerances. On these problems every Gauss–Newton step lowers the cost, so both loops take the same steps:
GTSAM's starts with ``λ = 1e-5``, the hand-written one with ``λ = 0``, a damping 1e-9 of the smallest diagonal
entry of these normal equations, which moves the iterates by about 1e-11 m. The two solutions therefore agree
to 1e-8 of the largest variable (1.3 m here) and their costs to 1e-10; one iteration more or less, or another
damping schedule, moves the solution by 1e-6 to 1e-2 m (the default tolerance stops each loop after two or
three steps) and fails the comparison. Run to convergence, both reach the same minimum to the same tolerances.
"""

import re

import numpy as np
import pytest

import gtsam

from fusion_vo.backends import FusionConfig, SensorStreams, chain, fuse, graph
from fusion_vo.backends.graph_builder import X
from fusion_vo.robust import robust_weight
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

#: the cases: (wrong visual matches [s], robust kernel)
CASES = {"clean": ([], "huber"), "wrong match, huber": ([1.5], "huber"), "wrong match, cauchy": ([1.5], "cauchy")}


@pytest.fixture(scope="module", params=list(CASES))
def captured(request):
    """The batch problem of a 3 s drive as ``run_graph`` hands it to its solver, and GTSAM's graph of it."""
    wrong, kernel = CASES[request.param]
    s = synthetic_streams(SyntheticOptions(duration=3.0, visual_scale=1.02, wrong_matches=wrong), seed=3)
    streams = SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)
    out = {}
    loop = chain.levenberg_marquardt

    def grab(problem, values, max_iterations=20, relative_tolerance=1e-3):
        out.update(problem=problem, values=values, settings=(max_iterations, relative_tolerance))
        return loop(problem, values, max_iterations, relative_tolerance)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(chain, "levenberg_marquardt", grab)
        fuse(streams, "gtsam", FusionConfig.from_dict({"graph": {"online": False, "robust": kernel}}))
    assert out, "the batch graph of the drive is not a chain"
    problem = out["problem"]
    full = gtsam.NonlinearFactorGraph(problem.graph)
    for group in problem.groups:
        for f in group.factors:
            full.add(f.custom_factor())
    out.update(full=full, case=request.param)
    return out


def _variables(problem, values) -> np.ndarray:
    """Every pose (x, y, yaw) and scalar variable (gyro biases, scales) of ``values``, in one vector."""
    poses = [values.atPose2(int(k)) for k in problem.pose_keys]
    return np.concatenate([np.array([[p.x(), p.y(), p.theta()] for p in poses]).ravel(),
                           [values.atDouble(int(k)) for k in problem.scalar_keys]])


def _gtsam_lm(full, values, max_iterations, tolerance):
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(tolerance)
    params.setAbsoluteErrorTol(0.0)
    optimizer = gtsam.LevenbergMarquardtOptimizer(full, values, params)
    return optimizer.optimize(), optimizer.iterations()


def _solve(problem, values, max_iterations, tolerance):
    solution, iterations, _ = chain.levenberg_marquardt(problem, values, max_iterations, tolerance)
    return solution, iterations


def _assert_equal(captured, ours, theirs):
    problem, full = captured["problem"], captured["full"]
    a, b = _variables(problem, ours), _variables(problem, theirs)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-8 * np.abs(b).max())
    assert full.error(ours) == pytest.approx(full.error(theirs), rel=1e-10)


def test_the_graph_is_small_and_has_every_kind_of_variable(captured):
    problem = captured["problem"]
    assert len(problem.pose_keys) == 61 and len(problem.scalar_keys) == 15
    assert problem.pose_keys[0] == X(0)
    assert {n for g in problem.groups for n in g.names} >= {"visual_scale", "wheel_scale", "gyro_bias"}


def test_same_steps_as_gtsam_with_the_run_settings(captured):
    """With the iteration limit and tolerance a run uses, the same iterations and the same solution."""
    problem, v0 = captured["problem"], captured["values"]
    max_iterations, tolerance = captured["settings"]
    ours, iterations = _solve(problem, v0, max_iterations, tolerance)
    theirs, gtsam_iterations = _gtsam_lm(captured["full"], v0, max_iterations, tolerance)
    assert iterations == gtsam_iterations >= 2
    _assert_equal(captured, ours, theirs)
    start = captured["full"].error(v0)
    assert captured["full"].error(theirs) < 0.8 * start  # the comparison is of solutions that moved


def test_same_minimum_as_gtsam_at_convergence(captured):
    problem, v0 = captured["problem"], captured["values"]
    ours, _ = _solve(problem, v0, 100, 1e-14)
    theirs, _ = _gtsam_lm(captured["full"], v0, 100, 1e-14)
    _assert_equal(captured, ours, theirs)


def test_robust_kernel_is_active_at_the_wrong_match(captured):
    """The wrong-match cases test the kernel: a factor is down-weighted at the solution."""
    problem = captured["problem"]
    ours, _ = _solve(problem, captured["values"], *captured["settings"])
    weights = []
    for g in problem.groups:
        if g.robust is not None:
            _, _, distance = g._whitened(ours)
            weights.append(robust_weight(distance, *g.robust))
    smallest = np.concatenate(weights).min()
    if captured["case"] == "clean":
        assert smallest > 0.5
    else:
        assert smallest < 0.2


def test_marginals_equal_gtsam_marginals_at_the_same_linearisation(captured):
    """The chain's marginal covariances (poses and scalars) are GTSAM's ``Marginals`` of the same linearisation."""
    problem = captured["problem"]
    _, _, system = chain.levenberg_marquardt(problem, captured["values"], *captured["settings"])
    point = system.point
    marginals = gtsam.Marginals(graph.gtsam_linearization(problem.graph, problem.groups, point), point)
    ours = chain.pose_marginals(system, list(problem.pose_keys))
    theirs = np.array([marginals.marginalCovariance(int(k)) for k in problem.pose_keys])
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9 * np.abs(theirs).max())
    ours = chain.pose_marginals(system, list(problem.scalar_keys), dim=1)[:, 0, 0]
    theirs = np.array([marginals.marginalCovariance(int(k))[0, 0] for k in problem.scalar_keys])
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)


def test_same_minimum_as_gtsam_from_far_off(captured):
    """From a start far off (headings up to 1.2 rad and positions up to 1 m wrong, every scale and bias 0.3 off),
    both loops reach the same minimum (their damping schedules differ: module docstring). Near the minimum a step
    can raise the cost by rounding alone, and then the damping grows; whether it does depends on the BLAS kernels
    (it did with OpenBLAS's SkylakeX ones, not with its Haswell ones), so the damping itself is held by
    :func:`test_damping_grows_until_a_step_lowers_the_cost`."""
    problem, v0 = captured["problem"], captured["values"]
    start = gtsam.Values(v0)
    for i, key in enumerate(problem.pose_keys):
        p = v0.atPose2(int(key))
        start.update(int(key), gtsam.Pose2(p.x() + 1.0 * np.cos(i / 3.0), p.y() - 0.7 * np.sin(i / 4.0),
                                           p.theta() + 1.2 * np.sin(i / 5.0)))
    for key in problem.scalar_keys:  # scales 30 % off, biases 0.3 rad/s
        start.update(int(key), v0.atDouble(int(key)) + 0.3)
    ours, _ = _solve(problem, start, 100, 1e-14)
    theirs, _ = _gtsam_lm(captured["full"], start, 100, 1e-14)
    _assert_equal(captured, ours, theirs)
    assert captured["full"].error(ours) < 1e-3 * captured["full"].error(start)


def test_damping_grows_until_a_step_lowers_the_cost(caplog):
    """The loop's damping on Rosenbrock's residuals ``r = (10 (y - x²), 1 - x)`` from ``(-1.2, 1)``, cost ``½|r|²``.

    There the Gauss–Newton step goes to ``(1, -3.84)``, where the cost is 1171.28 against 12.1 at the start, so the
    loop must reject it and raise the damping before it keeps a step; every kept step then lowers the cost and the
    loop reaches the minimum ``(1, 1)``. Fails if the loop keeps a step that raises the cost or gives up on a
    rejected one."""
    def residual(p):
        return np.array([10.0 * (p[1] - p[0] ** 2), 1.0 - p[0]])

    def cost(p):
        return 0.5 * float(residual(p) @ residual(p))

    def linearize(p):
        return np.array([[-20.0 * p[0], 10.0], [-1.0, 0.0]]), residual(p)

    def attempt(p, system, lam):
        J, r = system
        trial = p + np.linalg.solve(J.T @ J + lam * np.eye(2), -J.T @ r)
        return trial, cost(trial)

    start = np.array([-1.2, 1.0])
    J, r = linearize(start)
    assert cost(start + np.linalg.solve(J, -r)) == pytest.approx(1171.28)  # the undamped step raises the cost
    with caplog.at_level("DEBUG", logger="fusion_vo.backends.chain"):
        solution, iterations, _ = chain.damped_gauss_newton(start, cost(start), linearize, attempt, 200, 1e-15)
    steps = [tuple(float(g) for g in m.groups()) for rec in caplog.records
             if (m := re.search(r"cost (\S+) -> (\S+) \(lambda (\S+)\)", rec.getMessage()))]
    assert steps[0][2] > 0.0  # the first kept step needed the damping
    assert all(after <= before for before, after, _ in steps)
    np.testing.assert_allclose(solution, [1.0, 1.0], atol=1e-6)
