"""CPU time per frame of the KLT tracker itself, with and without each speed change, measured in one run.

The frames are decoded into memory first; then, interleaved and repeated, the KLT frontend's
``process`` runs over them on one thread in three variants:

* ``before``    raw frames, backward pass of the forward-backward check always on the pyramid
* ``prepare``   frames made by ``KltFrontend.prepare`` (texture measure and exposure thumbnail done
                ahead, as the reader threads of a run do), backward pass always on the pyramid
* ``current``   prepared frames, backward pass without a pyramid when every point landed within 2 px

Usage::

    python benchmarks/bench_tracker.py [--standard random60 | --sequence SEQ] [--frames 400] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from frontends import make_frontend
from frontends.klt import KltFrontend
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.odometry import opencv_threads
from fusion_vo.recording import Recording
from fusion_vo.simulation.standard import make_standard


def run(frames, geometry, reach: float) -> tuple[float, list]:
    """CPU ms per frame and the measured matrices."""
    fe = make_frontend("klt", {}, point_map=geometry.rectifier)
    fe._lk.fb_direct_reach = reach  # the variant under test
    start = time.process_time()
    out = [fe.process(image, t) for image, t in frames]
    ms = 1000 * (time.process_time() - start) / len(frames)
    return ms, [m.matrix for m in out if m.ok]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--standard", default="random60")
    ap.add_argument("--sequence")
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-tracker-") as tmp:
        seq = Path(args.sequence) if args.sequence else make_standard(args.standard, Path(tmp) / args.standard)
        rec = Recording(seq)
        raw = [(f.image, f.t) for f in rec.frames(stop=args.frames)]
    geometry = GroundGeometry(rec.camera)
    prepared = [(KltFrontend.prepare(image), t) for image, t in raw]
    variants = {"before": (raw, 0.0), "prepare": (prepared, 0.0), "current": (prepared, 2.0)}
    times: dict[str, list] = {name: [] for name in variants}
    matrices = {}
    with opencv_threads(1):
        start = time.process_time()
        [KltFrontend.prepare(image) for image, _ in raw]
        prepare_ms = 1000 * (time.process_time() - start) / len(raw)
        for _ in range(args.repeats):
            for name, (frames, reach) in variants.items():
                ms, matrices[name] = run(frames, geometry, reach)
                times[name].append(ms)
    print(f"{len(raw)} frames of {seq}; one thread; CPU time per frame of KltFrontend.process, median (range) "
          f"of {args.repeats} interleaved repeats")
    print("| variant | CPU time per frame | same motions as 'before' |")
    print("|---|---|---|")
    for name, values in times.items():
        same = len(matrices[name]) == len(matrices["before"]) and all(
            np.array_equal(a, b) for a, b in zip(matrices[name], matrices["before"]))
        print(f"| {name} | {statistics.median(values):.3f} ({min(values):.3f}-{max(values):.3f}) ms | "
              f"{'yes, bit for bit' if same else 'no'} |")
    print(f"prepare() itself, done in the reader threads: {prepare_ms:.3f} ms per frame")
    return 0


if __name__ == "__main__":
    sys.exit(main())
