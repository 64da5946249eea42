"""Monte-Carlo consistency of the fused covariances (NEES) and of each sensor's noise model (NIS).

Each of ``--seeds`` seeds generates a ``--duration`` drive with known sensor noise (camera increments, wheel
encoders, gyro; no images, so a seed takes a fraction of a second) and calibration errors drawn from the
priors the backends are given, fuses it with every backend and compares every fused pose with the truth
(``fusion_vo.evaluation.consistency``, whose docstring states the statistics). Printed per backend: the NEES of
(x, y, yaw) averaged over the seeds and the poses (the first second skipped), its median, the share of times
at which the seed-average lies inside the 95 % band of a consistent estimator (3 in expectation), and the
verdict; then per sensor and backend the same for the NIS, against its own degrees of freedom (camera and
wheels 3, gyro 1). The baseline is the chi-square band itself: where a consistent estimator's average lies.

``--config`` and ``--set`` change the backends' configuration (its ``fusion`` section), e.g. ``--set
fusion.visual_frame_error=0.5`` (a correlation the drives do not have: every backend should come out
overconfident) or ``--set fusion.ekf.visual_scale_random_walk=1e-4``.

Usage::

    python benchmarks/consistency.py [--seeds 25] [--duration 30] [--config FILE] [--set KEY=VALUE ...]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from common import add_settings, describe_settings, fusion_settings, parser, table

from fusion_vo.backends import FusionConfig
from fusion_vo.evaluation.consistency import NIS_BACKENDS, band, run, verdict


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--seeds", type=int, default=25)
    ap.add_argument("--duration", type=float, default=30.0, help="length of each drive [s]")
    add_settings(ap)
    args = ap.parse_args(argv)
    if args.seeds < 1 or args.duration < 3.0:
        ap.error("--seeds must be at least 1 and --duration at least 3 s")
    t0 = time.process_time()
    nis: dict = {}
    nees = run(args.seeds, args.duration, config=FusionConfig.from_dict(fusion_settings(args)), nis=nis)
    n = args.seeds
    lo, hi = band(3, n)
    print(f"NEES of (x, y, yaw), {n} seeds of a {args.duration:.0f} s generated drive (camera, wheels, gyro), "
          f"{describe_settings(args)}, {time.process_time() - t0:.1f} s CPU")
    print(f"consistent: 3; 95 % band of a {n}-seed average: [{lo:.2f}, {hi:.2f}]")
    rows = []
    for name, v in nees.items():
        avg = np.nanmean(v, axis=0)
        mean = float(np.nanmean(avg))
        rows.append([name, f"{mean:.2f}", f"{float(np.nanmedian(avg)):.2f}",
                     f"{100 * float(np.mean((avg >= lo) & (avg <= hi))):.0f} %", verdict(mean, lo, hi)])
    print(table(["backend", "mean NEES", "median", "times inside the band", "verdict"], rows))
    print("\nNIS per sensor, seed-average against its 95 % band (EKF: each block against the prediction updated with "
          "the other sensors; GTSAM batch and iSAM2: each sensor's residual at the solution, r'(R - HPH')^-1 r)")
    rows = []
    for sensor in sorted({sensor for t in nis.values() for sensor in t}):
        for backend in NIS_BACKENDS:
            if sensor not in nis.get(backend, {}):
                continue
            dof, v = nis[backend][sensor]
            avg = np.nanmean(v, axis=0)
            mean = float(np.nanmean(avg))
            s_lo, s_hi = band(dof, n)
            rows.append([sensor, backend, dof, f"{mean:.2f}", f"{float(np.nanmedian(avg)):.2f}",
                         f"{100 * float(np.mean((avg >= s_lo) & (avg <= s_hi))):.0f} %", f"[{s_lo:.2f}, {s_hi:.2f}]",
                         verdict(mean, s_lo, s_hi)])
    print(table(["sensor", "backend", "dof", "mean NIS", "median", "times inside the band", "band", "verdict"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
