"""iSAM2's robust weights at the updated estimate (:func:`fusion_vo.backends.isam.update_reweighted`)."""

import gtsam
import numpy as np

from fusion_vo.backends import FusionConfig
from fusion_vo.backends.factors import ModelFactor
from fusion_vo.backends.graph_builder import X, kernel_width
from fusion_vo.backends.isam import freeze_custom_factors, isam_params, update_reweighted
from fusion_vo.sensors.visual import VISUAL
from fusion_vo.sensors.wheel import WHEEL

PREDICTED = gtsam.Pose2(0.015, 0.0, 0.0)  # the wheels' increment, from which X1 is predicted


def _factors(camera_x: float, camera_sigma: float, wheel_sigma: float) -> list:
    """Ending at X1: a camera increment ``camera_x`` forward and a wheel increment of 15 mm, each with the
    given standard deviation in every component, both in the gate-wide Huber kernel."""
    kernel = ("huber", kernel_width(FusionConfig(), 3))
    motion = {"motion": (X(0), X(1))}
    camera = ModelFactor(VISUAL, np.array([camera_x, 0.0, 0.0]), motion, np.eye(3) * camera_sigma**2,
                         fixed={"visual_scale": 1.0}, robust=kernel)
    wheels = ModelFactor(WHEEL, np.array([PREDICTED.x(), 0.0, 0.0]), motion, np.eye(3) * wheel_sigma**2,
                         fixed={"wheel_scale": 1.0, "wheel_base_factor": 1.0}, robust=kernel)
    return [camera, wheels]


def _prior():
    return gtsam.PriorFactorPose2(X(0), gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 1e-9))


def _isam(factors: list, passes: int):
    """iSAM2's estimate of X1 after the node's update (``passes`` reweighting passes), the weights its
    factors entered with (at the prediction) and the passes made."""
    isam = gtsam.ISAM2(isam_params())
    first = gtsam.NonlinearFactorGraph()
    first.add(_prior())
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2())
    isam.update(first, values)
    values = gtsam.Values()
    values.insert(X(1), PREDICTED)
    weights = []
    graph = gtsam.NonlinearFactorGraph()
    for f in freeze_custom_factors(factors, {X(0): gtsam.Pose2(), X(1): PREDICTED}.__getitem__, weights=weights):
        graph.add(f)
    _, made = update_reweighted(isam, graph, values, factors, weights, passes=passes)
    return isam.calculateEstimatePose2(X(1)), weights, made


def _batch(factors: list) -> gtsam.Pose2:
    """Levenberg–Marquardt on the same factors (GTSAM's robust noise models, reweighted at every iteration)."""
    graph = gtsam.NonlinearFactorGraph()
    graph.add(_prior())
    for f in factors:
        graph.add(f.custom_factor())
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2())
    values.insert(X(1), PREDICTED)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-30)
    params.setMaxIterations(200)
    return gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize().atPose2(X(1))


def test_isam2_weighs_the_camera_where_the_update_puts_the_node():
    """A camera increment (σ 20 µm) 5 mm short of the wheels' (σ 5 mm, one of theirs): at the wheels'
    prediction the camera's residual, 250 of its σ, is far beyond the kernel and its weight small; the update
    puts the node within a fraction of the camera's σ of it, where its weight is 1. After one more pass
    iSAM2's estimate is the batch solution of the same factors, which the single update at the prediction's
    weights misses by 5 µm, a quarter of the camera's σ."""
    factors = _factors(0.010, 20e-6, 5e-3)
    once, weights, made = _isam(factors, passes=0)
    assert weights[0] < 0.05 and weights[1] == 1.0
    assert made == 0
    reweighted, _, made = _isam(factors, passes=2)
    assert made == 1  # the weights at its result are the ones it used: no second pass
    batch = _batch(factors)
    assert abs(batch.x() - 0.010) < 1e-7
    assert abs(reweighted.x() - batch.x()) < 1e-9
    assert abs(once.x() - batch.x()) > 3e-6


def test_a_measurement_still_beyond_the_kernel_at_the_update_keeps_its_small_weight():
    """A camera increment 5 cm off (a wrong match, σ 1 mm) beside precise wheels (σ 0.5 mm): the batch
    solution bounds its pull, and iSAM2, reweighted at its update, gives the same estimate with the camera
    still far beyond the kernel, not at full weight."""
    factors = _factors(0.065, 1e-3, 0.5e-3)
    reweighted, weights, _ = _isam(factors, passes=2)
    batch = _batch(factors)
    assert abs(batch.x() - PREDICTED.x()) < 2e-3
    assert abs(reweighted.x() - batch.x()) < 1e-6
    assert factors[0].weight(lambda k: gtsam.Pose2() if k == X(0) else reweighted) < 0.1
