"""Start-up and output cost of the command, beside a bare interpreter, measured in the same run.

Prints the wall time (median of the repeats) of:

* ``python -c pass`` (the interpreter alone) and ``python -c "import numpy, cv2"`` (the libraries every run needs);
* ``fusion-vo --help`` and ``fusion-vo run --help`` (they load neither numpy nor OpenCV);
* importing the EKF's libraries, filterpy and scipy.stats, beside numpy (what a camera-only run no longer
  loads: ``fusion_vo.backends`` loads its modules on first use, the EKF its libraries when it is built);
* the whole ``fusion-vo run SEQ --backend none --no-evaluate`` command, and the part of it spent outside
  visual odometry (start-up, imports, wheel dead reckoning, output writing);
* writing the visual odometry outputs (``vo.tum`` and ``velocities.csv``) of that run, in this process;
* the whole plain OpenCV script, ``python benchmarks/baseline_opencv.py SEQ``, as a command, interleaved
  with the ``fusion-vo run`` command above: the whole-command frame rates of both, side by side.

Usage::

    python benchmarks/bench_startup.py [--sequence SEQ] [--repeats 5]

Without ``--sequence`` the standard ``short`` recording (5 s) is generated.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def wall(argv: list[str], repeats: int) -> float:
    """Median wall time [s] of a command."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequence", help="recording for the run (default: generate the standard 'short')")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    py = sys.executable
    cli = [py, "-m", "fusion_vo.cli.main"]
    with tempfile.TemporaryDirectory(prefix="bench-startup-") as tmp:
        seq = args.sequence
        if seq is None:
            from fusion_vo.simulation.standard import make_standard

            seq = make_standard("short", Path(tmp) / "short")
        rows = [
            ("python -c pass", wall([py, "-c", "pass"], args.repeats)),
            ("python -c 'import numpy, cv2'", wall([py, "-c", "import numpy, cv2"], args.repeats)),
            ("fusion-vo --help", wall([*cli, "--help"], args.repeats)),
            ("fusion-vo run --help", wall([*cli, "run", "--help"], args.repeats)),
            ("python -c 'import numpy'", wall([py, "-c", "import numpy"], args.repeats)),
            ("python -c 'import numpy, filterpy.kalman, scipy.stats'",
             wall([py, "-c", "import numpy, filterpy.kalman, scipy.stats"], args.repeats)),
        ]
        out = Path(tmp) / "out"
        run = [*cli, "-q", "run", str(seq), "--out", str(out), "--backend", "none", "--no-evaluate"]
        plain = [py, str(Path(__file__).with_name("baseline_opencv.py")), str(seq)]
        total, inside, script = [], [], []
        for _ in range(args.repeats):
            start = time.perf_counter()
            subprocess.run(run, check=True, stdout=subprocess.DEVNULL)
            total.append(time.perf_counter() - start)
            inside.append(json.loads((out / "summary.json").read_text())["vo_seconds"])
            script.append(wall(plain, 1))
        frames = json.loads((out / "summary.json").read_text())["frames"]
        rows.append((f"fusion-vo run --backend none ({frames} frames)", statistics.median(total)))
        rows.append(("  of which outside visual odometry", statistics.median(t - v for t, v in zip(total, inside))))
        rows.append((f"python benchmarks/baseline_opencv.py ({frames} frames)", statistics.median(script)))
        ratios = [s_ / t for s_, t in zip(script, total)]

        from fusion_vo.odometry import OdometryConfig, run_visual_odometry
        from fusion_vo.pipeline import write_velocities
        from fusion_vo.recording import Recording, write_tum

        vo = run_visual_odometry(Recording(seq), OdometryConfig())
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            write_tum(Path(tmp) / "vo.tum", vo.track.t, vo.track.xyyaw)
            write_velocities(Path(tmp) / "velocities.csv", vo)
            times.append(time.perf_counter() - start)
        rows.append((f"writing vo.tum + velocities.csv ({frames} frames)", statistics.median(times)))
    print(f"load average {os.getloadavg()[0]:.1f} at the end")
    print("| what | wall time, median of %d |" % args.repeats)
    print("|---|---|")
    for name, seconds in rows:
        print(f"| {name} | {1000 * seconds:.0f} ms |")
    print(f"whole commands: fusion-vo run {frames / statistics.median(total):.0f} frames/s, plain script "
          f"{frames / statistics.median(script):.0f} frames/s; ratio {statistics.median(ratios):.2f} "
          f"({min(ratios):.2f}-{max(ratios):.2f}) between commands run next to each other")
    return 0


if __name__ == "__main__":
    sys.exit(main())
