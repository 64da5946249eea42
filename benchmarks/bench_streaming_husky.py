"""Streaming fusion against batch fusion on a real log: robot_localization's Husky ``test1.bag``.

The bag (395 s, 359 m; IMU at 30 Hz with an AHRS orientation, wheel odometry at 10 Hz, GPS at 2.5 Hz,
not fused) is imported with the IMU mounting of robot_localization's launch file, and its wheel odometry
and IMU are fused

* in batch (:func:`fusion_vo.backends.fuse`: the online EKF and iSAM2 tracks; the whole-log
  heading-consistency monitor drops this IMU's drifting AHRS heading for the whole log);
* streaming, every sample fed in time order through :class:`~fusion_vo.backends.StreamingFusion`, with
  the causal heading monitor (:mod:`fusion_vo.backends.live_monitor`) and the odometry's delay behind the
  gyro estimated from the samples so far (:class:`~fusion_vo.sensors.sync.TwistDelay`, the default);
  without that correction (``sync_odometry: false``); and without the monitor (``monitor: false``).

Printed per track: the RMS and maximum horizontal distance to the GPS fixes after the least-squares SE(2)
alignment (the fixes have σ ≈ 0.9 m), the median and 90th percentile distance to the batch online
track of the same backend, and the monitor's notes. Baseline in the same run: the raw wheel odometry
dead-reckoned.

Usage::

    python benchmarks/bench_streaming_husky.py [BAG] [--backend ekf|gtsam|all]
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.measurements import PoseData
from fusion_vo.recording import Recording
from fusion_vo.recording.rosbag import import_bag, parse_static_tf
from fusion_vo.sensors.wheel import twist_to_travel, wheel_track

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "examples"))

from husky_gps import DEFAULT_BAG, HUSKY_IMU_TF, gps_errors  # noqa: E402


def distance(a: PoseData, b: PoseData) -> np.ndarray:
    """Distances [m] between ``a``'s poses and ``b`` interpolated at their times (same frame, no alignment)."""
    inside = (a.t >= b.t[0]) & (a.t <= b.t[-1])
    q = np.column_stack([np.interp(a.t[inside], b.t, b.xyyaw[:, i]) for i in range(2)])
    return np.linalg.norm(a.xyyaw[inside, :2] - q, axis=1)


def stream(streams: SensorStreams, backend: str, config: FusionConfig):
    fusion = streaming_for(streams, backend, config)
    t0 = time.process_time()
    for _, kind, m in time_ordered_messages(streams):
        getattr(fusion, f"add_{kind}")(m)
    result = fusion.finish()
    return result, time.process_time() - t0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", nargs="?", default=str(DEFAULT_BAG))
    parser.add_argument("--backend", choices=["ekf", "gtsam", "all"], default="all")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    with tempfile.TemporaryDirectory() as tmp:
        seq = Path(tmp) / "husky"
        import_bag(args.bag, seq, static_tfs=[parse_static_tf(HUSKY_IMU_TF)], overwrite=True)
        rec = Recording(seq)
        odom, imu, gps = rec.odom(), rec.imu(), rec.gps()
    t_gps, enu = gps.t, gps.enu[:, :2]
    streams = SensorStreams(odom=odom, imu=imu)
    rows = [("raw wheel odometry (baseline)", wheel_track(twist_to_travel(odom)), None, "")]
    notes = []
    for backend in (["ekf", "gtsam"] if args.backend == "all" else [args.backend]):
        name = "ekf" if backend == "ekf" else "gtsam_online"
        batch = fuse(streams, backend, FusionConfig())
        ref = batch.trajectories[name]
        rows.append((f"batch {name}", ref, ref, ""))
        for label, cfg in (("streaming, live monitor", FusionConfig()),
                           ("streaming, twist delay not corrected", FusionConfig(sync_odometry=False)),
                           ("streaming, no monitor", FusionConfig(monitor=False))):
            result, cpu = stream(streams, backend, cfg)
            rows.append((f"{label}: {name}", result.trajectories[name], ref, f"{cpu:.1f} s CPU"))
            notes += [f"{label}, {name}: {n}" for n in result.notes
                      if "monitor" in n or "behind the gyro" in n or "late" in n]
    print(f"{'track':40s} {'GPS RMS m':>9s} {'GPS max m':>9s} {'to batch p50 m':>14s} {'p90 m':>7s}  time")
    for label, track, ref, extra in rows:
        err = gps_errors(track, t_gps, enu)
        d = distance(track, ref) if ref is not None else None
        to_batch = f"{np.median(d):14.2f} {np.percentile(d, 90):7.2f}" if d is not None else f"{'–':>14s} {'–':>7s}"
        print(f"{label:40s} {np.sqrt(np.mean(err**2)):9.2f} {err.max():9.2f} {to_batch}  {extra}")
    for n in notes:
        print("  " + n)
    return 0


if __name__ == "__main__":
    sys.exit(main())
