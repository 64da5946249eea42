"""iSAM2 and the EKF are causal estimates of one model: on a generated drive they score alike."""

import pytest

from fusion_vo import backends
from fusion_vo.evaluation.metrics import align_se2, ape_rmse, associate, planar_trajectory
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.simulation.generate import simulate


@pytest.fixture(scope="module")
def square_101(tmp_path_factory):
    """The standard ``square`` drive (camera, wheels, gyro) with seed 101, fused by every backend: ATE [mm]."""
    rec = Recording(simulate(tmp_path_factory.mktemp("square") / "rec", profile="square", seed=101))
    result = backends.run_backends(rec, run_visual_odometry(rec, OdometryConfig()), backend="all")
    gt = rec.groundtruth()
    reference = planar_trajectory(gt.t, gt.xyyaw[:, 0], gt.xyyaw[:, 1], gt.xyyaw[:, 2])
    ate = {}
    for name, track in result.trajectories.items():
        ref, est = associate(reference, planar_trajectory(track.t, *track.xyyaw.T))
        ate[name] = ape_rmse(ref, align_se2(ref, est)) * 1e3
    return ate


def test_isam2_scores_as_the_ekf_on_a_generated_square(square_101):
    """iSAM2 within 3 % of the EKF (measured: 0.1019 mm against 0.1021 mm). It was 25 % worse (0.1275 mm)
    while the graph dropped the camera's correlations (every entry of its covariance below GTSAM's 1e-9 test
    for a diagonal one; 8 % worse once they are kept) and weighed the camera at the wheels' prediction (16 %
    worse once it is weighed at the updated estimate)."""
    assert square_101["gtsam_online"] <= 1.03 * square_101["ekf"]


def test_batch_scores_as_the_rts_smoother_on_a_generated_square(square_101):
    """GTSAM batch within 3 % of the RTS-smoothed EKF, the same model smoothed (measured: 0.1025 mm against
    0.1032 mm; 0.1142 mm, 11 % worse, while the graph dropped the camera's correlations)."""
    assert square_101["gtsam"] <= 1.03 * square_101["ekf_smoothed"]
