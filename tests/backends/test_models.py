"""Jacobians of the EKF motion model and of the graph's sensor-model factors against finite differences;
the graph's grouped linearisation equals GTSAM's own (CustomFactor, robust noise models), and the native
GTSAM factors the graph keeps equal the models where it uses them."""

import gtsam
import numpy as np
import pytest

from fusion_vo.backends import FusionConfig
from fusion_vo.backends.ekf import PlanarEkf
from fusion_vo.backends.factors import POSE_LETTERS, ModelFactor, ModelFactors, covariance_noise, group, pose_table
from fusion_vo.backends.graph_adapter import pose_factor
from fusion_vo.backends.graph_builder import T_WS, X
from fusion_vo.sensors import gps
from fusion_vo.sensors.imu import AHRS, GYRO
from fusion_vo.sensors.visual import VISUAL
from fusion_vo.sensors.wheel import STANDSTILL, WHEEL


# the variables of the states, by their letters (the sensors' declarations: fusion_vo.sensors.registry.State)
def B(k):
    return gtsam.symbol("b", k)


def O(k):  # noqa: E743
    return gtsam.symbol("o", k)


def S(k):
    return gtsam.symbol("s", k)


def W(k):
    return gtsam.symbol("w", k)


def R(k):
    return gtsam.symbol("r", k)


EKF = PlanarEkf(FusionConfig())
DIM = EKF.dim


def _state(pose_twist, **states):
    """A state vector of the default filter: the pose and twist, then its scalar states by name (others 0)."""
    x = np.zeros(DIM)
    x[:6] = pose_twist
    for name, value in states.items():
        x[EKF.columns[name]] = value
    return x


def _predict(x, dt):
    ekf = PlanarEkf(FusionConfig())
    ekf.kf.x = np.asarray(x, dtype=float).reshape(DIM, 1)
    F = ekf.predict(dt)
    return ekf.x.copy(), F


def test_the_default_filter_carries_the_built_in_states_after_pose_and_twist():
    assert DIM == 11
    assert {EKF.columns[n].start for n in ("visual_scale", "wheel_base_factor", "wheel_scale", "gyro_bias",
                                           "ahrs_offset")} == set(range(6, 11))


X0 = _state([0.3, -0.2, 0.7, 0.4, 0.02, 0.8], gyro_bias=0.01, visual_scale=1.02, wheel_base_factor=0.99,
            ahrs_offset=0.05, wheel_scale=0.98)


def test_ekf_transition_jacobian():
    x = X0
    _, F = _predict(x, 0.05)
    eps = 1e-7
    num = np.zeros((DIM, DIM))
    for i in range(DIM):
        d = np.zeros(DIM)
        d[i] = eps
        num[:, i] = (_predict(x + d, 0.05)[0] - _predict(x - d, 0.05)[0]) / (2 * eps)
    np.testing.assert_allclose(F, num, atol=1e-7)


def test_ekf_wheel_block_jacobian_includes_the_wheel_scale():
    x0 = X0

    def block(x):
        ekf = PlanarEkf(FusionConfig())
        ekf.kf.x = np.asarray(x, dtype=float).reshape(DIM, 1)
        return ekf.block(WHEEL, np.zeros(3), np.eye(3))

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
    x = _state([0, 0, 0, 1.0, 0, np.pi / 2], visual_scale=1.0, wheel_base_factor=1.0)  # quarter circle, radius 2/π
    pred, _ = _predict(x, 1.0)
    np.testing.assert_allclose(pred[:3], [2 / np.pi, 2 / np.pi, np.pi / 2], atol=1e-12)


def _numeric_jacobians(factor, values, keys):
    out = []
    base = values
    for key in keys:
        is_pose = chr(gtsam.Symbol(key).chr()) in POSE_LETTERS
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
    v.insert(B(0), 0.012)
    v.insert(O(0), -0.1)
    return v


COV3 = np.array([[1e-4, 2e-5, 0.0], [2e-5, 2e-4, 1e-6], [0.0, 1e-6, 1e-5]])
NEAR_DIAGONAL = np.array([[7.6e-7, -8.4e-10, 0.0], [-8.4e-10, 3.9e-7, 0.0], [0.0, 0.0, 1e2]])


def _factors(robust=("huber", 1.345)):
    motion = {"motion": (X(0), X(1))}
    return [
        ModelFactor(VISUAL, np.array([0.05, 0.03, 0.06]), {**motion, "visual_scale": (S(0),)}, COV3, robust=robust),
        ModelFactor(VISUAL, np.array([0.09, 0.03, 0.06]), {**motion, "visual_scale": (S(0),)}, COV3, robust=robust),
        ModelFactor(WHEEL, np.array([0.05, 0.02, 0.0]), {**motion, "wheel_scale": (S(0),)}, NEAR_DIAGONAL,
                    fixed={"wheel_base_factor": 1.0}, robust=robust),
        ModelFactor(WHEEL, np.array([0.0, 0.0, 0.068]), {**motion, "wheel_base_factor": (W(0),)}, np.array([[1e-4]]),
                    fixed={"wheel_scale": 1.0}, rows=(2,), robust=robust),
        ModelFactor(GYRO, np.array([0.08]), {**motion, "gyro_bias": (B(0),)}, np.array([[1e-6]]), params={"dt": 0.05}),
        ModelFactor(STANDSTILL, np.zeros(1), {**motion}, np.array([[1e-6]])),
        ModelFactor(AHRS, np.array([0.35]), {"heading": (X(1),), "ahrs_offset": (O(0),)}, np.array([[4e-4]]), robust=robust),
    ]


def test_model_factor_jacobians_match_finite_differences():
    v = _values()
    for f in _factors(robust=None):
        factor = f.custom_factor()
        A = factor.linearize(v).jacobian()[0]
        # undo the noise model's whitening to compare with the unwhitened error
        R = covariance_noise(f.covariance).R()
        num = np.hstack(_numeric_jacobians(factor, v, list(factor.keys())))
        np.testing.assert_allclose(np.linalg.solve(R, A), num, atol=1e-6, err_msg=f.model.name)


@pytest.mark.parametrize("robust", [None, ("huber", 1.345), ("cauchy", 0.5)])
def test_grouped_linearisation_equals_gtsams_custom_factor(robust):
    """Error, information and gradient of each factor as GTSAM computes them for a CustomFactor with the same
    (robust) noise model, including a covariance of small entries whose correlation GTSAM's default noise
    model would drop (``NEAR_DIAGONAL``)."""
    v = _values()
    for values in (v, _moved(v)):
        factors = _factors(robust)
        groups = group(factors)
        assert sum(len(g) for g in groups) == len(factors) and len(groups) == 6
        for g in groups:
            for f, mine in zip(g.factors, g.linearize(values)):
                theirs = f.custom_factor().linearize(values)
                A1, b1 = theirs.jacobian()
                A2, b2 = mine.jacobian()
                scale = np.abs(A1.T @ A1).max()
                np.testing.assert_allclose(A2.T @ A2, A1.T @ A1, atol=1e-12 * scale, err_msg=f.model.name)
                np.testing.assert_allclose(A2.T @ b2, A1.T @ b1, atol=1e-12 * np.sqrt(scale))
            expected = sum(f.custom_factor().error(values) for f in g.factors)
            assert np.isclose(g.error(values), expected, rtol=1e-12, atol=1e-300), g.model.name


def _moved(v):
    delta = gtsam.VectorValues()
    delta.insert(X(1), np.array([0.01, -0.02, 0.03]))
    return v.retract(delta)


def test_frozen_model_factor_is_gtsams_linearisation():
    """What the incremental solvers receive equals GTSAM's linearisation of the CustomFactor."""
    v = _values()
    for f in _factors():
        frozen = f.linearized(lambda k: v.atPose2(k) if chr(gtsam.Symbol(k).chr()) == "x" else v.atDouble(k))
        theirs = gtsam.LinearContainerFactor(f.custom_factor().linearize(v), v)
        assert np.isclose(frozen.error(_moved(v)), theirs.error(_moved(v)), rtol=1e-10), f.model.name


@pytest.mark.parametrize("kernel", ["none", "cauchy"])
def test_fix_on_the_world_frame_and_a_pose_is_the_gps_model_of_their_composition(kernel):
    """A fix on ``T_WS X`` (streaming iSAM2 with GPS): its error is the GPS model's residual at the composed pose (lever
    arm included), its Jacobians in T's and X's tangent spaces match finite differences, and the frozen and grouped
    linearisations equal GTSAM's of the same CustomFactor."""
    v = gtsam.Values()
    v.insert(T_WS(), gtsam.Pose2(5.0, -3.0, 0.7))
    v.insert(X(3), gtsam.Pose2(1.2, 0.4, -2.9))
    lever = np.array([-0.3, 0.2])
    z = np.array([6.4, -1.6])
    f = pose_factor(gps.ANTENNA, z, np.diag([0.04, 0.09]), (T_WS(), X(3)), {"lever_arm": lever},
                    gps.GpsNoise(kernel=kernel))
    factor = f.custom_factor()
    world = v.atPose2(T_WS()).compose(v.atPose2(X(3)))
    expected = gps.predict(np.array([world.x(), world.y(), world.theta()]), lever) - z
    np.testing.assert_allclose(factor.unwhitenedError(v), expected, atol=1e-12)
    if kernel == "none":
        A = factor.linearize(v).jacobian()[0]
        num = np.hstack(_numeric_jacobians(factor, v, [T_WS(), X(3)]))
        np.testing.assert_allclose(np.linalg.solve(covariance_noise(f.covariance).R(), A), num, atol=1e-6)
    frozen = f.linearized(lambda k: v.atPose2(k))
    theirs = gtsam.LinearContainerFactor(factor.linearize(v), v)
    moved = v.retract(_delta({T_WS(): [0.02, -0.01, 0.01], X(3): [0.01, 0.03, -0.02]}))
    assert np.isclose(frozen.error(moved), theirs.error(moved), rtol=1e-10)
    (mine,) = ModelFactors([f]).linearize(v)
    A1, b1 = theirs.linearize(v).jacobian()
    A2, b2 = mine.jacobian()
    np.testing.assert_allclose(A2.T @ A2, A1.T @ A1, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(A2.T @ b2, A1.T @ b1, rtol=1e-10, atol=1e-12)


def _delta(steps: dict) -> gtsam.VectorValues:
    delta = gtsam.VectorValues()
    for key, d in steps.items():
        delta.insert(key, np.asarray(d, dtype=float))
    return delta


def test_gyro_factor_is_exact_away_from_its_linearisation_point():
    """The gyro's factor is linear in the headings and the bias: linearised anywhere, it is exact (across ±π)."""
    lin = {X(0): gtsam.Pose2(0, 0, 3.1), X(1): gtsam.Pose2(1, 0, -3.1), B(0): 0.0}
    f = ModelFactor(GYRO, np.array([0.1]), {"motion": (X(0), X(1)), "gyro_bias": (B(0),)}, np.array([[1e-4]]),
                    params={"dt": 0.05})
    frozen = f.linearized(lin.__getitem__)
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose2(0.3, 0.1, 3.0))
    v.insert(X(1), gtsam.Pose2(1.2, 0.0, -3.0))
    v.insert(B(0), 0.2)
    # d_ψ wraps across ±π: (-3.0 - 3.0) + 2π; error = d_ψ + b Δt - Θ
    e = (-3.0 - 3.0 + 2 * np.pi) + 0.05 * 0.2 - 0.1
    assert np.isclose(frozen.error(v), 0.5 * (e / 0.01) ** 2)
    assert np.isclose(ModelFactors([f]).error(v), 0.5 * (e / 0.01) ** 2)


def test_native_factors_the_graph_keeps_equal_the_models():
    """Where GTSAM has a factor the graph uses it. A heading-only PriorFactorPose2 is the AHRS model with its
    offset fixed at zero. BetweenFactorPose2 (wheels or camera without calibration) is the wheel model with
    ``k_r = k_b = 1`` whose noise is expressed in the frame at the end of the measured increment ``z``
    (GTSAM's tangent space): its error and Jacobians are the model's rotated by ``R(-z_ψ)``, the error to
    second order in the residual, the Jacobians to first order."""
    v = _values()
    pose = v.atPose2(X(1))
    prior = gtsam.PriorFactorPose2(X(1), gtsam.Pose2(0.0, 0.0, 0.4), gtsam.noiseModel.Diagonal.Sigmas([1e3, 1e3, 0.02]))
    ahrs = ModelFactor(AHRS, np.array([0.4]), {"heading": (X(1),)}, np.array([[0.02**2]]), fixed={"ahrs_offset": 0.0})
    e_model, blocks = ModelFactors([ahrs]).evaluate(v)
    assert np.isclose(prior.unwhitenedError(v)[2], e_model[0, 0])
    A = prior.linearize(v).jacobian()[0]
    np.testing.assert_allclose(A[2] * 0.02, blocks[0][0, 0], atol=1e-12)
    rel = gtsam.Pose2(0.2, -0.1, 0.4).between(pose)
    for z in (np.array([rel.x(), rel.y(), rel.theta()]), np.array([rel.x() + 1e-4, rel.y() - 2e-4, rel.theta() + 1e-4])):
        between = gtsam.BetweenFactorPose2(X(0), X(1), gtsam.Pose2(*z), gtsam.noiseModel.Unit.Create(3))
        wheel = ModelFactor(WHEEL, z, {"motion": (X(0), X(1))}, np.eye(3),
                            fixed={"wheel_scale": 1.0, "wheel_base_factor": 1.0})
        e_model, blocks = ModelFactors([wheel]).evaluate(v)
        c, s = np.cos(z[2]), np.sin(z[2])
        rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        size = np.abs(e_model).max()
        assert np.abs(between.unwhitenedError(v) - rot @ e_model[0]).max() <= 10 * size**2 + 1e-15
        A = between.linearize(v).jacobian()[0]
        np.testing.assert_allclose(A, rot @ np.concatenate(blocks, axis=2)[0], atol=1e-12 if size < 1e-12 else 10 * size)
        if size > 0:  # and they do differ: the rotation matters
            assert np.abs(A - np.concatenate(blocks, axis=2)[0]).max() > 0.01


def test_whole_wheel_arc_of_four_variables():
    """The wheels' whole arc with its radius and wheel-base factors (two poses and two scalars, a covariance that
    correlates the distance and the heading change, as one wheel's slip does): the batch's linearisation (a
    HessianFactor) and the incremental solvers' frozen one (a JacobianFactor) are GTSAM's linearisation of the
    same CustomFactor."""
    v = _values()
    v.insert(R(0), 1.002)
    cov = np.array([[4e-7, 0.0, 2e-7], [0.0, 3e-7, 1e-7], [2e-7, 1e-7, 2e-6]])
    f = ModelFactor(WHEEL, np.array([0.05, 0.02, 0.07]),
                    {"motion": (X(0), X(1)), "wheel_scale": (R(0),), "wheel_base_factor": (W(0),)}, cov,
                    robust=("huber", 3.0))
    rng = np.random.default_rng(1)
    for values in (v, _moved(v)):
        theirs = f.custom_factor().linearize(values)
        mine = ModelFactors([f]).linearize(values)[0]
        for _ in range(5):
            delta = gtsam.VectorValues()
            for key in f.all_keys():
                delta.insert(key, rng.normal(size=3 if chr(gtsam.Symbol(key).chr()) == "x" else 1) * 1e-3)
            assert np.isclose(mine.error(delta), theirs.error(delta), rtol=1e-9)
    lookup = lambda k: v.atPose2(k) if chr(gtsam.Symbol(k).chr()) == "x" else v.atDouble(k)  # noqa: E731
    frozen = f.linearized(lookup)
    theirs = gtsam.LinearContainerFactor(f.custom_factor().linearize(v), v)
    assert np.isclose(frozen.error(_moved(v)), theirs.error(_moved(v)), rtol=1e-8)


@pytest.mark.parametrize("curvature", [True, False])
def test_graph_takes_the_wheels_whole_arc_as_the_ekf_does(curvature):
    """With the radius and wheel-base factors estimated, each wheel interval is one factor of the whole arc and its
    covariance (the EKF's measurement), not a translation and an independent heading change: their
    correlation is what lets a heading known from the gyro correct the wheels' distance. With the curvature
    bias (the default) the whole arc is the curved model's."""
    from fusion_vo.backends import SensorStreams
    from fusion_vo.backends.graph_builder import GraphBuilder
    from fusion_vo.backends.timeline import build_intervals
    from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams
    from fusion_vo.sensors.wheel import CURVED_WHEEL

    s = synthetic_streams(SyntheticOptions(duration=2.0), seed=4)
    config = FusionConfig.from_dict({"wheel": {"estimate_curvature": curvature}})
    iv = build_intervals(SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height), config)
    builder = GraphBuilder(iv, config)
    assert {"wheel_scale", "wheel_base_factor"} <= {st.name for st in builder.variables}
    nf = builder.node(5, gtsam.Pose2())
    model = CURVED_WHEEL if curvature else WHEEL
    wheel = [f for f in nf.factors if isinstance(f, ModelFactor) and f.model.name == "wheel"]
    assert len(wheel) == 1
    f = wheel[0]
    expected = {"motion", "wheel_scale", "wheel_base_factor"} | ({"wheel_curvature"} if curvature else set())
    assert f.model is model and f.rows is None and f.covariance.shape == (3, 3) and set(f.keys) == expected
    assert abs(f.covariance[0, 2]) > 0 or abs(f.covariance[1, 2]) > 0


#: a visual increment's covariance of the generated drives: σ 20 µm and 20 µrad (the frontend's floors), its lateral
#: and heading errors correlated by -0.145; every entry is below GTSAM's 1e-9 test for a diagonal covariance
SMALL_CORRELATED = np.array([[4e-10, 0.0, 0.0], [0.0, 4e-10, -5.8e-11], [0.0, -5.8e-11, 4e-10]])


def test_small_covariance_keeps_its_correlation_in_every_factor():
    """The graph weighs a measurement by its whole covariance, however small its entries: the frozen factor of
    the incremental solvers, the grouped factors of the batch solution, the CustomFactor and the noise model
    of GTSAM's own factors all have the information ``Σ⁻¹`` (GTSAM's default noise model would make it
    diagonal)."""
    info = np.linalg.inv(SMALL_CORRELATED)
    assert abs(info[1, 2]) > 0.1 * info[1, 1]
    np.testing.assert_allclose(covariance_noise(SMALL_CORRELATED).R().T @ covariance_noise(SMALL_CORRELATED).R(),
                               info, rtol=1e-9)
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose2(0.0, 0.0, 0.0))
    v.insert(X(1), gtsam.Pose2(0.01, 0.0, 0.0))  # at the measured increment: ∂h/∂ξ_1 is the identity
    f = ModelFactor(VISUAL, np.array([0.01, 0.0, 0.0]), {"motion": (X(0), X(1))}, SMALL_CORRELATED,
                    fixed={"visual_scale": 1.0})
    frozen = f.linearized(lambda k: v.atPose2(k)).linearize(v)
    grouped = ModelFactors([f]).linearize(v, pose_table(v))[0]
    custom = f.custom_factor().linearize(v)
    for linear in (frozen, grouped, custom):
        A = linear.jacobian()[0][:, 3:]  # the block of X(1)
        np.testing.assert_allclose(A.T @ A, info, rtol=1e-9)


def test_graph_moves_the_translation_with_the_heading_by_the_stated_correlation():
    """A heading the gyro corrects moves the camera's translation by ``Σ_yψ / Σ_ψψ`` times the correction, as in
    the EKF's update (GTSAM's own BetweenFactorPose2 with the graph's noise model)."""
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 1e-9)))
    g.add(gtsam.BetweenFactorPose2(X(0), X(1), gtsam.Pose2(0.01, 0.0, 0.0), covariance_noise(SMALL_CORRELATED)))
    g.add(gtsam.PriorFactorPose2(X(1), gtsam.Pose2(0.0, 0.0, 1e-5), gtsam.noiseModel.Diagonal.Sigmas(np.array([1e3, 1e3, 1e-7]))))
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose2())
    v.insert(X(1), gtsam.Pose2(0.01, 0.0, 0.0))
    p = gtsam.LevenbergMarquardtOptimizer(g, v).optimize().atPose2(X(1))
    np.testing.assert_allclose(p.y(), SMALL_CORRELATED[1, 2] / SMALL_CORRELATED[2, 2] * p.theta(), rtol=1e-3)
    assert abs(p.y()) > 1e-6
