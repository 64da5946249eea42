"""``fusion-vo demo``: generate a short recording, run it, print the accuracy, write plots."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from fusion_vo.cli.progress import progress_bar
from fusion_vo.errors import InputError
from fusion_vo.cli.arguments import random_seed

DEMO_PROFILE = "square"


def register(sub) -> None:
    p = sub.add_parser("demo", help="generate a demo recording, run it and report the accuracy",
                       description="Generate a recording of the thesis' 0.9 m square over a photographed floor "
                                   "(camera, wheel encoders with calibration errors, IMU, ground truth), run visual "
                                   "odometry and both fusion backends on it, print the accuracy against ground truth "
                                   "and write a trajectory plot and an HTML report.")
    p.add_argument("--out", "-o", default="fusion-vo-demo", help="output folder (default: ./fusion-vo-demo)")
    p.add_argument("--frontend", choices=["klt", "features", "direct"], default="klt")
    p.add_argument("--seed", type=random_seed, default=0)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fusion_vo.config.run import RunConfig
    from fusion_vo.outputs import check_replaceable
    from fusion_vo.pipeline import RUN_MARKER, run_pipeline
    from fusion_vo.recording.writer import MARKER as RECORDING_MARKER
    from fusion_vo.simulation import simulate

    out = Path(args.out)
    seq = out / "recording"
    # both folders are checked before the recording is generated (a minute's work); demo has no --force
    if os.path.lexists(out) and not out.is_dir():
        raise InputError("the demo folder must be a folder, but a file of that name exists", out)
    check_replaceable(seq, RECORDING_MARKER, what="recording folder", remedy="give another --out")
    check_replaceable(out / "run", RUN_MARKER, inputs=[seq], remedy="give another --out")
    t0 = time.perf_counter()
    print(f"generating the demo recording ({DEMO_PROFILE} profile, seed {args.seed}) in {seq} ...")
    simulate(seq, profile=DEMO_PROFILE, seed=args.seed)
    t1 = time.perf_counter()
    cfg = RunConfig(frontend=args.frontend, backend="all")
    with progress_bar("visual odometry") as update:
        summary = run_pipeline(seq, out / "run", cfg, progress=update)
    t2 = time.perf_counter()
    for note in summary.notes:
        print(f"note: {note}")
    if summary.metrics:
        from fusion_vo.cli.evaluate import show_metrics

        show_metrics(summary.metrics, "the demo run")
    print(summary.line())
    print(f"recording generated in {t1 - t0:.1f} s, processed in {t2 - t1:.1f} s")
    for name in ("trajectories.png", "report.html"):
        p = out / "run" / name
        if p.exists():
            print(f"wrote {p}")
    return 0
