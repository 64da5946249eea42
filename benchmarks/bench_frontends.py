"""Frames per second of visual odometry beside the plain OpenCV script, on a generated 640 x 360 drive.

For each frontend, with one thread and with all threads: the wall time of visual odometry over the
whole recording, decoding included (``fusion_vo.odometry.run_visual_odometry``), beside the plain
OpenCV script ``benchmarks/baseline_opencv.py`` (Shi-Tomasi, pyramidal LK, RANSAC similarity, one frame
at a time, as read from disk) on the same frames. The runs are interleaved and repeated; each ratio is
taken between runs made next to each other. Then, on one thread, the CPU time per frame of PNG decode,
frontend and ground geometry, and the peak resident memory after each quarter of the frames. Usage::

    python benchmarks/bench_frontends.py [--standard random60] [--sequence SEQ] [--frames N]
                                         [--frontend klt,features] [--threads 1,2] [--repeats 3]
                                         [--variant 'klt:{"fb_skip_ratio": 0.9}' ...]

``--variant`` adds the rows of a frontend with non-default options (JSON), in the same interleaved runs.

``fusion-vo bench [SEQ]`` is the same measurement (same default recording, same code).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from baseline_opencv import run as baseline_run  # this folder

from fusion_vo.benchmark import run_benchmark
from fusion_vo.cli.bench import frame_count, frontend_list, thread_list
from fusion_vo.cli.arguments import positive_int
from fusion_vo.simulation.standard import make_standard


def variant(text: str) -> str:
    """An ``argparse`` type: ``FRONTEND:JSON``, a frontend and options it accepts."""
    from frontends import make_frontend

    name, _, options = text.partition(":")
    try:
        parsed = json.loads(options)
        if not isinstance(parsed, dict):
            raise ValueError("the options must be a JSON object")
        make_frontend(frontend_list(name)[0], parsed)
    except (argparse.ArgumentTypeError, ValueError, TypeError) as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None
    return text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--standard", default="random60", help="standard recording to generate (default random60)")
    ap.add_argument("--sequence", help="use this recording instead of generating one")
    ap.add_argument("--frames", type=frame_count, help="the first N frames only")
    ap.add_argument("--frontend", type=frontend_list, default=["klt", "features"])
    ap.add_argument("--threads", type=thread_list, help="thread counts (default: 1 and the cores available)")
    ap.add_argument("--repeats", type=positive_int, default=3)
    ap.add_argument("--variant", type=variant, action="append", default=[], metavar="FRONTEND:JSON",
                    help='also a frontend with these options, e.g. klt:{"fb_skip_ratio": 0.9} (repeatable)')
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-frontends-") as tmp:
        if args.sequence:
            seq = Path(args.sequence)
        else:
            print(f"generating the standard '{args.standard}' recording ...", flush=True)
            seq = make_standard(args.standard, Path(tmp) / args.standard)
        run_benchmark(seq, args.frontend + args.variant, baseline_run, args.threads, args.repeats, args.frames,
                      out=lambda line: print(line, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
