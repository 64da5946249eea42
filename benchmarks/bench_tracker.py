"""CPU time per frame of the tracking thread's work, this checkout beside an earlier revision, in one run.

The code of ``--against REV`` (``frontends/`` and ``fusion_vo/``) is exported with ``git archive`` to a
temporary folder. Then, interleaved and repeated, a fresh interpreter for each side decodes the frames
into memory, runs the frontend's ``prepare`` on them (as the reader threads of a run do) and times
``VisualOdometry.process`` over them on one thread: the frontend, the gyro derotation (the recording
has an IMU) and the ground geometry, i.e. what the tracking thread of a run does per frame. OpenCV and
BLAS run on one thread; the time is ``time.thread_time`` (CPU time, so the other jobs of a loaded
machine weigh less than on the wall clock). The frontend's motions and the body increments of both
sides are compared bit for bit. Each side also times the point map's ``to_image`` on every pixel of a frame
(what the dense fallback's rectification grid costs once per run).

Usage::

    python benchmarks/bench_tracker.py --against REV [--standard random60 | --sequence SEQ]
                                       [--frontend klt,features] [--frames 400] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent

WORKER = r"""
import json, sys, time
import numpy as np
sys.path.insert(0, sys.argv[1])
from frontends import make_frontend
from fusion_vo.geometry.derotation import GyroDerotation
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.odometry import VisualOdometry, opencv_threads
from fusion_vo.recording import Recording
seq, name, frames, out = sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5]
rec = Recording(seq)
raw = [(f.image, f.t) for f in rec.frames(stop=frames) if f.image is not None]
geometry = GroundGeometry(rec.camera)
with opencv_threads(1):
    fe = make_frontend(name, {}, point_map=geometry.rectifier)
    vo = VisualOdometry(fe, geometry, GyroDerotation(rec.imu(), geometry) if rec.has_imu() else None)
    prepare = getattr(fe, "prepare", None)
    frames = [(prepare(im) if prepare else im, t) for im, t in raw]
    start = time.thread_time()
    done = [vo.process(im, t) for im, t in frames]
    cpu = time.thread_time() - start
    motions = [m for m, _ in done]
    deltas = [inc.delta if inc is not None and inc.ok else np.full(3, np.nan) for _, inc in done]
    h, w = raw[0][0].shape
    grid = np.stack(np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)), -1).reshape(-1, 2)
    start = time.thread_time()
    geometry.rectifier.to_image(grid)
    grid_cpu = time.thread_time() - start
ok = [m.matrix if m.ok else np.full((2, 3), np.nan) for m in motions]
np.save(out, np.hstack([np.array(ok).reshape(len(ok), -1), np.array(deltas)]))
print(json.dumps({"ms": 1000 * cpu / len(frames), "grid_ms": 1000 * grid_cpu, "frames": len(frames),
                  "ok": sum(m.ok for m in motions), "module": sys.modules["frontends"].__file__}))
"""


def export(rev: str, dest: Path) -> Path:
    """``frontends/`` and ``fusion_vo/`` of ``rev`` in ``dest``."""
    archive = dest / "code.tar"
    subprocess.run(["git", "-C", str(REPO), "archive", "--format=tar", "-o", str(archive), rev, "frontends", "fusion_vo"],
                   check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(dest / "code", filter="data")
    return dest / "code"


def run_side(code: Path, seq: Path, frontend: str, frames: int, out: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(code)}
    done = subprocess.run([sys.executable, "-c", WORKER, str(code), str(seq), frontend, str(frames), str(out)],
                          check=True, capture_output=True, text=True, env=env, cwd=str(out.parent))
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert Path(result["module"]).resolve().is_relative_to(code.resolve()), result["module"]
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", required=True, help="git revision to compare with (e.g. main, HEAD~3)")
    ap.add_argument("--standard", default="random60")
    ap.add_argument("--sequence")
    ap.add_argument("--frontend", default="klt,features")
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-tracker-") as tmp:
        tmp = Path(tmp)
        if args.sequence:
            seq = Path(args.sequence).resolve()
        else:
            from fusion_vo.simulation.standard import make_standard

            seq = make_standard(args.standard, tmp / args.standard)
        sides = {args.against: export(args.against, tmp), "this checkout": REPO}
        load = os.getloadavg()[0]
        print(f"{seq}, first {args.frames} frames; one thread; CPU time of VisualOdometry.process per frame, median (range) of "
              f"{args.repeats} interleaved repeats; load average {load:.1f} before")
        print("| frontend | code | CPU time per frame | time relative to the other side | to_image on a frame's pixels | "
              "same motions and increments |")
        print("|---|---|---|---|---|---|")
        for frontend in args.frontend.split(","):
            times = {side: [] for side in sides}
            grid = {side: [] for side in sides}
            for _ in range(args.repeats):
                for side, code in sides.items():
                    r = run_side(code, seq, frontend, args.frames, tmp / f"{frontend}-{len(times[side])}-{id(side)}.npy")
                    times[side].append(r["ms"])
                    grid[side].append(r["grid_ms"])
            a, b = (np.load(next(tmp.glob(f"{frontend}-0-{id(side)}.npy"))) for side in sides)
            same = a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
            old, new = sides
            for side in sides:
                other = new if side == old else old
                ratio = statistics.median(times[other]) / statistics.median(times[side])
                print(f"| {frontend} | {side} | {statistics.median(times[side]):.3f} ({min(times[side]):.3f}-"
                      f"{max(times[side]):.3f}) ms | {1 / ratio:.3f} | {statistics.median(grid[side]):.1f} ms | "
                      f"{'yes, bit for bit' if same else 'NO'} |")
        print(f"load average {os.getloadavg()[0]:.1f} after")
    return 0


if __name__ == "__main__":
    sys.exit(main())
