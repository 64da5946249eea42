"""Inputs that contradict each other: what the pre-fusion checks (:mod:`fusion_vo.consistency`) do to the tracks.

Three sections, each beside its baselines measured in the same run:

1. **Husky, IMU mounting.** robot_localization's ``test1.bag`` (``tests/data/robot_localization``, 395 s,
   359 m; wheel odometry, IMU with an AHRS orientation, GPS not fused) imported without the static
   transform its launch file adds for the IMU (``T_BS`` the identity) and with it. Wheel odometry + IMU are
   fused in batch (EKF, RTS, GTSAM batch, iSAM2) and streaming (EKF, iSAM2; every sample in time order
   through :class:`~fusion_vo.backends.StreamingFusion`), with the checks (the default) and without
   (``consistency.check: false``, the IMU fused as stated); also the log without the transform and with its
   accelerometer's columns zeroed (no gravity: the gyro's axis alone decides). Figures: RMS horizontal
   distance to the GPS fixes after the least-squares SE(2) alignment (``examples/husky_gps.py``), beside
   the raw odometry dead-reckoned.
2. **Wrong focal length.** A generated recording run with ``--uncalibrated --focal-length F`` at about half
   its true focal length: the standard ``square`` (420 px; the README's demo with 220 and with 210) and,
   with ``--full``, ``hard`` and ``random60`` (210). Visual odometry once per recording and focal length,
   then fusion (all backends) with the checks (the camera's translation left out), without them (as
   stated), with only the camera's scale prior released (``released_scale_sigma``, increments as
   measured) and with the increments divided by the measured ratio with the lever arm's part undone
   (:func:`rescaled`) and the prior released. Figures: ATE [mm], RMS position error after the least-squares
   SE(2) alignment to the ground truth, beside visual odometry and the wheels alone.
3. **Broken copies of a generated drive** (30 s random drive, wheels + IMU; a twist made from the ground
   truth for the odometry cases), one fault each, as ``tests/consistency`` makes them: a left encoder
   counting backwards, wheel timestamps 0.3 s late, a twist in the odometry frame, a twist with its axes
   turned by 90°, an IMU on its side stated upright, an IMU whose gyro and accelerometer disagree
   (:mod:`fusion_vo.simulation.faults`). Figures:
   the check's decision and the EKF's ATE [mm] with and without the checks, beside the unbroken drive's.
4. **A stream that lies for a while.** Generated drives with a camera, wheels and a gyro
   (:func:`~fusion_vo.sensors.synthetic.synthetic_streams`: 30 s seed 2, 45 s seed 0, 60 s seed 0), the wheels' counts
   or the camera's translations 1.3 times too long over a span (:func:`~fusion_vo.sensors.synthetic.wheels_too_long`,
   :func:`~fusion_vo.sensors.synthetic.camera_too_long`). Figures: RMS position error [cm] from the truth (same start,
   no alignment) of the batch EKF and GTSAM with the checks (the default) and with the checks and the monitor off,
   and of the streamed EKF and iSAM2 with the live monitor and without, beside the clean drive's; the scale check's
   decision and the speed spans the batch check drops.

Usage::

    python benchmarks/contradictions.py [--sections 1,2,3,4] [--full] [--keep DIR]
"""

from __future__ import annotations

import dataclasses
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import common
from common import HUSKY_BAG, HUSKY_IMU_TF

from fusion_vo import baseline
from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.backends.batch import streams_from_recording
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.evaluation.metrics import gps_errors
from fusion_vo.measurements import PoseData
from fusion_vo.recording import Recording
from fusion_vo.recording.rosbag import import_bag, parse_static_tf
from fusion_vo.sensors.gps import read_fixes
from fusion_vo.sensors.synthetic import SyntheticOptions, camera_too_long, synthetic_streams, wheels_too_long
from fusion_vo.simulation.faults import columns, flip_left_encoder, shift_clock, turn_imu, twist_from_truth, write_csv

BAG = HUSKY_BAG
FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
ON_ITS_SIDE = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def config(check: bool = True, **changes) -> FusionConfig:
    return FusionConfig(**changes).merged({"consistency": {"check": check}})


def streamed(streams, backend: str, cfg: FusionConfig) -> PoseData:
    fusion = streaming_for(streams, backend, cfg)
    fusion.feed(time_ordered_messages(streams))
    result = fusion.finish()
    return result.trajectories["ekf" if backend == "ekf" else "gtsam_online"]


# --------------------------------------------------------------------------- 1. Husky
def husky(tmp: Path) -> None:
    plain, mounted = tmp / "husky_plain", tmp / "husky"
    import_bag(BAG, plain, overwrite=True)
    import_bag(BAG, mounted, static_tfs=[parse_static_tf(HUSKY_IMU_TF)], overwrite=True)
    no_gravity = tmp / "husky_no_gravity"
    shutil.copytree(plain, no_gravity)
    header, t, values = columns(no_gravity / "imu0" / "data.csv")
    values[:, 3:6] = 0.0
    write_csv(no_gravity / "imu0" / "data.csv", header, t, values)
    gps = read_fixes(Recording(plain))

    def rms(track: PoseData) -> str:
        return f"{float(np.sqrt(np.mean(gps_errors(track, gps) ** 2))):6.2f}"

    print("\n1. Husky test1.bag, wheel odometry + IMU: RMS distance to the GPS fixes [m] after SE(2) alignment")
    print(f"   raw wheel odometry: {rms(baseline.raw_odometry(Recording(plain)))}")
    print(f"   {'recording':38s} {'checks':7s} " + " ".join(f"{n:>12s}" for n in FUSED)
          + f" {'stream EKF':>11s} {'stream iSAM2':>12s}")
    for label, seq, checks in (("imported without the transform", plain, False),
                               ("imported without the transform", plain, True),
                               ("without the transform, no gravity", no_gravity, False),
                               ("without the transform, no gravity", no_gravity, True),
                               ("imported with the launch file's transform", mounted, True)):
        streams = streams_from_recording(Recording(seq), None, ["odom", "imu"])
        t0 = time.process_time()
        result = fuse(streams, "all", config(checks))
        live = [streamed(streams, b, config(checks)) for b in ("ekf", "gtsam")]
        print(f"   {label:38s} {'on' if checks else 'off':7s} "
              + " ".join(f"{rms(result.trajectories[n]):>12s}" for n in FUSED)
              + f" {rms(live[0]):>11s} {rms(live[1]):>12s}   ({time.process_time() - t0:.0f} CPU-s)")
        for note in result.notes:
            if note.startswith("imu0/"):
                print(f"      {note}")


# --------------------------------------------------------------------------- 2. wrong focal length
def rescaled(streams, ratio: float, offset: np.ndarray):
    """The alternative measured against leaving the translation out: each increment ``m`` of turn ``ψ`` made
    ``m / ρ + (1 - 1/ρ)(I - R(ψ)) t`` (the camera at ``t`` in the body frame, :mod:`fusion_vo.geometry.ground`),
    its translation covariance divided by ``ρ²``."""
    f = 1.0 / ratio
    S = np.diag([f, f, 1.0])

    def one(v):
        if not v.ok:
            return v
        d = np.asarray(v.delta, dtype=np.float64).copy()
        c, s = np.cos(d[2]), np.sin(d[2])
        d[:2] = f * d[:2] + (1.0 - f) * (offset - np.array([c * offset[0] - s * offset[1], s * offset[0] + c * offset[1]]))
        return dataclasses.replace(v, delta=d, covariance=S @ np.asarray(v.covariance) @ S)

    return streams.replace(visual=[one(v) for v in streams.visual], camera_height_sigma=None)


def wrong_focal(tmp: Path, full: bool) -> None:
    from fusion_vo.config.sensor_files import uncalibrated_camera
    from fusion_vo.odometry import OdometryConfig, run_visual_odometry
    from fusion_vo.simulation.standard import make_standard

    cases = [("square", 220.0), ("square", 210.0)] + ([("hard", 210.0), ("random60", 210.0)] if full else [])
    print("\n2. Wrong focal length (true 420 px), --uncalibrated --focal-length F: ATE [mm] after SE(2) alignment")
    print(f"   {'recording':10s} {'F':>5s} {'fusion':34s} " + " ".join(f"{n:>12s}" for n in ("vo", "wheel") + FUSED))
    for name, focal in cases:
        seq = tmp / name
        if not seq.exists():
            make_standard(name, seq)
        rec = Recording(seq)
        vo = run_visual_odometry(rec, OdometryConfig(uncalibrated=True, focal_length=focal))
        rec.camera = uncalibrated_camera(seq / "cam0" / "sensor.yaml", focal, quiet=True)
        truth = rec.groundtruth()
        streams = streams_from_recording(rec, vo, ["camera", "wheel", "imu"])
        checked = fuse(streams, "none", config())
        (scale,) = [f for f in checked.consistency if f["check"] == "scale"]
        ratio = scale["estimate"]["ratio"]
        released = config(False, visual_scale_sigma=config().consistency.released_scale_sigma)
        no_height = streams.replace(camera_height_sigma=None)
        variants = (("checks: translation left out", streams, config()),
                    ("as stated (no checks)", streams, config(False)),
                    ("scale prior released only", no_height, released),
                    (f"divided by {ratio:.3f}, prior released", rescaled(streams, ratio, rec.camera.T_BS[:2, 3]),
                     released))
        for label, s, cfg in variants:
            r = fuse(s, "all", cfg)
            print(f"   {name:10s} {focal:5.0f} {label:34s} {common.ate_mm(truth, vo.track):12.1f} "
                  + " ".join(f"{common.ate_mm(truth, r.trajectories[n]):12.1f}" for n in ("wheel",) + FUSED))


# --------------------------------------------------------------------------- 3. broken copies
def broken_drives(tmp: Path) -> None:
    from fusion_vo.simulation import simulate

    drive = simulate(tmp / "drive", profile="random", seed=3, duration=30.0, width=64, height=36, fu=42.0, fv=42.0,
                     cu=31.5, cv=17.5, camera_rate=5.0, supersample=1)
    truth = Recording(drive).groundtruth()
    faults = {
        "unbroken (wheels + IMU)": (None, "wheel,imu"),
        "left encoder counting backwards": (flip_left_encoder, "wheel,imu"),
        "wheel timestamps 0.3 s late": (lambda r: shift_clock(r, "wheel0", 0.3), "wheel,imu"),
        "IMU on its side, stated upright": (lambda r: turn_imu(r, ON_ITS_SIDE), "wheel,imu"),
        "IMU gyro and accelerometer disagree": (lambda r: turn_imu(r, ON_ITS_SIDE, np.eye(3)), "wheel,imu"),
        "unbroken twist (odometry + IMU)": (lambda r: twist_from_truth(r, "body"), "odom,imu"),
        "twist in the odometry frame": (lambda r: twist_from_truth(r, "world"), "odom,imu"),
        "twist axes turned by 90°": (lambda r: twist_from_truth(r, "turned"), "odom,imu"),
    }
    print("\n3. Broken copies of a generated 30 s drive: the checks' decisions and the EKF's ATE [mm]")
    print(f"   {'fault':38s} {'checks on':>10s} {'checks off':>11s}   decisions")
    for label, (edit, sensors) in faults.items():
        rec = Path(shutil.copytree(drive, tmp / f"broken_{len(list(tmp.iterdir()))}"))
        if edit is not None:
            edit(rec)
        streams = streams_from_recording(Recording(rec), None, sensors.split(","))
        on, off = fuse(streams, "ekf", config()), fuse(streams, "ekf", config(False))
        decided = ", ".join(f"{f['check']} {f['decision']}" for f in on.consistency if f["decision"] != "kept") or "all kept"
        print(f"   {label:38s} {common.ate_mm(truth, on.trajectories['ekf']):10.1f} {common.ate_mm(truth, off.trajectories['ekf']):11.1f}"
              f"   {decided}")


# --------------------------------------------------------------------------- 4. passing lies
def rms_cm(track: PoseData, truth: PoseData) -> float:
    """RMS position error [cm] of ``track`` from ``truth`` (same start, no alignment)."""
    gt = np.stack([np.interp(track.t, truth.t, truth.xyyaw[:, i]) for i in range(2)], axis=1)
    return 100.0 * float(np.sqrt(np.mean(np.sum((track.xyyaw[:, :2] - gt) ** 2, axis=1))))


def passing_lies() -> None:
    print("\n4. A stream 1.3 times too long over a span of a generated drive: RMS position error [cm]; batch EKF / "
          "GTSAM, streamed EKF / iSAM2")
    print(f"   {'drive, span':22s} {'lie':7s} {'batch, checks':>14s} {'batch, off':>11s} {'live monitor':>13s} "
          f"{'live, off':>10s}   scale check; speed spans dropped (batch)")
    off = {"consistency": {"check": False}, "monitor": False}
    for duration, seed, span in ((30.0, 2, (12.0, 22.0)), (45.0, 0, (20.0, 35.0)), (60.0, 0, (20.0, 35.0))):
        s = synthetic_streams(SyntheticOptions(duration=duration), seed=seed)
        clean = SensorStreams(visual=s.visual, camera_height=s.camera_height, wheel=s.wheel, imu=s.imu)
        cases = {"none": clean, "wheels": clean.replace(wheel=wheels_too_long(s.wheel, *span, 1.3)),
                 "camera": clean.replace(visual=camera_too_long(s.visual, *span, 1.3))}
        for lie, streams in cases.items():
            on, blind = fuse(streams, "all", FusionConfig()), fuse(streams, "all", FusionConfig.from_dict(off))
            live = [streamed(streams, b, FusionConfig()) for b in ("ekf", "gtsam")]
            live_off = [streamed(streams, b, FusionConfig(monitor=False)) for b in ("ekf", "gtsam")]
            pair = lambda a, b: f"{rms_cm(a, s.truth):5.1f} /{rms_cm(b, s.truth):5.1f}"
            scale = next((f["decision"] for f in on.consistency if f["check"] == "scale"), "-")
            spans = ", ".join(f"{e['start']:.1f}-{e['end']:.1f} s" for e in on.inconsistent if e["component"] == "speed")
            label = f"{duration:.0f} s seed {seed}, {span[0]:.0f}-{span[1]:.0f} s"
            print(f"   {label:22s} {lie:7s} {pair(on.trajectories['ekf'], on.trajectories['gtsam']):>14s} "
                  f"{pair(blind.trajectories['ekf'], blind.trajectories['gtsam']):>11s} {pair(*live):>13s} "
                  f"{pair(*live_off):>10s}   {scale}; {spans or 'none'}")


def main(argv: list[str] | None = None) -> int:
    parser = common.parser(__doc__)
    parser.add_argument("--sections", default="1,2,3,4", help="which sections to run (default 1,2,3,4)")
    parser.add_argument("--full", action="store_true", help="section 2 also on hard and random60 (slow)")
    parser.add_argument("--keep", help="write the recordings to this folder and keep them")
    args = parser.parse_args(argv)
    sections = {s.strip() for s in args.sections.split(",")}
    with tempfile.TemporaryDirectory() as scratch:
        tmp = Path(args.keep) if args.keep else Path(scratch)
        tmp.mkdir(parents=True, exist_ok=True)
        if "1" in sections:
            husky(tmp)
        if "2" in sections:
            wrong_focal(tmp, args.full)
        if "3" in sections:
            broken_drives(tmp)
        if "4" in sections:
            passing_lies()
    return 0


if __name__ == "__main__":
    sys.exit(main())
