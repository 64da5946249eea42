"""CPU cost of the direct frontend beside the plain OpenCV script, on the first frames of a recording.

The frames are decoded once, before timing; then, in every repeat and in turn, the plain script
(``benchmarks/baseline_opencv.py``, ``measure`` on each consecutive pair) and each frontend
configuration process the same frames with OpenCV and the BLAS libraries on one thread. The figure is
frames per CPU-second of the process (``time.process_time``), which a loaded machine disturbs less than
the wall clock; the median and range over the repeats are printed, with the ratio to the plain script.

    python benchmarks/bench_direct.py SEQ [--frames 150] [--repeats 3]
                                          [--configs 'direct' 'direct:{"finest_level": 1}' 'klt']
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent))

import baseline_opencv  # noqa: E402

from frontends import make_frontend  # noqa: E402
from fusion_vo.geometry.ground import GroundGeometry  # noqa: E402
from fusion_vo.recording import Recording  # noqa: E402


def parse_config(text: str) -> tuple[str, dict]:
    """``name`` or ``name:{json options}``."""
    name, _, options = text.partition(":")
    return name, json.loads(options) if options else {}


def time_plain(frames: list[np.ndarray]) -> float:
    """CPU seconds of the plain script over the frames."""
    start = time.process_time()
    for a, b in zip(frames[:-1], frames[1:]):
        baseline_opencv.measure(a, b)
    return time.process_time() - start


def time_frontend(name: str, options: dict, frames: list[np.ndarray], times: list[float], geometry) -> tuple[float, int]:
    """CPU seconds of a fresh frontend over the frames, and the pairs it measured."""
    frontend = make_frontend(name, options, point_map=geometry.rectifier)
    start = time.process_time()
    ok = sum(frontend.process(img, t).ok for img, t in zip(frames, times))
    return time.process_time() - start, ok


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seq", help="recording folder")
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--configs", nargs="+", default=["direct", 'direct:{"finest_level": 1}', "klt"],
                    help="frontend or frontend:{json options}")
    args = ap.parse_args(argv)
    if args.frames < 2 or args.repeats < 1:
        ap.error("--frames must be at least 2 and --repeats at least 1")
    rec = Recording(args.seq)
    frames, times = [], []
    for frame in rec.frames():
        if frame.image is None:
            continue
        frames.append(frame.image)
        times.append(frame.t)
        if len(frames) >= args.frames:
            break
    geometry = GroundGeometry(rec.camera)
    configs = [parse_config(c) for c in args.configs]
    results: dict[str, list[float]] = {"plain OpenCV script": []}
    measured: dict[str, int] = {}
    cv2.setNumThreads(1)
    load_before = os.getloadavg()
    with threadpool_limits(limits=1):
        for _ in range(args.repeats):
            results["plain OpenCV script"].append(len(frames) / time_plain(frames))
            for name, options in configs:
                label = name + (f" {json.dumps(options)}" if options else "")
                seconds, ok = time_frontend(name, options, frames, times, geometry)
                results.setdefault(label, []).append(len(frames) / seconds)
                measured[label] = ok
    plain = float(np.median(results["plain OpenCV script"]))
    print(f"{Path(args.seq).name}: {len(frames)} frames {frames[0].shape[1]}x{frames[0].shape[0]}, "
          f"{args.repeats} interleaved repeats, one thread, frames per CPU-second (median, range); load average "
          f"{load_before[0]:.1f} before, {os.getloadavg()[0]:.1f} after")
    for label, values in results.items():
        med = float(np.median(values))
        pairs = f", {measured[label]}/{len(frames) - 1} measured" if label in measured else ""
        print(f"  {label:<36} {med:7.1f}  ({min(values):.1f}-{max(values):.1f})  {med / plain:5.2f}x the plain "
              f"script{pairs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
