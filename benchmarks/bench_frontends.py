"""Frames per second of visual odometry beside the plain OpenCV script, on a generated 640 x 360 drive.

For each frontend, with one thread and with all threads: the wall time of visual odometry over the
whole recording, decoding included (``fusion_vo.odometry.run_visual_odometry``), beside the plain
OpenCV script ``benchmarks/baseline_opencv.py`` (Shi-Tomasi, pyramidal LK, RANSAC similarity, one frame
at a time, as read from disk) on the same frames. The runs are interleaved and repeated; each ratio is
taken between runs made next to each other. Then, on one thread, the CPU time per frame of PNG decode,
frontend and ground geometry, and the peak resident memory after each quarter of the frames. Usage::

    python benchmarks/bench_frontends.py [--standard random60] [--sequence SEQ] [--frames N]
                                         [--frontend klt,features] [--threads 1,2] [--repeats 3]

``fusion-vo bench [SEQ]`` is the same measurement (same default recording, same code).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from baseline_opencv import run as baseline_run  # this folder

from fusion_vo.benchmark import run_benchmark
from fusion_vo.cli.bench import frame_count, frontend_list, thread_list
from fusion_vo.cli.run import positive_int
from fusion_vo.simulation.standard import make_standard


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--standard", default="random60", help="standard recording to generate (default random60)")
    ap.add_argument("--sequence", help="use this recording instead of generating one")
    ap.add_argument("--frames", type=frame_count, help="the first N frames only")
    ap.add_argument("--frontend", type=frontend_list, default=["klt", "features"])
    ap.add_argument("--threads", type=thread_list, help="thread counts (default: 1 and the cores available)")
    ap.add_argument("--repeats", type=positive_int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-frontends-") as tmp:
        if args.sequence:
            seq = Path(args.sequence)
        else:
            print(f"generating the standard '{args.standard}' recording ...", flush=True)
            seq = make_standard(args.standard, Path(tmp) / args.standard)
        run_benchmark(seq, args.frontend, baseline_run, args.threads, args.repeats, args.frames,
                      out=lambda line: print(line, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
