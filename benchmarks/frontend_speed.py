"""Speed of the visual odometry chain beside the plain OpenCV script, measured in the same run.

The baseline is the plain OpenCV script of ``fusion_vo.baseline`` (Shi-Tomasi corners, pyramidal LK, a
RANSAC similarity, one frame at a time as read from disk), run interleaved with fusion-vo on the same frames.

Subcommands:

end-to-end  frames per second of the whole visual odometry of a recording (``run_visual_odometry``, PNG
            decoding included, wall clock) for each frontend with one thread and with all threads, beside
            the plain script run twice in every repeat (OpenCV's default threads as written, and on one
            thread); the runs are interleaved and repeated, and each ratio is taken against the faster
            plain-script run of the same repeat. Then what the CPU time allows (the shortest wall time per
            frame: the larger of the calling thread's CPU time and the total over the cores used) and, on one
            thread, the CPU time per frame of decode, frontend and ground geometry with the peak memory after
            each quarter of the frames. ``fusion-vo bench`` is the same measurement (same default recording,
            same code, ``fusion_vo.benchmark``); ``--variant`` adds the rows of a frontend with non-default
            options to the same interleaved runs.
cpu         frames per CPU-second of each frontend configuration on the first frames of a recording, decoded
            beforehand, OpenCV and BLAS on one thread, beside the plain script's per-frame step on the same
            frames; interleaved repeats, median and range, and the ratio to the plain script. A loaded
            machine disturbs CPU time less than the wall clock.

Usage::

    python benchmarks/frontend_speed.py end-to-end [--standard random60 | --sequence SEQ] [--frames N]
        [--frontend klt,features] [--threads 1,2] [--repeats 3] [--variant 'klt:{"fb_skip_ratio": 0.9}' ...]
    python benchmarks/frontend_speed.py cpu [--standard random60 | --sequence SEQ] [--frames 150] [--repeats 3]
        [--configs direct 'direct:{"finest_level": 1}' klt]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

from common import fail, load, parser, span, standard, table, work_dir

from frontends import make_frontend
from fusion_vo import baseline
from fusion_vo.benchmark import run_benchmark, split_spec
from fusion_vo.cli.arguments import frame_count, positive_int
from fusion_vo.cli.bench import frontend_list, thread_list
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.recording import Recording
from fusion_vo.simulation.standard import STANDARD


def spec(text: str) -> str:
    """An ``argparse`` type: ``FRONTEND`` or ``FRONTEND:JSON``, a frontend and options it accepts."""
    try:
        name, options = split_spec(text)
        if not isinstance(options, dict):
            raise ValueError("the options must be a JSON object")
        make_frontend(name, options)
    except (ValueError, TypeError) as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None
    return text


def variant(text: str) -> str:
    """An ``argparse`` type for ``--variant``: ``FRONTEND:JSON`` of a frontend ``fusion-vo bench`` measures."""
    try:
        frontend_list(text.partition(":")[0])
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None
    return spec(text)


def sequence(args, root: Path) -> Path:
    """``--sequence``, or the standard recording ``--standard`` generated in ``root``."""
    return Path(args.sequence) if args.sequence else standard(root, args.standard)


def end_to_end(args) -> int:
    with work_dir(None) as root:
        seq = sequence(args, root)
        run_benchmark(seq, args.frontend + args.variant, baseline.run, args.threads, args.repeats, args.frames,
                      out=lambda line: print(line, flush=True))
    return 0


def cpu(args) -> int:
    with work_dir(None) as root:
        rec = Recording(sequence(args, root))
        frames, times = [], []
        for frame in rec.frames(stop=args.frames):
            if frame.image is not None:
                frames.append(frame.image)
                times.append(frame.t)
        if len(frames) < 2:
            fail(f"{rec.path}: fewer than two readable frames")
        geometry = GroundGeometry(rec.camera)
        results: dict[str, list[float]] = {"plain OpenCV script": []}
        measured: dict[str, int] = {}
        before = load()
        cv2.setNumThreads(1)
        with threadpool_limits(limits=1):
            for _ in range(args.repeats):
                start = time.process_time()
                for a, b in zip(frames[:-1], frames[1:]):
                    baseline.measure(a, b)
                results["plain OpenCV script"].append(len(frames) / (time.process_time() - start))
                for text in args.configs:
                    name, options = split_spec(text)
                    frontend = make_frontend(name, options, point_map=geometry.rectifier)
                    start = time.process_time()
                    ok = sum(frontend.process(img, t).ok for img, t in zip(frames, times))
                    results.setdefault(text, []).append(len(frames) / (time.process_time() - start))
                    measured[text] = ok
    plain = float(np.median(results["plain OpenCV script"]))
    print(f"{rec.path.name}: {len(frames)} frames {frames[0].shape[1]}x{frames[0].shape[0]}, {args.repeats} "
          f"interleaved repeats, one thread; load average {before} before, {load()} after")
    print(table(["configuration", "frames per CPU-second, median (range)", "x the plain script", "frame pairs measured"],
                [[label, span(values, ".1f"), f"{np.median(values) / plain:.2f}",
                  f"{measured[label]} / {len(frames) - 1}" if label in measured else "–"]
                 for label, values in results.items()]))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    sub = ap.add_subparsers(dest="command", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--standard", default="random60", choices=sorted(STANDARD),
                        help="standard recording to generate (default random60)")
    common.add_argument("--sequence", help="use this recording instead of generating one")
    p = sub.add_parser("end-to-end", parents=[common], help="frames per second end to end, beside the plain script")
    p.add_argument("--frames", type=frame_count, help="the first N frames only")
    p.add_argument("--frontend", type=frontend_list, default=["klt", "features"])
    p.add_argument("--threads", type=thread_list, help="thread counts (default: 1 and the cores available)")
    p.add_argument("--repeats", type=positive_int, default=3)
    p.add_argument("--variant", type=variant, action="append", default=[], metavar="FRONTEND:JSON",
                   help='also a frontend with these options, e.g. klt:{"fb_skip_ratio": 0.9} (repeatable)')
    p.set_defaults(func=end_to_end)
    p = sub.add_parser("cpu", parents=[common], help="frames per CPU-second on decoded frames, beside the plain script")
    p.add_argument("--frames", type=frame_count, default=150, help="the first N frames (default 150)")
    p.add_argument("--repeats", type=positive_int, default=3)
    p.add_argument("--configs", type=spec, nargs="+", default=["direct", 'direct:{"finest_level": 1}', "klt"],
                   metavar="FRONTEND[:JSON]", help="frontend configurations (default: direct, direct at half "
                                                   "resolution, klt)")
    p.set_defaults(func=cpu)
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
