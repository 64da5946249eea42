"""iSAM2 and the EKF are causal estimates of one model: on a generated drive they score alike."""

import pytest

from square_scores_job import scores

#: the drive rendered and fused in the session's second process (tests/background.py)
BACKGROUND_COMMANDS = {"python:square_101": ["{repo}/tests/backends/square_scores_job.py", "{out}"]}
BACKGROUND_JOBS = {"*": ["python:square_101"]}


@pytest.fixture(scope="module")
def square_101(ahead_json, tmp_path_factory):
    """The standard ``square`` drive (camera, wheels, gyro) with seed 101, fused by every backend: ATE [mm]."""
    return ahead_json("python:square_101", lambda: scores(tmp_path_factory.mktemp("square")))


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
