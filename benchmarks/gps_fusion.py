"""GPS fused in both backends: accuracy while GPS is present, the multipath jump, drift in an outage, and
drift after GPS is withheld on a real recording.

1. ``gps_outage`` (standard generated recording: 60 s random drive, GPS at 5 Hz with 5 cm noise per
   axis, antenna 0.1 m behind the axle, a 10 s outage from 20 s, a 20 m jump of the fixes from 40 to
   41 s). Camera, wheels and IMU with GPS, every backend, are compared with the ground truth carried
   into ENU by the simulator's known world heading and origin -- no alignment: the fused world frame
   must *be* ENU. Beside them, from the same run: the fixes themselves (the best single sensor for
   position; the antenna's error), and the same backends without GPS placed in ENU by
   :func:`fusion_vo.sensors.gps.align_to_fixes` on all fixes (the best a GPS-free track can do).
   Printed per trajectory: position RMS while GPS is present (outside the outage), the largest
   error during the outage and at its end (drift), the largest error during the jump, and the fixes
   used / rejected.
2. Husky (``tests/data/robot_localization/test1.bag``, 395 s, 84 m, GPS 2.5 Hz, 0.9 m sigma): wheel
   odometry (twist) and IMU with the GPS of the first half only; the second half is scored against its
   withheld fixes (plain RMS in ENU of the antenna), with the receiver's claimed sigma and with the
   fixes' scatter (2 m, ``fusion.gps.min_sigma``) as its floor, and with the scatter the world-frame
   alignment measures (``fusion.gps.estimate_sigma``; 1.51 m per axis); ``--husky-split`` fuses another
   fraction than the first half. Beside it: wheel dead reckoning and the
   backends without GPS, placed in ENU by aligning them to the first half's fixes (the same
   information the fused run gets), scored the same way.

Usage::

    python benchmarks/gps_fusion.py [--out DIR] [--skip-husky] [--estimate-sigma] [--husky-split FRACTION]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from fusion_vo.backends import fuse, streams_from_recording
from fusion_vo.measurements import GpsData, PoseData
from fusion_vo.odometry import run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.sensors.gps import align_to_fixes, predict
from fusion_vo.simulation.standard import make_standard

BAG = Path(__file__).resolve().parents[1] / "tests" / "data" / "robot_localization" / "test1.bag"
HUSKY_IMU_TF = "0 -0.3 0.52 -1.570796327 0 1.570796327 base_link imu_link"
FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")


def truth_in_enu(rec: Recording) -> PoseData:
    """Ground truth carried into ENU by the simulator's world heading and origin (simulation.yaml)."""
    import yaml

    info = yaml.safe_load((rec.path / "simulation.yaml").read_text())
    flat = {}
    for v in info.values() if isinstance(info, dict) else ():
        if isinstance(v, dict):
            flat.update(v)
    flat.update({k: v for k, v in info.items() if not isinstance(v, dict)})
    yaw = math.radians(float(flat["gps_world_heading_deg"]))
    origin = np.asarray(flat["gps_world_origin_enu"], dtype=np.float64)
    gt = rec.groundtruth()
    c, s = math.cos(yaw), math.sin(yaw)
    p = gt.xyyaw
    enu = np.column_stack([c * p[:, 0] - s * p[:, 1] + origin[0], s * p[:, 0] + c * p[:, 1] + origin[1], p[:, 2] + yaw])
    return PoseData(gt.t.copy(), enu)


def position_errors(track: PoseData, truth: PoseData) -> tuple[np.ndarray, np.ndarray]:
    """Times and horizontal position errors [m] of ``track`` against ``truth`` (interpolated)."""
    t = track.t[(track.t >= truth.t[0]) & (track.t <= truth.t[-1])]
    xy = np.column_stack([np.interp(t, track.t, track.xyyaw[:, i]) for i in range(2)])
    ref = np.column_stack([np.interp(t, truth.t, truth.xyyaw[:, i]) for i in range(2)])
    return t, np.linalg.norm(xy - ref, axis=1)


def place_in_enu(track: PoseData, gps: GpsData, t_end: float | None = None) -> PoseData | None:
    """A GPS-free track carried into ENU by the rigid fit to the fixes up to ``t_end``."""
    fit = align_to_fixes(track.t, track.xyyaw, gps, t_end=t_end)
    return None if fit is None else PoseData(track.t.copy(), fit.apply(track.xyyaw))


def outage_figures(errors: tuple[np.ndarray, np.ndarray], t0: float, outage: tuple[float, float],
                   jump: tuple[float, float]) -> dict:
    t, e = errors
    rel = t - t0
    inside = (rel >= outage[0]) & (rel <= outage[1])
    during_jump = (rel >= jump[0]) & (rel <= jump[1])
    end = int(np.argmin(np.abs(rel - outage[1])))
    return {"rms_gps_present": float(np.sqrt(np.mean(e[~inside] ** 2))),
            "max_outage": float(e[inside].max()), "end_outage": float(e[end]),
            "max_jump": float(e[during_jump].max())}


def gps_outage(out: Path, options: dict | None = None) -> dict:
    seq = make_standard("gps_outage", out / "gps_outage")
    rec = Recording(seq)
    truth = truth_in_enu(rec)
    gps = rec.gps()
    vo = run_visual_odometry(rec)
    t0 = float(truth.t[0])
    outage, jump = (20.0, 30.0), (40.0, 41.0)
    rows = {}
    # the fixes themselves: the antenna's error against the true antenna position
    true_antenna = predict(np.column_stack([np.interp(gps.t, truth.t, truth.xyyaw[:, i]) for i in range(3)]),
                           gps.lever_arm)
    err = np.linalg.norm(gps.enu[:, :2] - true_antenna, axis=1)
    ok = ~((gps.t - t0 >= jump[0]) & (gps.t - t0 <= jump[1]))
    rows["GPS fixes (antenna)"] = {"rms_gps_present": float(np.sqrt(np.mean(err[ok] ** 2))),
                                   "max_jump": float(err[~ok].max())}
    timing = {}
    for label, sensors in (("with GPS", ["camera", "wheel", "imu", "gps"]), ("without GPS", ["camera", "wheel", "imu"])):
        start = time.perf_counter()
        result = fuse(streams_from_recording(rec, vo, sensors), "all", options)
        timing[label] = time.perf_counter() - start
        for name in FUSED:
            track = result.trajectories[name]
            if label == "without GPS":
                track = place_in_enu(track, gps)
            rows[f"{name} {label}"] = outage_figures(position_errors(track, truth), t0, outage, jump)
            counts = result.counts.get(name, {}).get("gps")
            if counts is not None:
                rows[f"{name} {label}"]["fixes"] = f"{counts.used} used / {counts.gated} rejected"
        if label == "with GPS":
            notes = [n for n in result.notes if "gps" in n]
    wheel = place_in_enu(result.trajectories["wheel"], gps)
    rows["wheel dead reckoning (aligned to all fixes)"] = outage_figures(position_errors(wheel, truth), t0, outage, jump)
    print(f"\ngps_outage: {len(gps)} fixes, sigma {gps.horizontal_sigma:.3f} m per axis; position errors [m] in ENU")
    print(f"{'trajectory':48s} {'RMS w/ GPS':>10s} {'max outage':>10s} {'end outage':>10s} {'max jump':>9s}  fixes")
    for name, r in rows.items():
        print(f"{name:48s} " + " ".join(f"{r[k]:10.4f}" if k in r else f"{'-':>10s}"
                                        for k in ("rms_gps_present", "max_outage", "end_outage", "max_jump"))
              + f"  {r.get('fixes', '')}")
    for n in notes:
        print("  note:", n)
    print("  backend wall time [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in timing.items()))
    return rows


def husky(out: Path, split: float = 0.5) -> dict:
    from fusion_vo.cli.main import main as cli

    seq = out / "husky"
    if not (seq / "gps0").exists():
        assert cli(["-q", "import-bag", str(BAG), str(seq), "--static-tf", HUSKY_IMU_TF]) == 0
    rec = Recording(seq)
    gps = rec.gps()
    t_mid = float(gps.t[0]) + split * (float(gps.t[-1]) - float(gps.t[0]))
    first = gps_subset(gps, gps.t <= t_mid)
    second = gps_subset(gps, gps.t > t_mid)
    rows = {}
    base = streams_from_recording(rec, None, ["odom", "imu"])
    fused = fuse(dataclasses.replace(base, gps=first), "all")
    free = fuse(base, "all")
    for name in FUSED:
        rows[f"{name} with first-half GPS"] = score_second_half(fused.trajectories[name], second)
    # the receiver's claimed 0.9 m against the 2.2 m its fixes scatter: the measured scatter as the floor
    floored = fuse(dataclasses.replace(base, gps=first), "all", {"gps": {"min_sigma": 2.0}})
    for name in FUSED:
        rows[f"{name} with first-half GPS, sigma >= 2 m"] = score_second_half(floored.trajectories[name], second)
    # the fixes' scatter measured by the world-frame alignment (fusion.gps.estimate_sigma) against the stated
    estimated = fuse(dataclasses.replace(base, gps=first), "all", {"gps": {"estimate_sigma": True}})
    for name in FUSED:
        rows[f"{name} with first-half GPS, sigma estimated"] = score_second_half(estimated.trajectories[name], second)
    claimed = fuse(dataclasses.replace(base, gps=first), "all", {"gps": {"estimate_sigma": False}})
    for name in FUSED:
        rows[f"{name} with first-half GPS, stated sigma"] = score_second_half(claimed.trajectories[name], second)
    for name in ("wheel",) + FUSED:
        placed = place_in_enu(free.trajectories[name], gps, t_end=t_mid)
        rows[f"{name} without GPS (aligned on first half)"] = score_second_half(placed, second)
        rows[f"{name} without GPS (SE(2)-aligned on second half)"] = score_second_half(
            place_in_enu(free.trajectories[name], second), second)
    print(f"\nHusky test1.bag: {len(gps)} fixes (sigma {math.sqrt(np.median(gps.covariance[:, 0, 0])):.2f} m); "
          f"GPS fused up to {t_mid - gps.t[0]:.0f} s, the {len(second)} later fixes withheld and scored")
    print(f"{'trajectory':58s} {'RMS 2nd half':>12s} {'at end':>8s}")
    for name, r in rows.items():
        print(f"{name:58s} {r['rms']:12.2f} {r['end']:8.2f}")
    for label, res in (("default", fused), ("sigma estimated", estimated), ("sigma >= 2 m", floored)):
        for n in res.notes:
            if "gps" in n:
                print(f"  note ({label}):", n)
    return rows


def gps_subset(gps: GpsData, keep: np.ndarray) -> GpsData:
    return dataclasses.replace(gps, t=gps.t[keep], enu=gps.enu[keep], covariance=gps.covariance[keep],
                               geodetic=gps.geodetic[keep], status=gps.status[keep])


def score_second_half(track: PoseData, withheld: GpsData) -> dict:
    """Plain ENU RMS [m] of the antenna against the withheld fixes, and the error at the last one."""
    inside = (withheld.t >= track.t[0]) & (withheld.t <= track.t[-1])
    t = withheld.t[inside]
    pose = np.column_stack([np.interp(t, track.t, track.xyyaw[:, 0]), np.interp(t, track.t, track.xyyaw[:, 1]),
                            np.interp(t, track.t, np.unwrap(track.xyyaw[:, 2]))])
    err = np.linalg.norm(predict(pose, withheld.lever_arm) - withheld.enu[inside, :2], axis=1)
    return {"rms": float(np.sqrt(np.mean(err ** 2))), "end": float(err[-1])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="working folder (default: a temporary one)")
    ap.add_argument("--skip-husky", action="store_true")
    ap.add_argument("--husky-split", type=float, default=0.5,
                    help="fraction of the Husky recording whose fixes are fused (default 0.5: the first half)")
    ap.add_argument("--estimate-sigma", action="store_true",
                    help="gps_outage with fusion.gps.estimate_sigma on (the Husky part always shows both)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        gps_outage(out, {"gps": {"estimate_sigma": True}} if args.estimate_sigma else None)
        if not args.skip_husky:
            husky(out, args.husky_split)


if __name__ == "__main__":
    main()
