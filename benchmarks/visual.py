"""Visual odometry accuracy of every frontend beside the plain OpenCV script, measured in the same run.

The baseline is the plain OpenCV script of ``fusion_vo.baseline`` (Shi-Tomasi corners, pyramidal LK, a
RANSAC similarity, one frame at a time, no undistortion), run in the same process on the same frames. Its
pixel similarities become body motion through the same ground geometry with a distortion-free pinhole of
the recording's focal length, the same heights (range finder) and the same bridging of failed frames
(``fusion_vo.baseline.odometry``), and its track is scored the same way.

Subcommands:

independent   the recordings of the independent renderer (``fusion_vo.simulation.realistic``: lenses the
              estimator does not model, defocus, rolling shutter, motion blur, noise, auto-exposure,
              coarse checkerboards; default all four ``real_*``). Per recording and frontend: frame pairs
              measured, failures by reason, end-point error [% of the path] and heading error [deg] of the
              visual track alone (anchored at the start), RMS speed error against ground truth, frames per
              second end to end (decode included, wall clock). ``--fusion`` also runs ``fusion-vo run
              --backend all`` (KLT) on each recording and prints the ATE [mm, after SE(2) alignment] of
              visual odometry, wheel dead reckoning and every fused track, the KLT increments' errors
              against the truth beside the standard deviations they state and their mean NIS (3 if honest;
              ``fusion_vo.evaluation.increments``), and what the consistency monitor dropped.
standard      the self-consistency checks on recordings rendered through the estimator's own camera model
              (square, circle, standstill, random60; not a measured accuracy): end point and heading of the
              visual track (``fusion-vo run --backend none``'s evaluation), the largest motion of a single
              frame and the drift over the standstill, frames per second.
lens          what a missing lens calibration costs and what a calibration wins back, on the ``real_*``
              recordings: the lens estimated from the frames (``--uncalibrated`` of ``fusion-vo run``,
              ``fusion_vo.calibration.lens_from_motion``), or with ``--calibrate N`` the lens that
              ``fusion-vo calibrate intrinsics`` finds from N views of a 9 x 6 board (2 cm squares) rendered
              through the recording's own lens (radial-tangential model for the barrel lens, two radial
              terms or ``--radial-terms 3``; the fisheye model for the fisheye). Printed: how far that lens
              and a pinhole of the focal length reproject the true lens (worst / median over a 17 x 13 grid),
              then the accuracy table with that lens.

Usage::

    python benchmarks/visual.py independent [--recordings a,b] [--frontends klt,features,direct]
                                            [--options JSON] [--no-derotation] [--fusion] [--out DIR]
    python benchmarks/visual.py standard [--frontends klt,features] [--out DIR]
    python benchmarks/visual.py lens [--recordings a,b] [--frontends ...] [--calibrate N [--board-tilt RAD]
                                     [--radial-terms 3]] [--out DIR]

Generating the four realistic recordings takes several minutes on two cores (``--out`` keeps them).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

from common import add_out, names, parser, standard, table, work_dir

from fusion_vo import baseline
from fusion_vo.calibration.chessboard import Board
from fusion_vo.calibration.intrinsics import calibrate_images
from fusion_vo.calibration.lens_from_motion import lens_from_motion
from fusion_vo.config import RunConfig
from fusion_vo.errors import InputError
from fusion_vo.evaluation.increments import against_truth
from fusion_vo.evaluation.io import GROUNDTRUTH_CSV, read_groundtruth
from fusion_vo.evaluation.metrics import evaluate_trajectory, planar_trajectory
from fusion_vo.geometry import se2
from fusion_vo.config.sensor_files import uncalibrated_camera
from fusion_vo.geometry.camera import CameraModel
from fusion_vo.measurements import PoseData
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.pipeline import run_pipeline
from fusion_vo.recording import Recording
from fusion_vo.simulation.realistic import RealisticCamera, RealisticRenderer, board_views
from fusion_vo.simulation.standard import REALISTIC, STANDARD

FRONTENDS = ("klt", "features", "direct")


@dataclasses.dataclass
class Row:
    """One frontend (or the plain script) on one recording."""

    name: str
    pairs: int
    measured: int
    failures: Counter
    end_pct: float
    heading_deg: float
    speed_rmse: float
    fps: float


def score(track: PoseData, gt: PoseData) -> tuple[float, float, float]:
    """End-point error [% of the path], heading error [deg] and RMS speed error [m/s] of ``track`` anchored
    at the start of ``gt``."""
    yaw = np.unwrap(gt.xyyaw[:, 2])
    ref = np.column_stack([np.interp(track.t, gt.t, gt.xyyaw[:, 0]), np.interp(track.t, gt.t, gt.xyyaw[:, 1]),
                           np.interp(track.t, gt.t, yaw)])
    est = np.array([se2.compose(ref[0], se2.between(track.xyyaw[0], p)) for p in track.xyyaw])
    err = float(np.linalg.norm(est[-1, :2] - ref[-1, :2]))
    m = (gt.t >= track.t[0]) & (gt.t <= track.t[-1])
    length = float(np.sum(np.linalg.norm(np.diff(gt.xyyaw[m, :2], axis=0), axis=1)))
    heading = float(np.degrees(abs(se2.wrap_angle(np.unwrap(est[:, 2])[-1] - ref[-1, 2]))))
    dt = np.diff(track.t)
    ok = dt > 1e-6
    v_est = np.linalg.norm(np.diff(est[:, :2], axis=0), axis=1)[ok] / dt[ok]
    v_ref = np.linalg.norm(np.diff(ref[:, :2], axis=0), axis=1)[ok] / dt[ok]
    return 100.0 * err / max(length, 1e-9), heading, float(np.sqrt(np.mean((v_est - v_ref) ** 2)))


def plain_row(rec: Recording) -> Row:
    """The plain OpenCV script on ``rec``, scored as the frontends are."""
    vo, _, results, seconds = baseline.odometry(rec)
    measured = sum(m is not None for _, _, m in results)
    end, heading, speed = score(vo.track(), rec.groundtruth())
    return Row("plain OpenCV script", len(results), measured, Counter({"failed": len(results) - measured}),
               end, heading, speed, (len(results) + 1) / seconds)


def frontend_row(rec: Recording, frontend: str, odometry: dict, options: dict | None = None):
    """One frontend on ``rec`` (``odometry``: OdometryConfig options); the row and the odometry result."""
    start = time.perf_counter()
    vo = run_visual_odometry(rec, OdometryConfig(frontend=frontend, frontend_options=dict(options or {}), **odometry))
    seconds = time.perf_counter() - start
    end, heading, speed = score(vo.track, rec.groundtruth())
    return Row(frontend, len(vo.status) - 1, sum(s == "ok" for s in vo.status), vo.failures, end, heading, speed,
               len(vo.status) / seconds), vo


def print_rows(title: str, rows: list[Row]) -> None:
    print(f"\n{title}")
    print(table(["frontend", "frames measured", "failures by reason", "end-point error", "heading error",
                 "speed RMS", "frames/s"],
                [[r.name, f"{r.measured} / {r.pairs}",
                  ", ".join(f"{k} {v}" for k, v in sorted(r.failures.items()) if v) or "none",
                  f"{r.end_pct:.3f} %", f"{r.heading_deg:.3f}°", f"{1000 * r.speed_rmse:.2f} mm/s", f"{r.fps:.1f}"]
                 for r in rows]), flush=True)


def frontends(text: str) -> list[str]:
    """An ``argparse`` type: comma-separated frontends, each of :data:`FRONTENDS`."""
    chosen = [f.strip() for f in text.split(",") if f.strip()]
    if not chosen or any(f not in FRONTENDS for f in chosen):
        raise argparse.ArgumentTypeError(f"{text!r}: expected some of {', '.join(FRONTENDS)}")
    return chosen


# ------------------------------------------------------------------------------------------- independent
def independent(args) -> int:
    odometry = {"gyro_derotation": not args.no_derotation}
    with work_dir(args.out) as root:
        for name in names(args.recordings, REALISTIC):
            seq = standard(root, name)
            rec = Recording(seq)
            rows, vos = [plain_row(rec)], {}
            for fe in args.frontends:
                row, vos[fe] = frontend_row(rec, fe, odometry, args.options)
                rows.append(row)
            print_rows(f"{name}: {STANDARD[name][3]}", rows)
            if args.fusion:
                fused(seq, root / f"run_{name}", vos.get("klt"))
    return 0


def fused(seq: Path, run_dir: Path, klt) -> None:
    """``fusion-vo run --backend all`` on ``seq``: ATE of every track, the KLT increments against the truth,
    what the monitor dropped."""
    from fusion_vo.evaluation import evaluate_run

    try:
        run_pipeline(seq, run_dir, RunConfig(backend="all", evaluate=False))
    except InputError as exc:  # print it and go on with the next recording
        print(f"  fused (KLT, default configuration): failed: {exc}", flush=True)
        return
    metrics = evaluate_run(run_dir, seq)
    print("  fused (KLT, default configuration), ATE mm: "
          + ", ".join(f"{k} {metrics[k]['ate_m'] * 1e3:.2f}" for k in ("vo", "wheel", *summary_tracks(metrics))))
    rec = Recording(seq)
    c = against_truth(rec, klt if klt is not None else run_visual_odometry(Recording(seq)))
    print(f"  KLT increments against the truth: RMS error x {1e3 * c['camera rms x [m]']:.3f} mm (stated sigma, "
          f"median {1e3 * c['camera median sigma x [m]']:.3f}), yaw {1e3 * c['camera rms yaw [rad]']:.3f} mrad "
          f"({1e3 * c['camera median sigma yaw [rad]']:.3f}), mean NIS {c['camera mean NIS (3 if honest)']:.1f} "
          "(3 if honest)"
          + (f"; gyro scatter {1e3 * c['gyro scatter about the truth [rad/s]']:.2f} mrad/s (stated "
             f"{1e3 * c['gyro scatter stated [rad/s]']:.2f})" if "gyro scatter stated [rad/s]" in c else ""))
    for note in json.loads((run_dir / "summary.json").read_text()).get("notes", []):
        if "inconsistent" in note or "unavailable" in note:
            print(f"  monitor: {note}")


def summary_tracks(metrics: dict) -> list[str]:
    return [k for k in ("ekf", "ekf_smoothed", "gtsam", "gtsam_online") if k in metrics]


# ------------------------------------------------------------------------------------------- standard
def standard_checks(args) -> int:
    with work_dir(args.out) as root:
        recs = {name: standard(root, name) for name in ("square", "circle", "standstill", "random60")}
        rows = []
        for fe in [*args.frontends, "plain OpenCV script"]:
            m, fps = {}, []
            for name in ("square", "circle", "random60"):
                if fe == "plain OpenCV script":
                    rec = Recording(recs[name])
                    vo, _, results, seconds = baseline.odometry(rec)
                    reference = read_groundtruth(recs[name] / GROUNDTRUTH_CSV)
                    t = vo.track()
                    m[name] = evaluate_trajectory(reference, planar_trajectory(t.t, *t.xyyaw.T)).figures
                    fps.append((len(results) + 1) / seconds)
                else:
                    s = run_pipeline(recs[name], root / f"run_{fe}_{name}", RunConfig(frontend=fe, backend="none"))
                    m[name] = s.metrics["vo"]
                    fps.append(s.vo_fps)
            still_rec = Recording(recs["standstill"])
            if fe == "plain OpenCV script":
                vo, increments, _, _ = baseline.odometry(still_rec)
                track = vo.track()
            else:
                vo = run_visual_odometry(still_rec, RunConfig(frontend=fe).odometry_config())
                increments, track = vo.increments, vo.track
            still = max(float(np.hypot(*inc.delta[:2])) for inc in increments if inc.ok) * 1000
            drift = float(np.hypot(*track.xyyaw[-1, :2])) * 1000
            rows.append([fe, f"{m['square']['end_pct']:.3f} %", f"{m['square']['heading_deg']:.3f}°",
                         f"{m['circle']['heading_deg']:.3f}°", f"{still:.4f} mm", f"{drift:.4f} mm",
                         f"{m['random60']['end_pct']:.3f} % / {m['random60']['heading_deg']:.3f}°",
                         f"{np.mean(fps):.0f}"])
    print("\nself-consistency checks (rendered through the estimator's own camera model; end point and heading "
          "of the visual track, anchored at the start):")
    print(table(["frontend", "square: end-point error", "square: heading error", "circle: heading error after 360°",
                 "standstill: largest per-frame motion", "standstill: drift", "random60: end-point / heading",
                 "frames/s"], rows))
    print("targets: square <= 0.2 %, circle <= 0.3°, standstill <= 0.1 mm, random60 <= 0.5 % / 0.5°")
    return 0


# ------------------------------------------------------------------------------------------- lens
def true_lens_errors(name: str, size: tuple[int, int], models: dict[str, CameraModel]) -> str:
    """Worst / median reprojection [px] of the true lens's rays by each model, over a 17 x 13 grid."""
    truth = RealisticRenderer(RealisticCamera.from_dict(dict(STANDARD[name][2]["realistic"])), *size)
    gu, gv = np.meshgrid(np.linspace(0, size[0] - 1, 17), np.linspace(0, size[1] - 1, 13))
    pix = np.column_stack([gu.ravel(), gv.ravel()])
    rays = truth.lens.rays(pix)
    parts = []
    for label, model in models.items():
        err = np.linalg.norm(model.project(rays) - pix, axis=1)
        parts.append(f"{label} {err.max():.2f} / {np.median(err):.2f} px")
    return "; ".join(parts)


def board_calibrated(rec: Recording, name: str, n_views: int, work: Path, radial_terms: int, tilt: float):
    """The recording's camera with the lens calibrated from ``n_views`` rendered board views, and a line
    that says how."""
    options = dict(STANDARD[name][2]["realistic"])
    cam = RealisticCamera.from_dict({**options, "checker_size": 0.02, "checker_squares": [9, 6], "grain": 0.0,
                                     "rocking_deg": 0.0, "auto_exposure": 0.0, "defocus_per_metre": 0.0})
    model = rec.camera
    fisheye = cam.lens == "equisolid"
    if fisheye:
        distance = (0.10, 0.14)
    else:  # the 18 cm board spans about half the image width
        d = 0.18 / (0.5 * model.width / cam.focal)
        distance = (0.8 * d, 1.1 * d)
    work.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, img in enumerate(board_views(cam, model.width, model.height, n_views, distance=distance, shift=0.07,
                                        tilt=tilt)):
        paths.append(work / f"{name}_view{k:02d}.png")
        cv2.imwrite(str(paths[-1]), img)
    result = calibrate_images(paths, Board(8, 5, 0.02), model="fisheye" if fisheye else "pinhole",
                              radial_terms=2 if fisheye else radial_terms)
    K = result.K
    calibrated = CameraModel(model.width, model.height, K[0, 0], K[1, 1], K[0, 2], K[1, 2], result.distortion_model,
                             np.asarray(result.distortion, float), model.T_BS, model.rate_hz)
    how = (f"calibrated from {len(paths) - len(result.skipped)} of {len(paths)} board views "
           f"({'fisheye' if fisheye else f'radial-tangential, {radial_terms} radial terms'} model, "
           f"RMS {result.rms:.2f} px)")
    return calibrated, how


def lens(args) -> int:
    with work_dir(args.out) as root:
        for name in names(args.recordings, REALISTIC):
            seq = standard(root, name)
            rec = Recording(seq)
            fitted = rec.camera
            size = (fitted.width, fitted.height)
            pinhole = uncalibrated_camera(seq / "cam0" / "sensor.yaml")
            rows = [plain_row(rec)]
            if args.calibrate:
                model, how = board_calibrated(rec, name, args.calibrate, root / "calibration-views",
                                              args.radial_terms, args.board_tilt)
                rec.camera = model
                odometry = {}
            else:
                estimate_rec = Recording(seq)
                estimate_rec.camera = pinhole
                model, est = lens_from_motion(estimate_rec, pinhole)
                how = ("lens from the frames: " + ("none (not estimated)" if est is None
                                                   else f"lambda {est.lam:.4f} from {est.pairs} frame pairs"))
                odometry = {"uncalibrated": True}
            print(f"\n{name}: {how}; reprojection of the true lens, worst / median: "
                  + true_lens_errors(name, size, {"this lens": model, "pinhole of the focal length": pinhole,
                                                  "fitted model of sensor.yaml": fitted}), flush=True)
            for fe in args.frontends:
                rows.append(frontend_row(rec, fe, odometry)[0])
            mode = "calibrated from board views" if args.calibrate else "estimated from the frames (--uncalibrated)"
            print_rows(f"{name}, the lens {mode}", rows)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("independent", help="the independent renderer's recordings beside the plain script")
    p.add_argument("--recordings", help=f"comma-separated standard recordings (default {','.join(REALISTIC)})")
    p.add_argument("--frontends", type=frontends, default=list(FRONTENDS), help="comma-separated (default: all)")
    p.add_argument("--options", type=json.loads, default={}, metavar="JSON",
                   help='options of the frontends, e.g. \'{"grid_cell": 160}\' (with one --frontends)')
    p.add_argument("--no-derotation", action="store_true", help="do not use the gyro to remove roll and pitch")
    p.add_argument("--fusion", action="store_true", help="also fuse with wheels and IMU and print the ATE per track")
    add_out(p)
    p.set_defaults(func=independent)
    p = sub.add_parser("standard", help="self-consistency checks on the estimator's own camera model")
    p.add_argument("--frontends", type=frontends, default=["klt", "features"], help="comma-separated")
    add_out(p)
    p.set_defaults(func=standard_checks)
    p = sub.add_parser("lens", help="the lens estimated from the frames or calibrated from board views")
    p.add_argument("--recordings", help=f"comma-separated standard recordings (default {','.join(REALISTIC)})")
    p.add_argument("--frontends", type=frontends, default=list(FRONTENDS), help="comma-separated (default: all)")
    p.add_argument("--calibrate", type=int, default=0, metavar="N",
                   help="calibrate the lens from N rendered board views instead of estimating it from the frames")
    p.add_argument("--board-tilt", type=float, default=0.2, metavar="RAD", help="largest tilt of the board views")
    p.add_argument("--radial-terms", type=int, choices=[2, 3], default=2,
                   help="radial terms of the calibrated pinhole model (the fisheye model has its own)")
    add_out(p)
    p.set_defaults(func=lens)
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
