"""``fusion-vo bench [SEQ]``: frames per second of the visual odometry chain, one thread."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path


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
