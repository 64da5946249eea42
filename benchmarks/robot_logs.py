"""robot_localization's own test logs (no camera) fused with the default configuration, beside their baselines.

Jackal (``test2.bag``, 61 s, 84 m of odometry twist, IMU with orientation): ``fusion-vo import-bag`` with its
odometry and IMU topics, ``fusion-vo run --backend all``; each track is rotated so that its first heading is
the IMU's first AHRS yaw (robot_localization's world frame), and its final position is compared with the one
robot_localization's own test expects, (1.0206, 3.4292) within 0.138 m. Baselines in the same run: the raw
odometry (``wheel.tum``) and the odometry's speed along the IMU's 3-D orientation
(``fusion_vo.baseline.along_orientation``, no filter).

Husky (``test1.bag``, 395 s, 359 m, IMU at 30 Hz with an AHRS orientation, odometry at 10 Hz, GPS at 2.5 Hz):
imported with the IMU mounting of robot_localization's launch file, odometry and IMU fused (GPS is not: it is
the reference), every track scored against the fixes after the robust SE(2) alignment ``fusion-vo evaluate``
makes (RMS and largest distance; the fixes scatter with about 0.9 m sigma). Fused in batch, and streamed
sample by sample through ``StreamingFusion`` (the causal heading monitor, the odometry's delay behind the gyro
estimated from the samples so far), without that delay correction (``sync_odometry: false``), and without the
monitor (``monitor: false``), with each streamed track's distance to the batch online track of the same
backend. Baselines in the same run: the raw wheel odometry, and wheel + gyro dead reckoning with the gyro's
bias at standstill (``fusion_vo.baseline.wheel_gyro``; not causal: the standstill is late in the log).

Usage::

    python benchmarks/robot_logs.py [--skip-jackal] [--skip-husky] [--no-streaming] [--backend ekf|gtsam|all]
"""

from __future__ import annotations

import json
import logging
import sys
import time

import numpy as np

from common import FUSED, JACKAL_BAG, gps_rms, import_husky, parser, table, work_dir

from fusion_vo import baseline
from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.config import RunConfig
from fusion_vo.evaluation.io import read_tum
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData
from fusion_vo.pipeline import run_pipeline
from fusion_vo.recording import Recording
from fusion_vo.recording.rosbag import import_bag
from fusion_vo.sensors.gps import read_fixes
from fusion_vo.sensors.imu import read_imu
from fusion_vo.sensors.wheel import read_twist, twist_to_travel, wheel_track

#: robot_localization's expected final position of the Jackal and its tolerance [m]
RL_FINAL, RL_TOLERANCE = np.array([1.0206, 3.4292]), 0.138


def read_track(path) -> PoseData:
    traj = read_tum(path)
    return PoseData(np.asarray(traj.timestamps), np.column_stack([traj.positions_xyz[:, :2],
                                                                  se2.yaw_of_quaternion(traj.orientations_quat_wxyz)]))


def final_in_imu_frame(track: PoseData, yaw0: float) -> np.ndarray:
    """The track's final position from its start, turned so that its first heading is ``yaw0``."""
    d = yaw0 - track.xyyaw[0, 2]
    rot = np.array([[np.cos(d), -np.sin(d)], [np.sin(d), np.cos(d)]])
    return rot @ (track.xyyaw[-1, :2] - track.xyyaw[0, :2])


def jackal(root) -> None:
    seq, out = root / "jackal", root / "run_jackal"
    if not (seq / "imu0").is_dir():
        import_bag(JACKAL_BAG, seq, imu_topic="/imu/data", odom_topic="/jackal_velocity_controller/odom",
                   overwrite=True)
    run_pipeline(seq, out, RunConfig(backend="all", evaluate=False), force=True)
    rec = Recording(seq)
    yaw0 = float(se2.yaw_of_quaternion(read_imu(rec).orientation[:1])[0])
    rows = []
    for name in ("wheel", *FUSED):
        final = final_in_imu_frame(read_track(out / f"{name}.tum"), yaw0)
        rows.append([f"{name}" + (" (raw odometry, baseline)" if name == "wheel" else ""), final])
    plain = baseline.along_orientation(rec)
    rows.append(["odometry speed along the IMU's 3-D orientation (baseline)", plain.xyyaw[-1, :2] - plain.xyyaw[0, :2]])
    notes = [n for n in json.loads((out / "summary.json").read_text()).get("notes", []) if "inconsistent" in n]
    print(f"\nJackal test2.bag: final position against robot_localization's expected ({RL_FINAL[0]}, {RL_FINAL[1]}), "
          f"which its test holds within {RL_TOLERANCE} m")
    print(table(["track", "final position [m]", "distance from robot_localization's [m]"],
                [[label, f"({f[0]:.3f}, {f[1]:.3f})", f"{np.linalg.norm(f - RL_FINAL):.3f}"] for label, f in rows]))
    for n in notes:
        print("  monitor:", n)


def distance(a: PoseData, b: PoseData) -> np.ndarray:
    """Distances [m] between ``a``'s poses and ``b`` interpolated at their times (same frame, no alignment)."""
    inside = (a.t >= b.t[0]) & (a.t <= b.t[-1])
    q = np.column_stack([np.interp(a.t[inside], b.t, b.xyyaw[:, i]) for i in range(2)])
    return np.linalg.norm(a.xyyaw[inside, :2] - q, axis=1)


def stream(streams: SensorStreams, backend: str, config: FusionConfig):
    fusion = streaming_for(streams, backend, config)
    t0 = time.process_time()
    fusion.feed(time_ordered_messages(streams))
    result = fusion.finish()
    return result, time.process_time() - t0


def husky(root, backends: list[str], streaming: bool) -> None:
    rec = Recording(import_husky(root / "husky"))
    odom, imu, gps = read_twist(rec), read_imu(rec), read_fixes(rec)
    streams = SensorStreams(odom=odom, imu=imu)
    rows = [("raw wheel odometry (baseline)", wheel_track(twist_to_travel(odom)), None, ""),
            ("wheel + gyro dead reckoning, bias at standstill (baseline)", baseline.wheel_gyro(rec), None, "")]
    notes = []
    for backend in backends:
        t0 = time.process_time()
        result = fuse(streams, backend, FusionConfig())
        cpu = time.process_time() - t0
        online = "ekf" if backend == "ekf" else "gtsam_online"
        for name in (FUSED[:2] if backend == "ekf" else FUSED[2:]):
            rows.append((f"batch {name}", result.trajectories[name], None, f"{cpu:.1f} s CPU (both)"))
        notes += [f"batch {backend}: {n}" for n in result.notes if "inconsistent" in n or "behind the gyro" in n]
        if not streaming:
            continue
        reference = result.trajectories[online]
        for label, cfg in (("streaming, live monitor", FusionConfig()),
                           ("streaming, twist delay not corrected", FusionConfig(sync_odometry=False)),
                           ("streaming, no monitor", FusionConfig(monitor=False))):
            streamed, cpu = stream(streams, backend, cfg)
            rows.append((f"{label}: {online}", streamed.trajectories[online], reference, f"{cpu:.1f} s CPU"))
            notes += [f"{label}, {online}: {n}" for n in streamed.notes
                      if "monitor" in n or "behind the gyro" in n or "late" in n]
    out = []
    for label, track, ref, extra in rows:
        rms, worst = gps_rms(track, gps)
        d = distance(track, ref) if ref is not None else None
        out.append([label, f"{rms:.2f}", f"{worst:.2f}",
                    "–" if d is None else f"{np.median(d):.2f} / {np.percentile(d, 90):.2f}", extra])
    print(f"\nHusky test1.bag: {len(gps)} GPS fixes (not fused); errors against them after the robust SE(2) alignment [m]")
    print(table(["track", "RMS", "max", "to the batch online track, p50 / p90", "time"], out))
    for n in notes:
        print("  " + n)


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--skip-jackal", action="store_true")
    ap.add_argument("--skip-husky", action="store_true")
    ap.add_argument("--no-streaming", action="store_true", help="the Husky in batch only")
    ap.add_argument("--backend", choices=["ekf", "gtsam", "all"], default="all", help="Husky backends (default all)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    with work_dir(None, "robot-logs-") as root:
        if not args.skip_jackal:
            jackal(root)
        if not args.skip_husky:
            husky(root, ["ekf", "gtsam"] if args.backend == "all" else [args.backend], not args.no_streaming)
    return 0


if __name__ == "__main__":
    sys.exit(main())
