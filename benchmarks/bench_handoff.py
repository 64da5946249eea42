"""What the frontends' hand-off thread saves: visual odometry with two threads, with and without it.

With two or more threads and ``odometry.handoff`` (default false), :func:`fusion_vo.odometry.run_visual_odometry`
gives a frontend that has a ``set_executor`` method one more thread for work it can hand off (KLT: the
next frame's reference warped by the predicted motion; features: the reference warped for the refinement
while the exposure change is measured). This script runs each frontend over a recording (default: the
standard random60 drive, generated) with two threads, with that thread and without it,
interleaved and alternating which goes first, and prints per run the wall time per frame, the CPU time
per frame of the whole process and of the calling (tracking) thread, and the load average. It then
checks that both ways gave the same increments, bit for bit. Usage::

    python benchmarks/bench_handoff.py [--sequence SEQ] [--frames N] [--frontend klt,features] [--repeats 4]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fusion_vo.benchmark import first_frames
from fusion_vo.cli.bench import frame_count, frontend_list
from fusion_vo.cli.arguments import positive_int
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.simulation.standard import make_standard


def timed_run(sequence: Path, frontend: str, handoff: bool):
    """One two-thread run: (result, wall ms per frame, CPU ms per frame, calling thread's CPU ms per frame)."""
    rec = Recording(sequence)
    n = len(rec)
    cpu, own = time.process_time(), time.thread_time()
    result = run_visual_odometry(rec, OdometryConfig(frontend=frontend, threads=2, handoff=handoff))
    cpu, own = time.process_time() - cpu, time.thread_time() - own
    return result, 1e3 * result.elapsed_s / n, 1e3 * cpu / n, 1e3 * own / n


def same(a, b) -> bool:
    """Whether two results have the same statuses, increments and track, bit for bit."""
    return a.status == b.status and len(a.increments) == len(b.increments) and all(
        np.array_equal(x.delta, y.delta) and np.array_equal(x.covariance, y.covariance)
        for x, y in zip(a.increments, b.increments)) and np.array_equal(a.track.xyyaw, b.track.xyyaw)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequence", help="recording (default: the standard random60, generated)")
    ap.add_argument("--frames", type=frame_count, help="the first N frames only")
    ap.add_argument("--frontend", type=frontend_list, default=["klt", "features"])
    ap.add_argument("--repeats", type=positive_int, default=4)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-handoff-") as tmp:
        seq = Path(args.sequence) if args.sequence else make_standard("random60", Path(tmp) / "random60")
        if args.frames is not None and args.frames < len(Recording(seq)):
            seq = first_frames(seq, args.frames, Path(tmp) / "first")
        print(f"{seq}: {len(Recording(seq))} frames, two threads, {args.repeats} interleaved repeats; "
              f"load average {os.getloadavg()[0]:.2f} before", flush=True)
        figures: dict = {}
        identical = {}
        for fe in args.frontend:  # warm-up: what loads on first use is not timed
            run_visual_odometry(Recording(seq), OdometryConfig(frontend=fe, threads=2),
                                frames=Recording(seq).frames(stop=20))
        for r in range(args.repeats):
            for fe in args.frontend:
                results = {}
                for handoff in ((False, True) if r % 2 == 0 else (True, False)):
                    result, wall, cpu, own = timed_run(seq, fe, handoff)
                    results[handoff] = result
                    figures.setdefault((fe, handoff), []).append((wall, cpu, own))
                    print(f"repeat {r + 1}: {fe}, hand-off thread {'on' if handoff else 'off'}: wall {wall:.2f} ms, "
                          f"CPU {cpu:.2f} ms, calling thread {own:.2f} ms per frame; load "
                          f"{os.getloadavg()[0]:.2f}", flush=True)
                identical[fe] = identical.get(fe, True) and same(results[False], results[True])
    print()
    print(f"load average {os.getloadavg()[0]:.2f} after; median (range) over the repeats, per frame:")
    print()
    print("| frontend, two threads | hand-off thread | wall time | CPU time, all threads | CPU time, calling "
          "thread | results |")
    print("|---|---|---|---|---|---|")
    for (fe, handoff), values in figures.items():
        cells = []
        for i in range(3):
            column = [v[i] for v in values]
            cells.append(f"{statistics.median(column):.2f} ({min(column):.2f}-{max(column):.2f}) ms")
        verdict = "identical bit for bit" if identical[fe] else "DIFFERENT"
        print(f"| {fe} | {'on' if handoff else 'off'} | {' | '.join(cells)} | {verdict} |")
    return 0 if all(identical.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
