"""``fusion-vo bench [SEQ]``: frames per second of the visual odometry chain, one thread."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

#: numerical libraries that start worker threads unless told otherwise (read when numpy loads)
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def register(sub) -> None:
    p = sub.add_parser("bench", help="measure frames per second of the frontends (single-threaded)",
                       description="Time PNG decode, frontend and ground geometry per frame on a recording "
                                   "(default: a generated 30 s random drive at 640x360), single-threaded.")
    p.add_argument("sequence", nargs="?", help="recording folder with PNG frames (default: generate one)")
    p.add_argument("--frontend", default="klt,features", help="comma-separated frontends (default: klt,features)")
    p.add_argument("--frames", type=int, default=None, help="use at most this many frames")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if any(os.environ.get(v) != "1" for v in THREAD_VARIABLES):
        # numpy is already loaded with multi-threaded BLAS, whose idle workers would be counted as CPU
        # time: measure in a fresh interpreter limited to one thread.
        env = {**os.environ, **{v: "1" for v in THREAD_VARIABLES}}
        argv = [sys.executable, "-m", "fusion_vo.cli.main", "bench", "--frontend", args.frontend, "--seed", str(args.seed)]
        if args.frames is not None:
            argv += ["--frames", str(args.frames)]
        if args.sequence is not None:
            argv.append(args.sequence)
        return subprocess.run(argv, env=env, check=False).returncode

    from fusion_vo.benchmark import format_timing, time_frontend

    with tempfile.TemporaryDirectory(prefix="fusion-vo-bench-") as tmp:
        seq = args.sequence
        if seq is None:
            from fusion_vo.simulation import simulate

            seq = Path(tmp) / "random30"
            print("generating a 30 s random drive (640x360, 20 frames/s) ...")
            simulate(seq, profile="random", seed=args.seed, duration=30.0)
        for name in [s.strip() for s in args.frontend.split(",") if s.strip()]:
            print(format_timing(time_frontend(seq, name, args.frames)))
    return 0
