"""GPS as a reference: scoring against fixes, and the world alignment, checked on a generated recording.

On the standard ``gps_outage`` recording (60 s random drive, GPS at 5 Hz with 5 cm noise, a 10 s outage
and a 20 m multipath jump of 6 fixes) the script

1. runs ``fusion-vo run`` (camera, wheels, IMU; every backend; GPS is not fused) and prints each
   trajectory's ATE against the ground truth;
2. scores the same trajectories against the GPS fixes as ``fusion-vo evaluate`` does for a recording
   without ground truth (a copy of the recording without ``state_groundtruth_estimate0/``): RMS over
   every fix, RMS without outliers, median, outliers. A perfect track scores the fixes' own noise:
   RMS ``sqrt(2) σ`` = 0.071 m, median ``1.1774 σ`` = 0.059 m;
3. estimates the world frame's heading in ENU (true: 30°) from the first 5, 10, 20 and 60 s of fixes
   with :func:`fusion_vo.sensors.gps.align_to_fixes`, from each dead-reckoned track.

Usage::

    python benchmarks/gps_scoring.py [--out DIR]
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import numpy as np

from fusion_vo.config import RunConfig
from fusion_vo.evaluation import evaluate_run
from fusion_vo.evaluation.io import read_tum
from fusion_vo.geometry import se2
from fusion_vo.pipeline import run_pipeline
from fusion_vo.recording import Recording
from fusion_vo.sensors.gps import align_to_fixes
from fusion_vo.simulation.standard import make_standard


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="keep the recording and the runs here (default: a temporary folder)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="gps-scoring-") as tmp:
        root = Path(args.out or tmp)
        seq = root / "gps_outage"
        if not (seq / "simulation.yaml").is_file():
            make_standard("gps_outage", seq)
        run = root / "run"
        summary = run_pipeline(seq, run, RunConfig(backend="all"))
        truth = summary.metrics
        no_gt = root / "gps_outage_without_groundtruth"
        no_gt.mkdir(exist_ok=True)
        for folder in ("cam0", "imu0", "wheel0", "gps0"):
            link = no_gt / folder
            if not link.exists():
                link.symlink_to((seq / folder).resolve())
        against_gps = evaluate_run(run, no_gt)

        print("trajectory      ATE vs truth [m]   vs GPS: RMS [m]  RMS inliers [m]  median [m]  outliers / fixes")
        for name, g in against_gps.items():
            print(f"{name:<14} {truth[name]['ate_m']:>17.4f} {g['gps_rms_m']:>17.3f} {g['gps_rms_inliers_m']:>16.3f} "
                  f"{g['gps_median_m']:>11.3f} {g['gps_outliers']:>9d} / {g['gps_fixes']}")

        gps = Recording(seq).gps()
        print("\nheading of the world frame in ENU from the first fixes (true 30 deg): error [deg] (1-sigma)")
        spans = (5.0, 10.0, 20.0, 60.0)
        print("trajectory    " + "".join(f"{f'{s:.0f} s':>20}" for s in spans))
        for name in against_gps:
            traj = read_tum(run / f"{name}.tum")
            t = np.asarray(traj.timestamps)
            xyyaw = np.column_stack([traj.positions_xyz[:, :2], se2.yaw_of_quaternion(traj.orientations_quat_wxyz)])
            cells = []
            for span in spans:
                fit = align_to_fixes(t, xyyaw, gps, t[0] + span)
                cells.append("not observable" if fit is None else
                             f"{math.degrees(fit.yaw) - 30.0:+.2f} ({math.degrees(fit.yaw_sigma):.2f})")
            print(f"{name:<14}" + "".join(f"{c:>20}" for c in cells))


if __name__ == "__main__":
    main()
