"""Accuracy figures of a visual track against ground truth, computed independently of evo.

The estimate starts at the identity at its first pose; it is anchored to the ground-truth pose at that
time (interpolated), and compared at its last pose.
"""

import numpy as np

from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData


def gt_at(gt: PoseData, t: float) -> np.ndarray:
    yaw = np.unwrap(gt.xyyaw[:, 2])
    return np.array([np.interp(t, gt.t, gt.xyyaw[:, 0]), np.interp(t, gt.t, gt.xyyaw[:, 1]),
                     float(se2.wrap_angle(np.interp(t, gt.t, yaw)))])


def anchored(track: PoseData, gt: PoseData) -> np.ndarray:
    start = gt_at(gt, track.t[0])
    first = track.xyyaw[0]
    return np.array([se2.compose(start, se2.between(first, p)) for p in track.xyyaw])


def path_length(gt: PoseData, t0: float, t1: float) -> float:
    m = (gt.t >= t0) & (gt.t <= t1)
    return float(np.sum(np.linalg.norm(np.diff(gt.xyyaw[m, :2], axis=0), axis=1)))


def end_errors(track: PoseData, gt: PoseData) -> tuple[float, float, float]:
    """(end-point error [m], end-point error [% of path], heading error [deg]) at the track's end."""
    est = anchored(track, gt)[-1]
    ref = gt_at(gt, track.t[-1])
    err = float(np.linalg.norm(est[:2] - ref[:2]))
    length = path_length(gt, track.t[0], track.t[-1])
    heading = float(np.degrees(abs(se2.wrap_angle(est[2] - ref[2]))))
    return err, 100.0 * err / max(length, 1e-9), heading
