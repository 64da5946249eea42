"""Frames per second of the visual odometry chain, single-threaded, on a generated 640 x 360 recording.

For each frontend: PNG decode (``cv2.imread``), the frontend's ``process`` and the ground geometry, per
frame, in CPU time of this process with OpenCV and the BLAS limited to one thread; frames per second
with decode included (end to end) and excluded; peak resident memory after each quarter of the frames
(flat in recording length). Usage::

    python benchmarks/bench_frontends.py [--standard random60] [--frames N] [--frontend klt,features]

The same measurement is ``fusion-vo bench [SEQ]``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # single-threaded numerical libraries (before numpy loads)

import argparse  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

from fusion_vo.benchmark import format_timing, time_frontend  # noqa: E402
from fusion_vo.simulation.standard import make_standard  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--standard", default="random60", help="standard recording to generate (default random60)")
    ap.add_argument("--sequence", help="use this recording instead of generating one")
    ap.add_argument("--frames", type=int, help="at most this many frames")
    ap.add_argument("--frontend", default="klt,features")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-frontends-") as tmp:
        seq = Path(args.sequence) if args.sequence else make_standard(args.standard, Path(tmp) / args.standard)
        for name in args.frontend.split(","):
            print(format_timing(time_frontend(seq, name.strip(), args.frames)))


if __name__ == "__main__":
    main()
