"""Cost of the checks ``fusion-vo run`` makes before any work, beside the run itself, in the same process.

The checks (:func:`fusion_vo.pipeline.check_inputs`) validate the configuration and read every stream the
run will use (frame list, camera calibration, wheels, IMU, ground truth) once more than the run does. They
are timed against the whole run (visual odometry, EKF + RTS smoother, files, no evaluation), interleaved
and repeated, in CPU time of this process with single-threaded numerical libraries. A run's staging
(writing into a hidden folder and renaming it) is part of the run's time.

Usage::

    python benchmarks/bench_run_checks.py [--standard short] [--repeat 3]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # single-threaded numerical libraries (before numpy loads)

import argparse
import logging
import statistics
import tempfile
import time
from pathlib import Path

from fusion_vo.config import RunConfig
from fusion_vo.pipeline import check_inputs, run_pipeline
from fusion_vo.simulation.standard import make_standard


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--standard", default="short", help="standard generated recording (default: short)")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    with tempfile.TemporaryDirectory() as tmp:
        seq = make_standard(args.standard, Path(tmp) / "rec")
        config = RunConfig(backend="ekf", evaluate=False)
        checks, runs = [], []
        for i in range(args.repeat):
            t0 = time.process_time()
            inputs = check_inputs(seq, config)
            checks.append(time.process_time() - t0)
            t0 = time.process_time()
            run_pipeline(seq, Path(tmp) / "run", config)
            runs.append(time.process_time() - t0)
        frames = len(inputs.recording)
    check, run = statistics.median(checks), statistics.median(runs)
    print(f"recording '{args.standard}': {frames} frames, streams {', '.join(inputs.spans)}")
    print(f"checks before work: {check * 1000:.1f} ms (median of {args.repeat}, CPU time; "
          f"all: {', '.join(f'{c * 1000:.1f}' for c in checks)})")
    print(f"whole run (checks included): {run:.3f} s (all: {', '.join(f'{r:.3f}' for r in runs)})")
    print(f"checks / run: {100 * check / run:.1f} %")


if __name__ == "__main__":
    main()
