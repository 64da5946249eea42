"""CPU time of a streaming run, this checkout against another one, interleaved.

A generated drive (``--seconds``, default 20: camera increments at 20 Hz arriving 150 ms late, wheels
50 Hz, IMU 200 Hz; the drive of ``bench_latency.py``) is fed through
:class:`~fusion_vo.backends.StreamingFusion` in arrival order, ``current_estimate()`` after every
sample, and the process CPU time of the whole feed is printed. Each run is a fresh Python process that
imports ``fusion_vo`` from the given checkout; the two checkouts alternate ``--repeat`` times per
backend, so load on a shared machine affects both alike. The baseline checkout is any other tree of the
repository, e.g. ``git archive main | tar -x -C /tmp/base``.

Usage::

    python benchmarks/bench_stream_cpu.py --base /tmp/base [--seconds 20] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

_CHILD = """
import logging, sys, time
logging.disable(logging.WARNING)
root, backend, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
sys.path[:0] = [root, root + "/benchmarks"]
import fusion_vo
assert fusion_vo.__file__.startswith(root), fusion_vo.__file__
from bench_latency import messages
from fusion_vo.backends import FusionConfig, StreamingFusion
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams
s = synthetic_streams(SyntheticOptions(duration=seconds, visual_scale=1.02), seed=1)
msgs = messages(s, 0.15)
f = StreamingFusion(backend, FusionConfig(reorder_window=0.05 if backend == "ekf" else 0.2),
                    ["camera", "wheel", "imu"], wheel_config=s.wheel.config, imu_noise=s.imu.noise)
c = time.process_time()
for _, kind, m in msgs:
    getattr(f, "add_" + kind)(m)
    f.current_estimate()
f.finish()
print(time.process_time() - c)
"""


def cpu_seconds(root: Path, backend: str, seconds: float) -> float:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", _CHILD, str(root.resolve()), backend, str(seconds)],
                         capture_output=True, text=True, check=True, env=env)
    return float(out.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--base", required=True, help="the other checkout (its folder holds fusion_vo/)")
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    base = Path(args.base)
    if not (base / "fusion_vo").is_dir():
        print(f"bench_stream_cpu: error: {base} holds no fusion_vo/", file=sys.stderr)
        return 2
    print(f"load average (1 min) {os.getloadavg()[0]:.1f}; {args.seconds:.0f} s drive; CPU seconds base / this")
    for backend in ("ekf", "gtsam"):
        pairs = []
        for _ in range(args.repeat):
            pairs.append((cpu_seconds(base, backend, args.seconds), cpu_seconds(REPO, backend, args.seconds)))
        ratio = sum(b for _, b in pairs) / sum(a for a, _ in pairs)
        print(f"{backend:6s} " + ", ".join(f"{a:.2f} / {b:.2f}" for a, b in pairs) + f"  (this / base {ratio:.2f})")
    print(f"load average (1 min) {os.getloadavg()[0]:.1f} after")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
