"""Frames per second of the visual frontends on 640 x 360 frames, single-threaded.

Renders a drive over scikit-image's gravel photograph (speeds up to ``--max-speed`` px/frame, turns up
to 2.6 deg/frame, stops), writes it as PNG files to a temporary folder, then for every frontend:

* ``decode excluded``: frames already in memory, ``frontend.process`` only;
* ``decode included``: ``cv2.imread`` of each PNG followed by ``frontend.process``;

and reports the resident memory at the start and end of the decode-included run (it must not grow
with the number of frames). Times are CPU times of this (single-threaded) process, so the figures
describe one core even on a machine shared with other jobs. Usage::

    python benchmarks/bench_frontends.py [--frames 400] [--frontend klt features] [--png-compression 3]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # single-threaded numerical libraries (before numpy loads)

import argparse
import math
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import skimage.data

from frontends import make_frontend

WIDTH, HEIGHT = 640, 360


def _clock() -> float:
    """CPU time of this process [s]: single-threaded throughput, unaffected by other jobs' load."""
    return time.process_time()


def _rss_mb() -> float:
    """Current resident set size [MB] (Linux)."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def drive_frames(n: int, max_speed: float, seed: int = 0):
    """Yield ``n`` frames of a camera driving over a mirrored, enlarged gravel floor."""
    tex = cv2.resize(skimage.data.gravel(), (1024, 1024), interpolation=cv2.INTER_CUBIC)
    tile = np.vstack([np.hstack([tex, tex[:, ::-1]]), np.hstack([tex[::-1], tex[::-1, ::-1]])])
    rng = np.random.default_rng(seed)
    x, y, heading = 1024.0, 1024.0, 0.0
    speed, turn = 0.0, 0.0
    for i in range(n):
        if i % 40 == 0:  # new segment: drive, turn or stop
            speed = float(rng.choice([0.0, 0.3, 0.6, 1.0])) * max_speed
            turn = float(rng.uniform(-2.6, 2.6)) if rng.random() < 0.5 else 0.0
        heading += math.radians(turn)
        x += speed * math.sin(heading)
        y -= speed * math.cos(heading)
        # keep the camera over the floor: reflect the walk at the canvas border
        x, y = min(max(x, 500.0), 1548.0), min(max(y, 500.0), 1548.0)
        c, s = math.cos(heading), math.sin(heading)
        # canvas -> frame: rotate about the camera position and centre it
        m = np.array([[c, s, 0.0], [-s, c, 0.0]])
        m[:, 2] = np.array([WIDTH / 2, HEIGHT / 2]) - m[:, :2] @ np.array([x, y])
        yield cv2.warpAffine(tile, m, (WIDTH, HEIGHT), flags=cv2.INTER_LINEAR)


def run(frontend: str, frames_dir: Path, names: list[str], in_memory: list[np.ndarray], dt: float) -> dict:
    fe = make_frontend(frontend)
    for i, img in enumerate(in_memory[:5]):  # warm-up
        fe.process(img, i * dt)
    fe.reset()
    t0 = _clock()
    ok = 0
    for i, img in enumerate(in_memory):
        ok += fe.process(img, i * dt).ok
    excluded = _clock() - t0

    fe = make_frontend(frontend)
    rss = []
    t0 = _clock()
    for i, name in enumerate(names):
        img = cv2.imread(str(frames_dir / name), cv2.IMREAD_GRAYSCALE)
        fe.process(img, i * dt)
        if i % 100 == 0 or i == len(names) - 1:
            rss.append(_rss_mb())
    included = _clock() - t0

    t0 = _clock()
    for name in names:
        cv2.imread(str(frames_dir / name), cv2.IMREAD_GRAYSCALE)
    decode = _clock() - t0
    n = len(names)
    return {
        "fps_excluded": n / excluded,
        "fps_included": n / included,
        "ms_frontend": excluded / n * 1e3,
        "ms_decode": decode / n * 1e3,
        "ok": ok / max(n - 1, 1),
        "rss_start": rss[1] if len(rss) > 1 else rss[0],
        "rss_end": rss[-1],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=400, help="frames in the generated drive (default 400)")
    parser.add_argument("--frontend", nargs="+", default=["klt", "features"], help="frontends to time")
    parser.add_argument("--max-speed", type=float, default=100.0, help="fastest image motion [px/frame]")
    parser.add_argument("--png-compression", type=int, default=3, help="PNG compression level 0-9 (OpenCV default 3)")
    args = parser.parse_args()
    cv2.setNumThreads(1)

    with tempfile.TemporaryDirectory(prefix="bench_frontends_") as tmp:
        folder = Path(tmp)
        names, in_memory = [], []
        for i, img in enumerate(drive_frames(args.frames, args.max_speed)):
            name = f"{i:06d}.png"
            cv2.imwrite(str(folder / name), img, [cv2.IMWRITE_PNG_COMPRESSION, args.png_compression])
            names.append(name)
            in_memory.append(img)
        size_kb = sum((folder / n).stat().st_size for n in names) / len(names) / 1e3
        print(f"{args.frames} frames {WIDTH}x{HEIGHT}, PNG level {args.png_compression} ({size_kb:.0f} kB/frame), "
              f"OpenCV {cv2.__version__}, 1 thread")
        print(f"{'frontend':10s} {'fps (decode excl.)':>18s} {'fps (decode incl.)':>18s} {'ms/frame':>9s} "
              f"{'decode ms':>9s} {'ok %':>6s} {'RSS MB start->end':>18s}")
        for frontend in args.frontend:
            r = run(frontend, folder, names, in_memory, 0.05)
            print(f"{frontend:10s} {r['fps_excluded']:18.0f} {r['fps_included']:18.0f} {r['ms_frontend']:9.2f} "
                  f"{r['ms_decode']:9.2f} {100 * r['ok']:6.1f} {r['rss_start']:8.1f} -> {r['rss_end']:6.1f}")


if __name__ == "__main__":
    main()
