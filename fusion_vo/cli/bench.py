"""``fusion-vo bench [SEQ]``: frames per second of visual odometry beside the plain OpenCV script."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from fusion_vo.cli.arguments import frame_count, repeat_count, thread_count
from fusion_vo.errors import InputError

#: the frontends that can be measured
FRONTENDS = ("klt", "features")

#: the recording generated when none is given (the same as benchmarks/frontend_speed.py end-to-end)
STANDARD = "random60"


def frontend_list(text: str) -> list[str]:
    """An ``argparse`` type: comma-separated frontend names, each of :data:`FRONTENDS`."""
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"expected one or more of {', '.join(FRONTENDS)}")
    for name in names:
        if name not in FRONTENDS:
            raise argparse.ArgumentTypeError(f"unknown frontend '{name}' (choose from {', '.join(FRONTENDS)})")
    return list(dict.fromkeys(names))


def thread_list(text: str) -> list[int]:
    """An ``argparse`` type: comma-separated thread counts, each from 1 to ``MAX_THREADS``."""
    values = [thread_count(s.strip()) for s in text.split(",") if s.strip()]
    if not values:
        raise argparse.ArgumentTypeError("expected one or more thread counts")
    return sorted(set(values))


def register(sub) -> None:
    p = sub.add_parser("bench", help="frames per second of visual odometry beside a plain OpenCV script",
                       description="Frames per second of visual odometry, end to end (decoding included), with "
                                   "one thread and with all threads, beside the plain OpenCV script "
                                   "of fusion_vo.baseline run on the same frames in the same run; then "
                                   "the time per frame of decoding, frontend and ground geometry on one thread. "
                                   f"Default recording: the standard '{STANDARD}' drive (generated, 1201 frames "
                                   "of 640x360), as benchmarks/frontend_speed.py end-to-end. A run that tracks "
                                   "fewer than half of the frame pairs (textureless or blurred frames) gets no "
                                   "rate: its rows say 'not a speed' (and their ratios 'not comparable'), and the "
                                   "command ends with an error naming those runs and exit status 2.")
    p.add_argument("sequence", nargs="?", help=f"recording folder (default: generate the standard '{STANDARD}')")
    p.add_argument("--frontend", type=frontend_list, default=list(FRONTENDS),
                   help="comma-separated frontends (default: klt,features)")
    p.add_argument("--frames", type=frame_count, default=None, help="use the first N frames only (N >= 2)")
    p.add_argument("--threads", type=thread_list, default=None,
                   help="comma-separated thread counts to measure (default: 1 and the cores available)")
    p.add_argument("--repeats", type=repeat_count, default=3, help="interleaved repeats (default: 3, at most 100)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fusion_vo.benchmark import MIN_TRACKED, not_comparable, run_benchmark
    from fusion_vo.recording import Recording

    with tempfile.TemporaryDirectory(prefix="fusion-vo-bench-") as tmp:
        seq = args.sequence
        if seq is None:
            from fusion_vo.simulation.standard import make_standard

            print(f"generating the standard '{STANDARD}' recording (60 s, 640x360, 20 frames/s) ...", flush=True)
            seq = make_standard(STANDARD, Path(tmp) / STANDARD)
        else:
            rec = Recording(seq)
            if not rec.has("cam0"):
                raise InputError("this recording has no camera stream (cam0/data.csv is missing)", rec.path)
            rec.camera, rec.frame_times  # noqa: B018 -- a one-line error for a bad sensor.yaml or data.csv
        rows = run_benchmark(seq, args.frontend, thread_counts=args.threads, repeats=args.repeats,
                             max_frames=args.frames, out=lambda line: print(line, flush=True))
    unmeasured = not_comparable(rows)
    if unmeasured:
        runs = "; ".join(f"{row.label} ({100 * row.tracked:.0f} %)" for row in unmeasured)
        raise InputError(f"no speed measured: fewer than {100 * MIN_TRACKED:.0f} % of the frame pairs tracked by "
                         f"{runs}; a rate over frames that measured nothing (textureless, blurred) is not a speed",
                         args.sequence or seq)
    return 0
