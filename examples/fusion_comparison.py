"""Fusion comparison on a hard generated recording: raw visual and wheel odometry against the fused tracks.

The thesis closes (section 5.3.2) by proposing Kalman filtering and fusion with other sensors to cut the
visual odometry's error. This script measures what that buys on a recording built to hurt every single
sensor:

* wheel encoders with a wrong wheel radius and wheel base in their calibration, and wheel slip;
* a gyro with bias and noise;
* a specular highlight fixed in the image, motion blur, dropped camera frames and a stretch of
  featureless floor where the camera sees nothing to track.

``fusion_vo.pipeline.run_pipeline`` (what ``fusion-vo run SEQ --out DIR --backend all`` does) produces
the raw visual track (``vo``), wheel dead reckoning (``wheel``), the EKF and its RTS smoothing
(``ekf``, ``ekf_smoothed``) and the GTSAM factor graph, batch and online (``gtsam``, ``gtsam_online``);
``fusion_vo.evaluation.evaluate_run`` scores each against ground truth:

* ATE: RMS position error after the least-squares SE(2) alignment [m];
* end: end-point error with the track anchored at the start pose, as % of the path length;
* heading: heading error at the end [deg];
* RPE 1 m: RMS relative position error over 1 m of path, as % of 1 m.

The run folders (trajectories, ``metrics.json``, plots, ``report.html``) stay in ``--out``.

Run::

    python examples/fusion_comparison.py [--out DIR] [--seed N] [--quick]

``--quick`` generates a 10 s recording instead of 60 s (rendered with fewer rays per pixel) and runs the
KLT frontend only.
"""

from __future__ import annotations

import time

from common import FRONTENDS, example_parser, fmt, format_table, output_dir
from fusion_vo.config import RunConfig
from fusion_vo.evaluation import evaluate_run
from fusion_vo.pipeline import run_pipeline
from fusion_vo.simulation import simulate

#: trajectories in the order of the table
TRAJECTORIES = ("vo", "wheel", "ekf", "ekf_smoothed", "gtsam", "gtsam_online")

#: simulator options of the hard recording
HARD = {
    "radius_error_left": 0.02,
    "radius_error_right": -0.01,
    "base_error": 0.05,
    "slip": 0.002,
    "highlight_radius": 30.0,
    "exposure_time": 0.015,
    "dropped_frames": 0.03,
}

#: the stretch of featureless floor, as a fraction of the duration
FEATURELESS = (0.45, 0.5)

DURATION_S = 60.0
#: the quick run: a shorter drive, rendered with fewer rays and blur samples
QUICK = {"duration": 10.0, "supersample": 1, "blur_samples": 3}


def main(argv=None) -> int:
    parser = example_parser(__doc__.split("\n\n")[0])
    args = parser.parse_args(argv)
    frontends = FRONTENDS[:1] if args.quick else FRONTENDS
    length = dict(QUICK) if args.quick else {"duration": DURATION_S}
    duration = length["duration"]
    with output_dir(args.out) as out:
        t_start = time.perf_counter()
        featureless = [FEATURELESS[0] * duration, FEATURELESS[1] * duration]
        seq = simulate(out / "hard", profile="random", seed=args.seed, featureless_time=featureless,
                       **length, **HARD)
        print(f"generated the hard recording in {time.perf_counter() - t_start:.1f} s: {seq}")
        for frontend in frontends:
            run_dir = out / f"run-{frontend}"
            t0 = time.perf_counter()
            summary = run_pipeline(seq, run_dir, RunConfig(frontend=frontend, backend="all", evaluate=False))
            metrics = evaluate_run(run_dir, seq)
            print(f"{frontend}: {summary.line()} ({time.perf_counter() - t0:.1f} s)")
            for note in summary.notes:
                print(f"  note: {note}")
            rows = []
            for name in TRAJECTORIES:
                fig = metrics.get(name)
                if fig is None:
                    rows.append([name, "-", "-", "-", "-", "missing"])
                    continue
                seconds = summary.vo_seconds if name == "vo" else summary.backend_seconds.get(name)
                rows.append([name, fmt(fig["ate_m"], 4), fmt(fig["end_pct"], 2), fmt(fig["heading_deg"], 2),
                             fmt(fig["rpe_1m_pct"], 2), fmt(seconds, 2) if seconds is not None else "-"])
            print()
            print(format_table(f"Fusion comparison, {frontend} frontend ({summary.distance_m:.1f} m of visual track)",
                               ["trajectory", "ATE m", "end %", "heading deg", "RPE 1m %", "time s"], rows))
            print()
        print(f"total time {time.perf_counter() - t_start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
