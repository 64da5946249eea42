"""Every frontend beside the plain OpenCV script on the recordings of the independent renderer.

The recordings (``fusion_vo.simulation.standard.REALISTIC``, ``datasets/generated.md``) are rendered
through :mod:`fusion_vo.simulation.realistic`: lenses the estimator does not model (a four-term barrel
lens, a true equisolid fisheye), defocus, rolling shutter, motion blur, noise, auto-exposure, coarse
checkerboards. For each recording the script prints one table: per frontend the frame pairs measured,
the failures by reason, the end-point and heading error of the visual track alone (anchored at the
start, end-point in % of the path), the RMS speed error against ground truth, and frames per second
end to end (decode included, wall clock, one process). The plain script
(``benchmarks/baseline_opencv.py``, used unchanged) runs in the same process; its pixel similarities
become body motion through the same ground geometry with a distortion-free pinhole of the recording's
focal length (the script does not undistort), the same heights (range finder) and the same
constant-velocity bridging of failed frames.

    python benchmarks/bench_realistic.py [--data DIR] [--recordings a,b] [--frontends klt,direct]
                                         [--uncalibrated | --calibrate N [--radial-terms 3] [--board-tilt R]]
                                         [--no-derotation] [--fusion] [--options JSON]

``--uncalibrated`` runs the frontends without the lens model of ``sensor.yaml``: a pinhole of its focal
length with the lens estimated from the frames (:mod:`fusion_vo.calibration.lens_from_motion`), whose
reprojection of the true lens it prints. ``--calibrate N`` replaces the lens model by what
``fusion-vo calibrate intrinsics`` finds (:func:`fusion_vo.calibration.intrinsics.calibrate_images`) from
``N`` views of a printed 9 x 6 board (2 cm squares, tilted up to ``--board-tilt`` rad, default 0.2)
rendered through the recording's own lens
(:func:`fusion_vo.simulation.realistic.board_views`; the radial-tangential model for the barrel lens,
``--model fisheye`` for the fisheye; ``--radial-terms 3`` fits ``k3`` too), and prints how far that
model reprojects the true lens.

``--fusion`` also runs ``fusion-vo run --backend all`` (default configuration, KLT) on each recording
through :func:`fusion_vs_best.compare` and prints the ATE [mm, after SE(2) alignment] of visual
odometry, wheel dead reckoning and every fused track, and the per-sensor consistency against the truth
(:func:`fusion_vs_best.inputs_against_truth`: the KLT increments' RMS errors beside the standard
deviations their covariances state and their mean NIS, 3 when the covariance is honest; the gyro's
scatter about the true yaw rate beside the scatter its noise density states), then what the fusion's
consistency monitor dropped (the run's notes).

Recordings are generated into ``--data`` (default ``./realistic-data``) unless already there.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import baseline_opencv  # noqa: E402

from frontends.base import FrameMotion, MotionStatus  # noqa: E402
from fusion_vo.errors import InputError  # noqa: E402
from fusion_vo.geometry import se2  # noqa: E402
from fusion_vo.geometry.ground import GroundGeometry  # noqa: E402
from fusion_vo.measurements import PoseData  # noqa: E402
from fusion_vo.odometry import OdometryConfig, VisualOdometry, heights_for, run_visual_odometry  # noqa: E402
from fusion_vo.recording import Recording  # noqa: E402
from fusion_vo.simulation.standard import REALISTIC, STANDARD, make_standard  # noqa: E402

FRONTENDS = ("klt", "features", "direct")


@dataclasses.dataclass
class Row:
    name: str
    pairs: int
    measured: int
    failures: Counter
    end_pct: float
    heading_deg: float
    speed_rmse: float
    fps: float
    vo: object = None


def _gt_at(gt: PoseData, t: np.ndarray) -> np.ndarray:
    yaw = np.unwrap(gt.xyyaw[:, 2])
    return np.column_stack([np.interp(t, gt.t, gt.xyyaw[:, 0]), np.interp(t, gt.t, gt.xyyaw[:, 1]),
                            np.interp(t, gt.t, yaw)])


def score(track: PoseData, gt: PoseData) -> tuple[float, float, float]:
    """End-point error [% of path], heading error [deg], RMS speed error [m/s] of an anchored track."""
    ref = _gt_at(gt, track.t)
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


class _Replay:
    """A frontend that returns the plain script's precomputed similarities, one per frame."""

    def __init__(self, results):
        self._results = list(results)
        self._k = -1
        self._ref_t: float | None = None

    def process(self, image, t: float) -> FrameMotion:
        self._k += 1
        if self._k == 0:
            self._ref_t = t
            return FrameMotion(t, None, status=MotionStatus.FIRST)
        t0, t1, m = self._results[self._k - 1]
        prev = self._ref_t
        if m is None:
            return FrameMotion(t, prev, status=MotionStatus.TOO_FEW_FEATURES)
        self._ref_t = t
        return FrameMotion(t, prev, matrix=np.asarray(m, float), covariance=np.eye(4) * 1e-4, status=MotionStatus.OK)


def baseline_odometry(rec: Recording) -> tuple[VisualOdometry, list, list, float]:
    """The plain script (``baseline_opencv.run``) on ``rec`` turned into body motion (module docstring):
    its visual odometry, the body increments, the script's per-frame results and its run time [s]."""
    results, seconds = baseline_opencv.run(rec.path)
    cam = rec.camera
    plain = dataclasses.replace(cam, distortion_model="none", distortion=np.zeros(4))
    vo = VisualOdometry(_Replay(results), GroundGeometry(plain))
    times = rec.frame_times
    heights = heights_for(rec, times)
    increments = []
    for k, t in enumerate(times):
        _, inc = vo.process(None, float(t), None if heights is None else float(heights[k]))
        if inc is not None:
            increments.append(inc)
    return vo, increments, results, seconds


def run_baseline(rec: Recording) -> Row:
    vo, _, results, seconds = baseline_odometry(rec)
    measured = sum(m is not None for _, _, m in results)
    end, heading, speed = score(vo.track(), rec.groundtruth())
    return Row("plain OpenCV script", len(results), measured, Counter({"failed": len(results) - measured}),
               end, heading, speed, (len(results) + 1) / seconds)


def run_frontend(rec: Recording, frontend: str, odometry: dict, options: dict | None = None) -> Row:
    start = time.perf_counter()
    vo = run_visual_odometry(rec, OdometryConfig(frontend=frontend, frontend_options=dict(options or {}), **odometry))
    seconds = time.perf_counter() - start
    pairs = len(vo.status) - 1
    measured = sum(s == "ok" for s in vo.status)
    end, heading, speed = score(vo.track, rec.groundtruth())
    return Row(frontend, pairs, measured, vo.failures, end, heading, speed, len(vo.status) / seconds, vo)


def calibrated_camera(rec: Recording, name: str, n_views: int, work: Path, radial_terms: int = 2,
                      tilt: float = 0.2):
    """The recording's camera with the lens model calibrated from ``n_views`` rendered board views."""
    import cv2

    from fusion_vo.calibration.chessboard import Board
    from fusion_vo.calibration.intrinsics import calibrate_images
    from fusion_vo.geometry.camera import CameraModel
    from fusion_vo.simulation.realistic import RealisticCamera, RealisticRenderer, board_views

    options = dict(STANDARD[name][2]["realistic"])
    cam = RealisticCamera.from_dict({**options, "checker_size": 0.02, "checker_squares": [9, 6], "grain": 0.0,
                                     "rocking_deg": 0.0, "auto_exposure": 0.0, "defocus_per_metre": 0.0})
    model = rec.camera
    size = (model.width, model.height)
    fisheye = cam.lens == "equisolid"
    if fisheye:
        distance = (0.10, 0.14)
    else:  # the 18 cm board spans about half the image width
        d = 0.18 / (0.5 * size[0] / cam.focal)
        distance = (0.8 * d, 1.1 * d)
    work.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, img in enumerate(board_views(cam, *size, n_views, distance=distance, shift=0.07, tilt=tilt)):
        paths.append(work / f"{name}_view{k:02d}.png")
        cv2.imwrite(str(paths[-1]), img)
    result = calibrate_images(paths, Board(8, 5, 0.02), model="fisheye" if fisheye else "pinhole",
                              radial_terms=2 if fisheye else radial_terms)
    K = result.K
    calibrated = CameraModel(model.width, model.height, K[0, 0], K[1, 1], K[0, 2], K[1, 2],
                             result.distortion_model, np.asarray(result.distortion, float), model.T_BS, model.rate_hz)
    # reprojection of the true lens's rays by the calibrated model, over the whole image
    truth = RealisticRenderer(RealisticCamera.from_dict(options), *size)
    gu, gv = np.meshgrid(np.linspace(0, size[0] - 1, 17), np.linspace(0, size[1] - 1, 13))
    pix = np.column_stack([gu.ravel(), gv.ravel()])
    rays = truth.lens.rays(pix)
    err = {label: np.linalg.norm(m.project(rays) - pix, axis=1)
           for label, m in (("calibrated", calibrated), ("sensor.yaml", model))}
    print(f"\n{name}: calibrated from {len(paths) - len(result.skipped)} of {len(paths)} views "
          f"({'fisheye' if fisheye else f'radial-tangential, {radial_terms} radial terms'} model, RMS "
          f"{result.rms:.2f} px); reprojection of the "
          f"true lens, worst / median: calibrated {err['calibrated'].max():.2f} / {np.median(err['calibrated']):.2f} "
          f"px, sensor.yaml's fitted model {err['sensor.yaml'].max():.2f} / {np.median(err['sensor.yaml']):.2f} px")
    return calibrated


def lens_estimate_report(rec: Recording, name: str) -> None:
    """Print the lens that ``--uncalibrated`` estimates from the frames and how far it reprojects the true lens."""
    from fusion_vo.calibration.lens_from_motion import lens_from_motion
    from fusion_vo.geometry.camera import uncalibrated_camera
    from fusion_vo.simulation.realistic import RealisticCamera, RealisticRenderer

    pinhole = uncalibrated_camera(rec.path / "cam0" / "sensor.yaml")
    rec.camera = pinhole
    estimated, est = lens_from_motion(rec, pinhole)
    size = (pinhole.width, pinhole.height)
    truth = RealisticRenderer(RealisticCamera.from_dict(dict(STANDARD[name][2]["realistic"])), *size)
    gu, gv = np.meshgrid(np.linspace(0, size[0] - 1, 17), np.linspace(0, size[1] - 1, 13))
    pix = np.column_stack([gu.ravel(), gv.ravel()])
    rays = truth.lens.rays(pix)
    err = {label: np.linalg.norm(m.project(rays) - pix, axis=1) for label, m in (("estimated", estimated),
                                                                                ("pinhole", pinhole))}
    lam = "none (not estimated)" if est is None else f"lambda {est.lam:.4f} from {est.pairs} frame pairs"
    print(f"\n{name}: lens from the frames: {lam}; reprojection of the true lens, worst / median: estimated "
          f"{err['estimated'].max():.2f} / {np.median(err['estimated']):.2f} px, pinhole of the focal length "
          f"{err['pinhole'].max():.2f} / {np.median(err['pinhole']):.2f} px")


def print_table(name: str, rows: list[Row]) -> None:
    print(f"\n{name}: {STANDARD[name][3]}")
    print(f"  {'frontend':<20} {'measured':>11} {'failures by reason':<34} {'end-point %':>11} "
          f"{'heading deg':>11} {'speed RMS mm/s':>14} {'frames/s':>8}")
    for r in rows:
        fails = ", ".join(f"{k} {v}" for k, v in sorted(r.failures.items()) if v) or "none"
        print(f"  {r.name:<20} {r.measured:>5}/{r.pairs:<5} {fails:<34} {r.end_pct:11.3f} {r.heading_deg:11.3f} "
              f"{1000 * r.speed_rmse:14.2f} {r.fps:8.1f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="realistic-data", help="folder of the recordings (generated when missing)")
    ap.add_argument("--recordings", default=",".join(REALISTIC), help="comma-separated standard names")
    ap.add_argument("--frontends", default=",".join(FRONTENDS))
    ap.add_argument("--uncalibrated", action="store_true",
                    help="run the frontends without the lens distortion of sensor.yaml (its focal length only)")
    ap.add_argument("--calibrate", type=int, default=0, metavar="N",
                    help="replace the lens model by one calibrated from N rendered board views")
    ap.add_argument("--board-tilt", type=float, default=0.2, metavar="RAD",
                    help="largest tilt of the rendered board views (--calibrate)")
    ap.add_argument("--radial-terms", type=int, choices=[2, 3], default=2,
                    help="radial terms of the calibrated pinhole model (--calibrate; the fisheye model has its own)")
    ap.add_argument("--no-derotation", action="store_true", help="do not use the gyro to remove roll and pitch")
    ap.add_argument("--options", type=json.loads, default={}, metavar="JSON",
                    help='options of the frontends, e.g. \'{"grid_cell": 160}\' (with one --frontends)')
    ap.add_argument("--fusion", action="store_true", help="also fuse with wheels and IMU and print the ATE per track")
    args = ap.parse_args(argv)
    if args.calibrate and args.uncalibrated:
        ap.error("--calibrate and --uncalibrated exclude each other")
    odometry = {"uncalibrated": args.uncalibrated, "gyro_derotation": not args.no_derotation}
    root = Path(args.data)
    for name in args.recordings.split(","):
        seq = root / name
        if not (seq / "simulation.yaml").is_file():
            print(f"generating {name} ...", flush=True)
            make_standard(name, seq)
        rec = Recording(seq)
        rows = [run_baseline(rec)]
        if args.calibrate:
            rec.camera = calibrated_camera(rec, name, args.calibrate, root / "calibration-views", args.radial_terms,
                                           args.board_tilt)
        if args.uncalibrated:
            lens_estimate_report(Recording(seq), name)
        for fe in args.frontends.split(","):
            rows.append(run_frontend(rec, fe, odometry, args.options))
        print_table(name, rows)
        if args.fusion:
            import fusion_vs_best

            try:
                r = fusion_vs_best.compare(seq, root / f"run_{name}")
            except InputError as exc:  # print it and go on with the next recording
                print(f"  fused (KLT, default configuration): failed: {exc}", flush=True)
                continue
            print("  fused (KLT, default configuration), ATE mm: "
                  + ", ".join(f"{k} {v:.2f}" for k, v in r["ate"].items()), flush=True)
            klt = next((row.vo for row in rows if row.name == "klt"), None)
            if klt is None:
                klt = run_visual_odometry(Recording(seq))
            c = fusion_vs_best.inputs_against_truth(Recording(seq), klt)
            print(f"  consistency against the truth: camera RMS error x {1e3 * c['camera rms x [m]']:.3f} mm "
                  f"(stated sigma, median {1e3 * c['camera median sigma x [m]']:.3f}), yaw "
                  f"{1e3 * c['camera rms yaw [rad]']:.3f} mrad ({1e3 * c['camera median sigma yaw [rad]']:.3f}), "
                  f"mean NIS {c['camera mean NIS (3 if honest)']:.1f} (3 if honest)"
                  + (f"; gyro scatter {1e3 * c['gyro scatter about the truth [rad/s]']:.2f} mrad/s (stated "
                     f"{1e3 * c['gyro scatter stated [rad/s]']:.2f})" if "gyro scatter stated [rad/s]" in c else ""))
            summary = json.loads((root / f"run_{name}" / "summary.json").read_text())
            for note in summary.get("notes", []):
                if "inconsistent" in note or "unavailable" in note:
                    print(f"  monitor: {note}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
