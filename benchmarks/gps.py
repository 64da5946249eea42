"""GPS fused in both backends, beside the fixes themselves and the GPS-free tracks placed on the fixes afterwards.

1. ``gps_outage`` (standard generated recording: 60 s random drive, GPS at 5 Hz with 5 cm noise per axis,
   antenna 0.1 m behind the axle, a 10 s outage from 20 s, a 20 m jump of the fixes from 40 to 41 s). Camera,
   wheels and IMU with GPS, every backend, compared with the ground truth carried into ENU by the simulator's
   known world heading and origin, without any alignment (the fused world frame must *be* ENU). Baselines
   from the same run: the fixes themselves (the antenna's error; the best single sensor for position), wheel
   dead reckoning and the same backends without GPS, each placed in ENU by the robust rigid fit to all fixes
   (``fusion_vo.sensors.gps.align_to_fixes``: the best a GPS-free track can do, future fixes included).
   Printed per trajectory: position RMS while GPS is present, the largest error during the outage and at its
   end (drift), the largest error during the jump, and the fixes used / rejected. Then the same streams fed in
   arrival order to ``StreamingFusion`` (EKF and iSAM2, each with and without GPS; without it placed in ENU as
   above), with the whole-drive position RMS beside the batch run's ``gtsam_online`` track, and each run's
   latency per node (each call processing all that is due, as the ROS 2 node runs it): percentiles of the wall
   time of the calls that processed a node, and the mean CPU time per node.
2. robot_localization's Husky bag (395 s, 989 fixes, about 0.9 m sigma): wheel odometry (twist) and IMU with
   the GPS of the first half (``--husky-split``), the later fixes withheld and scored (plain RMS of the
   antenna in ENU); with the receiver's stated sigma (the default), with the fixes' scatter measured by the
   world-frame alignment (``fusion.gps.estimate_sigma``) and with a 2 m floor (``fusion.gps.min_sigma``).
   Baselines: wheel dead reckoning and the backends without GPS, placed in ENU by the fit to the same fused
   fixes (the same information), and for reference fitted to the withheld fixes themselves. The same streamed
   (``StreamingFusion``, EKF and iSAM2, the stated sigma) with their fix counts and latency.

``--config`` and ``--set`` change the configuration of every run (``--set fusion.gps.estimate_sigma=true``).

Usage::

    python benchmarks/gps.py [--skip-husky | --skip-outage] [--husky-split 0.5] [--config FILE] [--set KEY=VALUE ...]
                             [--out DIR]
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from common import (FUSED, add_out, add_settings, fusion_settings, import_husky, parser, standard, table,
                    with_settings, work_dir)

from fusion_vo.backends import fuse, streams_from_recording
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.measurements import GpsData, PoseData
from fusion_vo.odometry import run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.sensors.gps import align_to_fixes, predict, read_fixes

OUTAGE, JUMP = (20.0, 30.0), (40.0, 41.0)
COLUMNS = ("rms_gps_present", "max_outage", "end_outage", "max_jump")


def truth_in_enu(rec: Recording) -> PoseData:
    """Ground truth carried into ENU by the simulator's world heading and origin (``simulation.yaml``)."""
    info = yaml.safe_load((rec.path / "simulation.yaml").read_text())
    flat = {}
    for v in info.values():
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


def outage_figures(errors: tuple[np.ndarray, np.ndarray], t0: float) -> dict:
    t, e = errors
    rel = t - t0
    inside = (rel >= OUTAGE[0]) & (rel <= OUTAGE[1])
    during_jump = (rel >= JUMP[0]) & (rel <= JUMP[1])
    end = int(np.argmin(np.abs(rel - OUTAGE[1])))
    return {"rms_gps_present": float(np.sqrt(np.mean(e[~inside] ** 2))), "max_outage": float(e[inside].max()),
            "end_outage": float(e[end]), "max_jump": float(e[during_jump].max())}


def gps_outage(out: Path, fusion: dict) -> None:
    rec = Recording(standard(out, "gps_outage"))
    truth = truth_in_enu(rec)
    gps = read_fixes(rec)
    vo = run_visual_odometry(rec)
    t0 = float(truth.t[0])
    rows = {}
    true_antenna = predict(np.column_stack([np.interp(gps.t, truth.t, truth.xyyaw[:, i]) for i in range(3)]),
                           gps.lever_arm)
    err = np.linalg.norm(gps.enu[:, :2] - true_antenna, axis=1)
    ok = ~((gps.t - t0 >= JUMP[0]) & (gps.t - t0 <= JUMP[1]))
    rows["GPS fixes alone (antenna)"] = {"rms_gps_present": float(np.sqrt(np.mean(err[ok] ** 2))),
                                         "max_jump": float(err[~ok].max())}
    timing, notes, batch = {}, [], None
    for label, sensors in (("with GPS", ["camera", "wheel", "imu", "gps"]), ("without GPS", ["camera", "wheel", "imu"])):
        start = time.perf_counter()
        result = fuse(streams_from_recording(rec, vo, sensors), "all", fusion)
        timing[label] = time.perf_counter() - start
        for name in FUSED:
            track = result.trajectories[name]
            key = f"{name} {label}" + (" (fitted to all fixes)" if label == "without GPS" else "")
            if label == "without GPS":
                track = place_in_enu(track, gps)
            rows[key] = outage_figures(position_errors(track, truth), t0)
            counts = result.counts.get(name, {}).get("gps")
            if counts is not None:
                rows[key]["fixes"] = f"{counts.used} / {counts.gated}"
        if label == "with GPS":
            notes, batch = [n for n in result.notes if "gps" in n], result
        else:
            wheel = place_in_enu(result.trajectories["wheel"], gps)
            rows["wheel dead reckoning (fitted to all fixes)"] = outage_figures(position_errors(wheel, truth), t0)
    print(f"\ngps_outage: {len(gps)} fixes, sigma {gps.horizontal_sigma:.3f} m per axis; position errors in ENU [mm]")
    print(table(["trajectory", "RMS while GPS present", "max during outage", "at outage end", "max during jump",
                 "fixes used / rejected"],
                [[name, *(f"{1e3 * r[k]:.1f}" if k in r else "–" for k in COLUMNS), r.get("fixes", "–")]
                 for name, r in rows.items()]))
    for n in notes:
        print("  note:", n)
    print("  backends' wall time [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in timing.items()))
    streaming(rec, vo, truth, gps, fusion, batch)


def stream(streams, backend: str, fusion: dict):
    """``StreamingFusion`` fed ``streams`` in arrival order, each call processing all that is due
    (``steps_per_call=None``, as the ROS 2 node runs it): its result, the wall times [ms] of the calls that processed
    a node (the processed state moved on: one node, rarely more) and the CPU time per node [ms] (of the whole run,
    ``finish`` included)."""
    fusion_run = streaming_for(streams, backend, fusion, steps_per_call=None)
    calls = []
    last = None
    cpu = time.process_time()
    for message in time_ordered_messages(streams):
        start = time.perf_counter()
        fusion_run.feed([message])
        spent = time.perf_counter() - start
        now = fusion_run.processed_estimate()
        if now is not None and (last is None or now.t > last):
            calls.append(spent)
            last = now.t
    result = fusion_run.finish()
    cpu = time.process_time() - cpu
    name = "ekf" if backend == "ekf" else "gtsam_online"
    return result, name, 1e3 * np.array(calls), 1e3 * cpu / max(len(result.trajectories[name]), 1)


def streaming(rec: Recording, vo, truth: PoseData, gps: GpsData, fusion: dict, batch) -> None:
    """The streaming backends with and without GPS, beside the batch run's online iSAM2 track with GPS."""
    t0 = float(truth.t[0])
    rows = []

    def whole(track):
        return float(np.sqrt(np.mean(position_errors(track, truth)[1] ** 2)))

    for label, sensors in (("with GPS", ["camera", "wheel", "imu", "gps"]), ("without GPS", ["camera", "wheel", "imu"])):
        streams = streams_from_recording(rec, vo, sensors)
        for backend in ("ekf", "gtsam"):
            result, name, calls, per_node = stream(streams, backend, fusion)
            track = result.trajectories[name]
            if label == "without GPS":
                track = place_in_enu(track, gps)
            r = outage_figures(position_errors(track, truth), t0)
            c = result.counts[name].get("gps")
            rows.append([f"streaming {backend} {label}" + (" (fitted to all fixes)" if label == "without GPS" else ""),
                         f"{1e3 * whole(track):.1f}", f"{1e3 * r['rms_gps_present']:.1f}", f"{1e3 * r['end_outage']:.1f}",
                         f"{1e3 * r['max_jump']:.1f}", "–" if c is None else f"{c.used} / {c.gated} / {c.missing} / {c.late}",
                         f"{np.percentile(calls, 50):.3f}", f"{np.percentile(calls, 99):.3f}", f"{calls.max():.1f}",
                         f"{per_node:.3f}"])
    online = batch.trajectories["gtsam_online"]
    r = outage_figures(position_errors(online, truth), t0)
    c = batch.counts["gtsam_online"]["gps"]
    rows.append(["batch run's gtsam_online with GPS", f"{1e3 * whole(online):.1f}", f"{1e3 * r['rms_gps_present']:.1f}",
                 f"{1e3 * r['end_outage']:.1f}", f"{1e3 * r['max_jump']:.1f}", f"{c.used} / {c.gated} / {c.missing} / –",
                 "–", "–", "–", "–"])
    print("\nstreaming, fed in arrival order: position errors in ENU [mm], fixes, latency per node [ms]")
    print(table(["trajectory", "RMS whole drive", "RMS while GPS present", "at outage end", "max during jump",
                 "fixes used / gated / missing / late", "node p50", "node p99", "node max", "CPU per node"], rows))


def gps_subset(gps: GpsData, keep: np.ndarray) -> GpsData:
    return dataclasses.replace(gps, t=gps.t[keep], enu=gps.enu[keep], covariance=gps.covariance[keep],
                               geodetic=gps.geodetic[keep], status=gps.status[keep])


def score_withheld(track: PoseData, withheld: GpsData) -> dict:
    """Plain ENU RMS [m] of the antenna against the withheld fixes, and the error at the last one."""
    inside = (withheld.t >= track.t[0]) & (withheld.t <= track.t[-1])
    t = withheld.t[inside]
    pose = np.column_stack([np.interp(t, track.t, track.xyyaw[:, 0]), np.interp(t, track.t, track.xyyaw[:, 1]),
                            np.interp(t, track.t, np.unwrap(track.xyyaw[:, 2]))])
    err = np.linalg.norm(predict(pose, withheld.lever_arm) - withheld.enu[inside, :2], axis=1)
    return {"rms": float(np.sqrt(np.mean(err ** 2))), "end": float(err[-1])}


def husky(out: Path, split: float, fusion: dict) -> None:
    rec = Recording(import_husky(out / "husky"))
    gps = read_fixes(rec)
    t_mid = float(gps.t[0]) + split * (float(gps.t[-1]) - float(gps.t[0]))
    first, second = gps_subset(gps, gps.t <= t_mid), gps_subset(gps, gps.t > t_mid)
    base = streams_from_recording(rec, None, ["odom", "imu"])
    free = fuse(base, "all", fusion)
    rows = {}
    for name in ("wheel",) + FUSED:
        placed = place_in_enu(free.trajectories[name], gps, t_end=t_mid)
        rows[f"{name} without GPS, fitted to the fused part's fixes"] = score_withheld(placed, second)
    notes = []
    for label, change in (("stated sigma", []), ("sigma estimated", ["gps.estimate_sigma=true"]),
                          ("sigma >= 2 m", ["gps.min_sigma=2.0"])):
        result = fuse(base.replace(gps=first), "all", with_settings(fusion, change))
        for name in FUSED:
            rows[f"{name} with the fused part's GPS, {label}"] = score_withheld(result.trajectories[name], second)
        notes += [f"({label}) {n}" for n in result.notes if "gps" in n]
    for backend in ("ekf", "gtsam"):  # live: the stated sigma, the world frame found from the fixes so far
        result, name, calls, per_node = stream(base.replace(gps=first), backend, fusion)
        c = result.counts[name]["gps"]
        rows[f"streaming {backend} with the fused part's GPS, stated sigma"] = score_withheld(
            result.trajectories[name], second)
        notes.append(f"(streaming {backend}) gps {c.used} used, {c.gated} gated, {c.missing} missing, {c.late} late; "
                     f"per node p50 {np.percentile(calls, 50):.3f} ms, p99 {np.percentile(calls, 99):.3f} ms, "
                     f"CPU per node {per_node:.3f} ms")
    for name in ("wheel",) + FUSED:
        rows[f"{name} without GPS, fitted to the withheld fixes (reference)"] = score_withheld(
            place_in_enu(free.trajectories[name], second), second)
    print(f"\nHusky test1.bag: {len(gps)} fixes (sigma {math.sqrt(np.median(gps.covariance[:, 0, 0])):.2f} m); GPS fused "
          f"up to {t_mid - gps.t[0]:.0f} s, the {len(second)} later fixes withheld and scored [m]")
    print(table(["trajectory", "RMS against the withheld fixes", "at the end"],
                [[name, f"{r['rms']:.2f}", f"{r['end']:.2f}"] for name, r in rows.items()]))
    for n in notes:
        print("  note", n)


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--skip-husky", action="store_true", help="the generated recording only")
    ap.add_argument("--skip-outage", action="store_true", help="the Husky log only")
    ap.add_argument("--husky-split", type=float, default=0.5,
                    help="fraction of the Husky recording whose fixes are fused (default 0.5: the first half)")
    add_settings(ap)
    add_out(ap)
    args = ap.parse_args(argv)
    if not 0.05 <= args.husky_split <= 0.95:
        ap.error("--husky-split must be between 0.05 and 0.95")
    fusion = fusion_settings(args)
    with work_dir(args.out, "gps-") as out:
        if not args.skip_outage:
            gps_outage(out, fusion)
        if not args.skip_husky:
            husky(out, args.husky_split, fusion)
    return 0


if __name__ == "__main__":
    sys.exit(main())
