"""The standard ``square`` drive (camera, wheels, gyro) with seed 101, fused by every backend.

``python tests/backends/square_scores_job.py OUT`` renders the drive into the folder ``OUT`` and prints, as JSON, each
track's ATE [mm] after the SE(2) alignment, what ``test_online_vs_ekf.py`` checks. The session's second process runs
it ahead (tests/background.py); a test run without that process calls :func:`scores` itself.
"""

import json
import sys
from pathlib import Path

from fusion_vo import backends
from fusion_vo.evaluation.metrics import align_se2, ape_rmse, associate, planar_trajectory
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.simulation.generate import simulate


def scores(out) -> dict:
    """ATE [mm] of every track of the drive rendered into ``out``."""
    rec = Recording(simulate(Path(out) / "rec", profile="square", seed=101))
    result = backends.run_backends(rec, run_visual_odometry(rec, OdometryConfig()), backend="all")
    gt = rec.groundtruth()
    reference = planar_trajectory(gt.t, gt.xyyaw[:, 0], gt.xyyaw[:, 1], gt.xyyaw[:, 2])
    ate = {}
    for name, track in result.trajectories.items():
        ref, est = associate(reference, planar_trajectory(track.t, *track.xyyaw.T))
        ate[name] = ape_rmse(ref, align_se2(ref, est)) * 1e3
    return ate


if __name__ == "__main__":
    print(json.dumps(scores(sys.argv[1])))
