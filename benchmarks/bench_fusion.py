"""Speed of the fusion backends on generated measurement streams, single-threaded.

A drive of ``--seconds`` (default 60 s) with visual increments at 20 Hz, wheel encoders at 50 Hz and a
gyro at 200 Hz (:mod:`fusion_vo.sensors.synthetic`, with a 2 % camera-height error so self-calibration
is active) is fused by:

* ``ekf``            timeline merging + filter + Rauch–Tung–Striebel smoother;
* ``gtsam batch``    timeline merging + graph construction + Levenberg–Marquardt + marginal covariances;
* ``gtsam iSAM2``    one incremental update per camera frame (with the newest pose's covariance).

and again on a drive ten times as long, to show the cost is linear in length. Times are CPU times of
this process (single-threaded numerical libraries), so the figures describe one core even on a shared
machine. Targets: EKF >= 150x faster than real time, GTSAM batch >= 300x, iSAM2 < 0.5 ms per camera frame;
the split of the GTSAM batch time (merging the streams, building the graph, solving, marginal covariances)
is printed too.
Usage::

    python benchmarks/bench_fusion.py [--seconds 60] [--scale 10]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # single-threaded numerical libraries (before numpy loads)

import argparse
import time

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


def _cpu(fn):
    t0 = time.process_time()
    out = fn()
    return time.process_time() - t0, out


def measure(seconds: float) -> dict:
    s = synthetic_streams(SyntheticOptions(duration=seconds, visual_scale=1.02), seed=1)
    streams = SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)
    frames = len(s.visual)
    batch_only = FusionConfig.from_dict({"graph": {"online": False}})
    online_only = FusionConfig.from_dict({"graph": {"batch": False}})
    fuse(streams, "gtsam", FusionConfig.from_dict({"graph": {"batch": False, "online": False}}))  # warm up imports
    ekf_s, _ = _cpu(lambda: fuse(streams, "ekf"))
    gtsam_s, batch = _cpu(lambda: fuse(streams, "gtsam", batch_only))
    isam_ms = fuse(streams, "gtsam", online_only).timing["gtsam_online_per_node_ms"]
    split = {k: batch.timing.get(k, 0.0) for k in ("timeline", "gtsam_build", "gtsam_solve", "gtsam_marginals")}
    return {"seconds": seconds, "frames": frames, "ekf": ekf_s, "gtsam": gtsam_s, "isam_ms": isam_ms, "split": split}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="length of the base drive [s]")
    parser.add_argument("--scale", type=int, default=10, help="length factor of the long drive")
    args = parser.parse_args()
    rows = [measure(args.seconds), measure(args.seconds * args.scale)]
    print(f"{'drive':>8} {'frames':>7} {'EKF [s]':>8} {'x real':>7} {'GTSAM [s]':>10} {'x real':>7} {'iSAM2 [ms/frame]':>17}")
    for r in rows:
        print(f"{r['seconds']:>7.0f}s {r['frames']:>7d} {r['ekf']:>8.3f} {r['seconds'] / r['ekf']:>7.0f} "
              f"{r['gtsam']:>10.3f} {r['seconds'] / r['gtsam']:>7.0f} {r['isam_ms']:>17.3f}")
    for r in rows:
        sp = r["split"]
        print(f"GTSAM batch on {r['seconds']:.0f} s: streams merged {sp['timeline']:.3f} s, graph built {sp['gtsam_build']:.3f} s, "
              f"solved {sp['gtsam_solve']:.3f} s, marginal covariances {sp['gtsam_marginals']:.3f} s")
    a, b = rows
    print(f"cost ratio {args.scale}x length: EKF {b['ekf'] / a['ekf']:.1f}x, GTSAM batch {b['gtsam'] / a['gtsam']:.1f}x, "
          f"iSAM2 per frame {b['isam_ms'] / a['isam_ms']:.2f}x")
    ok = a["seconds"] / a["ekf"] >= 150 and a["seconds"] / a["gtsam"] >= 300 and a["isam_ms"] < 0.5
    print("targets (EKF >= 150x real time, GTSAM batch >= 300x, iSAM2 < 0.5 ms/frame):", "met" if ok else "NOT met")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
