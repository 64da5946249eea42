"""Per-call latency and estimate age of :class:`~fusion_vo.backends.streaming.StreamingFusion`.

A generated drive of ``--seconds`` (default 60 s: camera increments at 20 Hz, wheel encoders at 50 Hz,
IMU at 200 Hz, :mod:`fusion_vo.sensors.synthetic`) is fed in real-time order, the camera's increments
arriving ``--camera-delay`` seconds (default 0.15) after their time as a frontend delivers them. After
every sample the caller asks for ``current_estimate()``, as a controller would. Printed per backend:

* latency percentiles (p50, p90, p99, max) of one call ``add_*(sample)`` + ``current_estimate()``
  (iSAM2 twice: its updates on the caller's thread, and on a worker thread with ``background=True``),
  in wall-clock milliseconds (what the caller's thread waits), and the p99 and max of the same calls'
  CPU time (this thread's), which other processes on a shared machine do not inflate;
* the age of the returned pose behind the newest measurement (median and max), beside the age of
  the processed state (``processed_estimate()``, the pose the reorder window holds back);
* position error of the returned pose against the truth at the newest measurement time.

Baseline, measured in the same run and order: plain wheel dead reckoning (pose integrated from each
tick pair, returned after every sample), the cheapest possible "pose for now". The backends run
interleaved ``--repeat`` times (default 3) and the figures pool the repeats, so load on a shared
machine affects all of them alike; the machine's load average before and after is printed. Targets:
p99 <= 2 ms and worst <= 10 ms per call.

The worst call is usually one of CPython's full garbage collections, which scan every tracked object of
the process (about 100 000 after importing numpy, scipy, GTSAM and filterpy and making the drive: some
40 ms), whatever the call was doing. ``--gc-freeze`` calls :func:`gc.freeze` after start-up, as a live
process should; the collections then scan only what was made since.
Usage::

    python benchmarks/bench_latency.py [--seconds 60] [--repeat 3] [--camera-delay 0.15] [--gc-freeze]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # single-threaded numerical libraries (before numpy loads)

import argparse
import gc
import time

import numpy as np

from fusion_vo.backends import FusionConfig, SensorStreams, StreamingFusion
from fusion_vo.backends.streaming import time_ordered_messages
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


def messages(s, camera_delay: float) -> list:
    """(arrival time, kind, message) in arrival order."""
    streams = SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)
    return time_ordered_messages(streams, camera_delay)


def truth_at(s, t: np.ndarray) -> np.ndarray:
    tr = s.truth
    return np.column_stack([np.interp(t, tr.t, tr.xyyaw[:, 0]), np.interp(t, tr.t, tr.xyyaw[:, 1])])


def run_backend(s, msgs, backend: str, window: float, background: bool = False) -> dict:
    fusion = StreamingFusion(backend, FusionConfig(reorder_window=window), ["camera", "wheel", "imu"],
                             wheel_config=s.wheel.config, imu_noise=s.imu.noise, background=background)
    lat, cpu, age, age_held, t_new, pos = [], [], [], [], [], []
    newest = -np.inf
    clock, cpu_clock = time.perf_counter, time.thread_time
    for t, kind, m in msgs:
        add = getattr(fusion, f"add_{kind}")
        c0, p0 = clock(), cpu_clock()
        add(m)
        est = fusion.current_estimate()
        lat.append(clock() - c0)
        cpu.append(cpu_clock() - p0)
        t_m = m.t1 if kind == "visual" else m.t
        newest = max(newest, t_m)
        if est is not None:
            held = fusion.processed_estimate()
            age.append(newest - est.t)
            age_held.append(newest - held.t)
            t_new.append(newest)
            pos.append(est.pose[:2])
    result = fusion.finish()
    name = "ekf" if backend == "ekf" else "gtsam_online"
    err = np.linalg.norm(np.array(pos) - truth_at(s, np.array(t_new)), axis=1)
    late = sum(c.late for c in result.counts[name].values())
    return {"lat": np.array(lat), "cpu": np.array(cpu), "age": np.array(age), "age_held": np.array(age_held), "err": err,
            "late": late, "rewinds": fusion.rewinds}


def _wrap32(d: int) -> int:
    """Tick difference across a 32-bit counter wrap."""
    return (int(d) + 2**31) % 2**32 - 2**31


def run_dead_reckoning(s, msgs) -> dict:
    cfg = s.wheel.config
    per_tick = 2.0 * np.pi / cfg.ticks_per_revolution
    pose = np.zeros(3)
    prev = None
    lat, cpu, t_new, pos = [], [], [], []
    clock, cpu_clock = time.perf_counter, time.thread_time
    for t, kind, m in msgs:
        c0, p0 = clock(), cpu_clock()
        if kind == "wheel":
            if prev is not None:
                dl = _wrap32(m.left - prev[0]) * per_tick * cfg.wheel_radius_left
                dr = _wrap32(m.right - prev[1]) * per_tick * cfg.wheel_radius_right
                d, dyaw = 0.5 * (dl + dr), (dr - dl) / cfg.wheel_base
                mid = pose[2] + 0.5 * dyaw
                pose = pose + np.array([d * np.cos(mid), d * np.sin(mid), dyaw])
            prev = (m.left, m.right)
            t_last = m.t
        out = pose.copy()
        lat.append(clock() - c0)
        cpu.append(cpu_clock() - p0)
        if prev is not None:
            t_new.append(t_last)
            pos.append(out[:2])
    err = np.linalg.norm(np.array(pos) - truth_at(s, np.array(t_new)), axis=1)
    return {"lat": np.array(lat), "cpu": np.array(cpu), "err": err}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="length of the drive [s]")
    parser.add_argument("--repeat", type=int, default=3, help="interleaved repetitions")
    parser.add_argument("--camera-delay", type=float, default=0.15, help="camera increments arrive this late [s]")
    parser.add_argument("--gc-freeze", action="store_true",
                        help="call gc.freeze() after start-up (imports, the drive, the warm-up), as a live process "
                             "should: CPython's full collections then no longer scan the start-up objects")
    parser.add_argument("--window", type=float, default=0.05,
                        help="reorder window of the EKF [s]; iSAM2 uses camera-delay + 0.05 (it cannot rewind)")
    args = parser.parse_args()
    load_before = os.getloadavg()
    s = synthetic_streams(SyntheticOptions(duration=args.seconds, visual_scale=1.02), seed=1)
    msgs = messages(s, args.camera_delay)
    windows = {"ekf": args.window, "gtsam": args.camera_delay + 0.05, "gtsam background": args.camera_delay + 0.05}
    runs: dict[str, list] = {"dead reckoning": [], "ekf": [], "gtsam": [], "gtsam background": []}
    for backend in ("ekf", "gtsam"):  # warm up: imports and first-call caches (a live stack starts once)
        run_backend(s, msgs[:500], backend, 0.2)
    if args.gc_freeze:
        gc.collect()
        gc.freeze()
    print(f"objects the garbage collector tracks: {len(gc.get_objects())}"
          f"{f' (+ {gc.get_freeze_count()} frozen)' if args.gc_freeze else ''}")
    for _ in range(args.repeat):
        runs["dead reckoning"].append(run_dead_reckoning(s, msgs))
        for name in ("ekf", "gtsam", "gtsam background"):
            backend = name.split()[0]
            runs[name].append(run_backend(s, msgs, backend, windows[name], background=name.endswith("background")))
    load_after = os.getloadavg()
    print(f"load average (1 min) {load_before[0]:.1f} before, {load_after[0]:.1f} after, on {os.cpu_count()} cores")
    print(f"{args.seconds:.0f} s drive, {len(msgs)} samples (camera 20 Hz arriving {args.camera_delay * 1e3:.0f} ms "
          f"late, wheels 50 Hz, IMU 200 Hz), {args.repeat} interleaved runs; latency = add_*() + current_estimate()")
    print(f"{'':>16} {'window':>7} {'p50 ms':>7} {'p90 ms':>7} {'p99 ms':>7} {'max ms':>7} {'age p50/max ms':>15} "
          f"{'held-back age p50 ms':>21} {'err p50 cm':>10} {'late':>5} {'rewinds':>8} {'CPU p99/max ms':>15}")
    for name, rs in runs.items():
        lat = np.concatenate([r["lat"] for r in rs]) * 1e3
        err = np.concatenate([r["err"] for r in rs]) * 100
        cpu = np.concatenate([r["cpu"] for r in rs]) * 1e3
        cpu_txt = f"{np.percentile(cpu, 99):.3f} / {cpu.max():.3f}"
        p50, p90, p99 = np.percentile(lat, [50, 90, 99])
        if name == "dead reckoning":
            print(f"{name:>16} {'-':>7} {p50:>7.3f} {p90:>7.3f} {p99:>7.3f} {lat.max():>7.3f} {'0 / 0':>15} {'-':>21} "
                  f"{np.median(err):>10.2f} {'-':>5} {'-':>8} {cpu_txt:>15}")
            continue
        age = np.concatenate([r["age"] for r in rs]) * 1e3
        held = np.concatenate([r["age_held"] for r in rs]) * 1e3
        late = sum(r["late"] for r in rs) // len(rs)
        rewinds = sum(r["rewinds"] for r in rs) // len(rs)
        print(f"{name:>16} {windows[name]:>7.2f} {p50:>7.3f} {p90:>7.3f} {p99:>7.3f} {lat.max():>7.3f} "
              f"{f'{np.median(age):.1f} / {age.max():.1f}':>15} {np.median(held):>21.1f} {np.median(err):>10.2f} "
              f"{late:>5d} {rewinds:>8d} {cpu_txt:>15}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
