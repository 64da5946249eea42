"""Fused tracks with the camera's heading noise calibrated on other drives, beside the default and visual odometry.

For each standard generated recording named (default: square, circle, random60, gps_outage, tilted, short),
this generates two calibration drives of the same profile and options with other seeds (``seed + 1000 i``),
measures the KLT frontend's heading noise on them (:func:`fusion_vo.calibration.camera_noise_drive.calibrate`, what
``fusion-vo calibrate camera-noise`` does), and then, on the recording itself and on ``--seeds`` more of its
seeds (``seed + 100 i``, as ``fusion.py --seeds`` uses), runs visual odometry once (default
configuration) and fuses its increments (all sensors but GPS, default configuration, every backend) twice:
as the frontend states them (``default``) and with the calibrated model applied
(:meth:`~fusion_vo.calibration.camera_noise.CameraNoise.apply`, what a run does when ``cam0/sensor.yaml``
states it). It prints the ATE [mm] of visual odometry and of each fused track (EKF / RTS / GTSAM batch /
iSAM2), and per recording, over its seeds (and over all the drives), each variant's mean ATE relative to
visual odometry, on how many seeds each fused track is at most visual odometry's, and how often the RTS
smoother is at most the EKF and the batch at most iSAM2. The baseline is visual odometry alone, the best
single sensor on these drives, and the default fusion beside it.

Usage::

    python benchmarks/camera_noise.py [--only square,tilted] [--seeds N] [--calibration-drives K] [--out DIR]
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

from common import FUSED, add_out, ate_against, names, parser, standard, work_dir

from fusion_vo import backends
from fusion_vo.calibration.camera_noise_drive import calibrate
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.simulation.standard import STANDARD

DEFAULT_SET = "square,circle,random60,gps_outage,tilted,short"


def one_seed(seq: Path, noise) -> dict[str, list[float] | float]:
    """ATE [mm] of visual odometry and of the fused tracks, default and calibrated, on one recording."""
    rec = Recording(seq)
    ate = ate_against(rec)
    vo = run_visual_odometry(rec, OdometryConfig(camera_noise=False))
    row: dict = {"vo": ate(vo.track)}
    for label, increments in (("default", vo.increments), ("calibrated", noise.apply(vo.increments))):
        fused = backends.run_backends(rec, dataclasses.replace(vo, increments=increments), backend="all")
        row[label] = [ate(fused.trajectories[k]) for k in FUSED]
    return row


def summary(rows: list[dict]) -> list[str]:
    """Per variant: mean ATE relative to visual odometry, seeds at most it, RTS <= EKF, batch <= iSAM2."""
    vo = np.array([r["vo"] for r in rows])
    out = []
    for label in ("default", "calibrated"):
        ate = np.array([r[label] for r in rows])  # seeds x (EKF, RTS, batch, iSAM2)
        rel = 100.0 * (ate / vo[:, None] - 1.0).mean(axis=0)
        at_most = (ate <= vo[:, None]).sum(axis=0)
        rts = int(np.sum(ate[:, 1] <= ate[:, 0]))
        batch = int(np.sum(ate[:, 2] <= ate[:, 3]))
        out.append(f"    {label:10s} mean vs visual odometry " + " / ".join(f"{v:+.1f} %" for v in rel)
                   + "; at most it on " + " / ".join(str(int(n)) for n in at_most) + f" of {len(rows)} seeds"
                   + f"; RTS <= EKF on {rts}, batch <= iSAM2 on {batch}")
    return out


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--only", help=f"comma-separated standard recordings (default {DEFAULT_SET})")
    ap.add_argument("--seeds", type=int, default=2, help="other seeds of each recording (default 2)")
    ap.add_argument("--calibration-drives", type=int, default=2, help="drives to calibrate on (default 2)")
    add_out(ap)
    args = ap.parse_args(argv)
    chosen = names(args.only, DEFAULT_SET.split(","))
    print("ATE [mm]: visual odometry | default EKF / RTS / batch / iSAM2 | calibrated EKF / RTS / batch / iSAM2")
    every = []
    with work_dir(args.out, "camera-noise-") as out:
        for name in chosen:
            drives = [Recording(standard(out, name, 1000 * i, f"_calibration{i}"))
                      for i in range(1, args.calibration_drives + 1)]
            noise = calibrate(drives)
            print(f"{name}: {noise.describe()}", flush=True)
            rows = []
            for i in range(args.seeds + 1):
                seq = standard(out, name, 100 * i, "" if i == 0 else f"_seed{STANDARD[name][1] + 100 * i}")
                row = one_seed(seq, noise)
                rows.append(row)
                print(f"  seed +{100 * i}: {row['vo']:.4f} | " + " / ".join(f"{v:.4f}" for v in row["default"])
                      + " | " + " / ".join(f"{v:.4f}" for v in row["calibrated"]), flush=True)
            print("\n".join(summary(rows)), flush=True)
            every.extend(rows)
    if len(chosen) > 1:
        print(f"all {len(every)} drives:")
        print("\n".join(summary(every)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
