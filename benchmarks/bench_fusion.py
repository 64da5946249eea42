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
``--repeat N`` measures each drive N times (figures: the median, and every run); the split of the batch on
the base drive is then printed with the wall time beside the CPU time of each stage (streams merged, graph
built, factors grouped and laid out, Levenberg–Marquardt, marginal covariances), and ``--profile N``
prints the N functions with the largest cumulative time of one batch run (cProfile).

Usage::

    nice -n -15 python benchmarks/bench_fusion.py [--seconds 60] [--scale 10] [--repeat 3] [--profile 25] [--visual-frame-error F]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # single-threaded numerical libraries (before numpy loads)

import argparse
import cProfile
import pstats
import statistics
import sys
import time

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


def _cpu(fn):
    t0 = time.process_time()
    out = fn()
    return time.process_time() - t0, out


def _streams(seconds: float) -> SensorStreams:
    s = synthetic_streams(SyntheticOptions(duration=seconds, visual_scale=1.02), seed=1)
    return SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)


BATCH_ONLY = {"graph": {"online": False}}


def measure(seconds: float, repeat: int = 1, options: dict | None = None) -> dict:
    """CPU seconds of each backend on a generated drive of ``seconds`` (median of ``repeat`` runs); ``options``:
    top-level fusion options for every backend (e.g. ``visual_frame_error``)."""
    options = options or {}
    streams = _streams(seconds)
    frames = len(streams.visual)
    ekf = FusionConfig.from_dict(options)
    batch_only = FusionConfig.from_dict({**BATCH_ONLY, **options})
    online_only = FusionConfig.from_dict({"graph": {"batch": False}, **options})
    fuse(streams, "gtsam", FusionConfig.from_dict({"graph": {"batch": False, "online": False}}))  # warm up imports
    runs = []
    for _ in range(repeat):  # the backends one after the other, repeated
        ekf_s, _ = _cpu(lambda: fuse(streams, "ekf", ekf))
        gtsam_s, batch = _cpu(lambda: fuse(streams, "gtsam", batch_only))
        isam_ms = fuse(streams, "gtsam", online_only).timing["gtsam_online_per_node_ms"]
        split = {k: batch.timing.get(k, 0.0) for k in ("timeline", "gtsam_build", "gtsam_solve", "gtsam_marginals")}
        runs.append({"ekf": ekf_s, "gtsam": gtsam_s, "isam_ms": isam_ms, "split": split})
    med = statistics.median
    out = {"seconds": seconds, "frames": frames, "runs": runs}
    for key in ("ekf", "gtsam", "isam_ms"):
        out[key] = med(r[key] for r in runs)
    out["split"] = {k: med(r["split"][k] for r in runs) for k in runs[0]["split"]}
    return out


def stage_split(seconds: float, repeat: int) -> list[tuple[str, float, float]]:
    """Wall and CPU seconds of the batch's stages (median of ``repeat`` runs), from timers wrapped around
    the functions that do them."""
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
    from bench_run import Stages
    from fusion_vo.backends import batch, chain, graph

    streams = _streams(seconds)
    config = FusionConfig.from_dict(BATCH_ONLY)
    saved = {(m, a): getattr(m, a) for m, a in ((batch, "build_intervals"), (graph, "run_graph"), (graph, "group"),
                                                 (chain, "ChainProblem"), (chain, "levenberg_marquardt"),
                                                 (chain, "pose_marginals"))}
    names = {"build_intervals": "streams merged", "run_graph": "graph built (and the rest of run_graph)",
             "group": "factors grouped into arrays", "ChainProblem": "system laid out (chain.ChainProblem)",
             "levenberg_marquardt": "Levenberg-Marquardt", "pose_marginals": "marginal covariances"}
    runs = []
    try:
        for _ in range(repeat):
            stages = Stages()
            for module, attribute in saved:
                setattr(module, attribute, saved[(module, attribute)])
                stages.wrap(module, attribute, names[attribute])
            fuse(streams, "gtsam", config)
            stages.restore()
            runs.append(stages)
    finally:
        for (module, attribute), value in saved.items():
            setattr(module, attribute, value)
    med = statistics.median
    return [(name, med(r.wall.get(name, 0.0) for r in runs), med(r.cpu.get(name, 0.0) for r in runs))
            for name in names.values()]


def profile(seconds: float, top: int) -> None:
    streams = _streams(seconds)
    config = FusionConfig.from_dict(BATCH_ONLY)
    fuse(streams, "gtsam", config)
    prof = cProfile.Profile()
    prof.enable()
    fuse(streams, "gtsam", config)
    prof.disable()
    print(f"\ncProfile of one GTSAM batch run on {seconds:.0f} s (cumulative; the profiler's own overhead inflates it):")
    pstats.Stats(prof, stream=sys.stdout).sort_stats("cumulative").print_stats(top)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="length of the base drive [s]")
    parser.add_argument("--scale", type=int, default=10, help="length factor of the long drive")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each measurement (the median is shown)")
    parser.add_argument("--profile", type=int, default=0, metavar="N", help="print the N costliest functions of a batch run")
    parser.add_argument("--visual-frame-error", type=float, default=0.0,
                        help="fusion.visual_frame_error of every backend (default 0, as the default configuration)")
    args = parser.parse_args()
    print(f"load average {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    options = {"visual_frame_error": args.visual_frame_error} if args.visual_frame_error else {}
    rows = [measure(args.seconds, args.repeat, options), measure(args.seconds * args.scale, args.repeat, options)]
    print(f"{'drive':>8} {'frames':>7} {'EKF [s]':>8} {'x real':>7} {'GTSAM [s]':>10} {'x real':>7} {'iSAM2 [ms/frame]':>17}")
    for r in rows:
        print(f"{r['seconds']:>7.0f}s {r['frames']:>7d} {r['ekf']:>8.3f} {r['seconds'] / r['ekf']:>7.0f} "
              f"{r['gtsam']:>10.3f} {r['seconds'] / r['gtsam']:>7.0f} {r['isam_ms']:>17.3f}")
    if args.repeat > 1:
        for r in rows:
            print(f"  {r['seconds']:.0f} s, every run: EKF " + ", ".join(f"{x['ekf']:.3f}" for x in r["runs"])
                  + " s; GTSAM batch " + ", ".join(f"{x['gtsam']:.3f}" for x in r["runs"])
                  + " s; iSAM2 " + ", ".join(f"{x['isam_ms']:.3f}" for x in r["runs"]) + " ms/frame")
    for r in rows:
        sp = r["split"]
        print(f"GTSAM batch on {r['seconds']:.0f} s: streams merged {sp['timeline']:.3f} s, graph built {sp['gtsam_build']:.3f} s, "
              f"solved {sp['gtsam_solve']:.3f} s, marginal covariances {sp['gtsam_marginals']:.3f} s")
    a, b = rows
    print(f"cost ratio {args.scale}x length: EKF {b['ekf'] / a['ekf']:.1f}x, GTSAM batch {b['gtsam'] / a['gtsam']:.1f}x, "
          f"iSAM2 per frame {b['isam_ms'] / a['isam_ms']:.2f}x")
    print(f"\nstages of the GTSAM batch on {args.seconds:.0f} s ({'median of %d runs' % args.repeat if args.repeat > 1 else 'one run'}):")
    print(f"  {'stage':42s} {'wall [s]':>9s} {'CPU [s]':>9s}")
    for name, wall, cpu in stage_split(args.seconds, args.repeat):
        print(f"  {name:42s} {wall:9.4f} {cpu:9.4f}")
    if args.profile:
        profile(args.seconds, args.profile)
    ok = a["seconds"] / a["ekf"] >= 150 and a["seconds"] / a["gtsam"] >= 300 and a["isam_ms"] < 0.5
    print("targets (EKF >= 150x real time, GTSAM batch >= 300x, iSAM2 < 0.5 ms/frame):", "met" if ok else "NOT met")
    print(f"load average {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
