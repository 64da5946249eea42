"""Fuse a Husky's wheel odometry with its IMU and compare the tracks with its GPS fixes.

The recording is robot_localization's ``test1.bag`` (a Clearpath Husky driving about 360 m around a
parking lot: IMU at 30 Hz, wheel odometry at 10 Hz, GPS at 2.5 Hz). The script

1. imports the bag into a recording folder (``fusion_vo.recording.rosbag.import_bag``), with the IMU
   mounting of robot_localization's launch file (the IMU lies on its side);
2. dead-reckons the raw wheel odometry, and fuses wheel odometry with the IMU with the project's
   backends (``fusion_vo.backends.fuse``: EKF, RTS-smoothed EKF, GTSAM batch and iSAM2) with their
   default configuration, once with everything the IMU gives (gyro and its AHRS heading) and once
   with the gyro only; a plain wheel + gyro dead reckoning (``fusion_vo.baseline.wheel_gyro``: the gyro's
   heading less its bias at standstill, the wheels' distance) is printed as a baseline;
3. aligns each track to the GPS fixes in local East-North-Up with the least-squares rotation and
   translation on the plane (the odometry frame's heading relative to north is unknown), and prints the
   RMS and maximum horizontal distance to the fixes, the distance travelled, and the RMS error as a
   percentage of it.

The GPS fixes themselves have about 0.9 m standard deviation (the bag's covariance), so errors of a
metre or two are at the level of the reference. The AHRS heading of this IMU (a Microstrain 3DM-GX2
that robot_localization calls "slightly broken") strays from the gyro's by up to about 35 degrees in
the second half of the drive (a heading-dependent, hard-iron-like error; against the GPS course the
gyro is the right one); the backends' consistency monitor finds it contradicting the gyro and the
wheels from 180 s on and drops it there (it prints a note), keeping its first three minutes, whose
absolute heading pins the gyro's bias before the only standstill. The "gyro only" variant shows what
the tracks are without it. The Husky is skid-steered: its odometry reports about
four fifths of the turn rate the gyro measures, with an error that persists over a turn (the
backends model it as correlated, not white), and it is stamped about 0.39 s after the gyro, which
batch fusion estimates from the two yaw rates and corrects (it prints a note).

Usage::

    python examples/husky_gps.py [BAG] [--backend ekf|gtsam|all] [--keep DIR]

``BAG`` defaults to ``tests/data/robot_localization/test1.bag`` of the repository (BSD, see the
``LICENSE`` there).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fusion_vo import baseline
from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.errors import InputError
from fusion_vo.evaluation.metrics import gps_errors
from fusion_vo.measurements import PoseData
from fusion_vo.recording import Recording
from fusion_vo.recording.rosbag import import_bag, parse_static_tf
from fusion_vo.sensors.gps import read_fixes
from fusion_vo.sensors.imu import read_imu
from fusion_vo.sensors.wheel import read_twist, twist_to_travel, wheel_track

REPO = Path(__file__).resolve().parents[1]
DEFAULT_BAG = REPO / "tests" / "data" / "robot_localization" / "test1.bag"
#: base_link -> imu_link of robot_localization's test_ekf_localization_node_bag1.test
HUSKY_IMU_TF = "0 -0.3 0.52 -1.570796327 0 1.570796327 base_link imu_link"


def distance_travelled(rec: Recording) -> float:
    """Path length of the wheel odometry: the integral of ``|v_x|`` [m]."""
    odom = read_twist(rec)
    return float(np.sum(np.abs(odom.vx[:-1]) * np.diff(odom.t)))


#: fusion variants (default configuration otherwise): name -> use the AHRS heading
VARIANTS = {
    "gyro + AHRS": True,
    "gyro only": False,
}
#: fused trajectories in the order they are printed
TRAJECTORIES = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")


def fused_tracks(rec: Recording, backend: str) -> tuple[dict[str, PoseData], list[str]]:
    """Wheel odometry fused with the IMU by the backends, for each of :data:`VARIANTS`.

    Returns the tracks (named ``"<variant>: <trajectory>"``) and notes on what ran and how long it took.
    """
    odom, imu = read_twist(rec), read_imu(rec)
    tracks: dict[str, PoseData] = {}
    notes: list[str] = []
    for variant, ahrs in VARIANTS.items():
        streams = SensorStreams(odom=odom, imu=imu if ahrs else dataclasses.replace(imu, orientation=None))
        for name in (["ekf", "gtsam"] if backend == "all" else [backend]):
            t0 = time.perf_counter()
            try:
                result = fuse(streams, name, FusionConfig())
            except RuntimeError as exc:  # e.g. GTSAM finding the system indeterminate
                notes.append(f"{variant}, {name}: failed ({' '.join(str(exc).split())[:120]})")
                continue
            gated = {s: c.gated for s, c in result.counts.get(name, {}).items() if c.gated}
            notes.append(f"{variant}, {name}: {time.perf_counter() - t0:.1f} s; calibration "
                         + ", ".join(f"{k}={v:.4g}" for k, v in result.calibration.get(name, {}).items())
                         + (f"; gated {gated}" if gated else "")
                         + "".join(f"; {n}" for n in result.notes if "behind the gyro" in n))
            for traj in TRAJECTORIES:
                if traj in result.trajectories:
                    tracks[f"{variant}: {traj}"] = result.trajectories[traj]
    return tracks, notes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", nargs="?", default=str(DEFAULT_BAG), help="robot_localization's test1.bag")
    parser.add_argument("--backend", choices=["ekf", "gtsam", "all"], default="all", help="fusion backends to run")
    parser.add_argument("--keep", help="write the imported recording to this folder and keep it")
    args = parser.parse_args(argv)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            seq = Path(args.keep) if args.keep else Path(tmp) / "husky"
            t0 = time.perf_counter()
            summary = import_bag(args.bag, seq, static_tfs=[parse_static_tf(HUSKY_IMU_TF)], overwrite=True)
            print(f"imported {args.bag} in {time.perf_counter() - t0:.1f} s:")
            for s in summary.streams:
                print(f"  {s.stream:6s} {s.topic:34s} {s.written:6d} rows  {s.rate_hz:6.2f} Hz  {s.duration_s:6.1f} s")
            rec = Recording(seq)
            gps = read_fixes(rec)
            path = distance_travelled(rec)
            tracks = {"raw wheel odometry": baseline.raw_odometry(rec),
                      "wheel + gyro dead reckoning (no filter)": baseline.wheel_gyro(rec)}
            fused, notes = fused_tracks(rec, args.backend)
            tracks.update(fused)
    except InputError as exc:
        print(f"husky_gps: error: {exc}", file=sys.stderr)
        return 2
    print(f"\ndistance travelled (wheel odometry): {path:.1f} m; GPS fixes: {len(gps.t)}")
    print("errors against the GPS fixes after SE(2) alignment:")
    print(f"  {'track':48s} {'RMS m':>7s} {'max m':>7s} {'RMS % of path':>14s}")
    for name, track in tracks.items():
        err = gps_errors(track, gps)
        rms = float(np.sqrt(np.mean(err**2)))
        print(f"  {name:48s} {rms:7.2f} {err.max():7.2f} {100.0 * rms / path:14.2f}")
    print("\nfusion runs:")
    for note in notes:
        print(f"  {note}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
