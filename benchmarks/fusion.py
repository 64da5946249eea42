"""Fused tracks beside the best single sensor on the standard generated recordings.

For every standard recording with a camera and wheels (``fusion_vo.simulation.standard``; or those named with
``--only``) this generates it (or reuses it from ``--out``), runs ``fusion-vo run --backend all`` on it
(default configuration, KLT frontend, unless ``--config`` / ``--set`` / ``--sensors`` say otherwise) and prints:

* the ATE [mm] (RMS position error after SE(2) alignment) of visual odometry (``vo``) and wheel dead
  reckoning (``wheel``), the better of the two (the baseline: the best single sensor), and every fused
  track (EKF, EKF + RTS smoother, GTSAM batch, iSAM2);
* whether every fused track is at most the best single sensor, the RTS-smoothed EKF at most the EKF, and
  GTSAM batch at most iSAM2;
* the largest difference [percentage points] between a fused track's leg-length error and visual
  odometry's over the straight legs of the ground truth (``legs`` of ``metrics.json``).

With ``--seeds N`` every recording is also generated with ``N`` other seeds (the same profile and options,
seeds ``seed + 100 i``), and a summary per recording prints, over the standard seed and these, the mean ATE
of every track, each fused track's mean relative difference from the best single input of its seed and on
how many seeds it is at most that input, and the same for the RTS smoother against the EKF and GTSAM batch
against iSAM2 and the EKF: what tells a systematic loss from the chance of one drive. A seed whose best
input has an ATE of 0 (a drive that does not move) is left out of those comparisons.

With ``--live`` each recording's streams are also fed to ``StreamingFusion`` (EKF and iSAM2) in time order
(``time_ordered_messages``), and a line under its row prints the largest position difference of each live track
from the batch run's online track (``ekf``, ``gtsam_online``) over their common nodes, and both ATEs: where the
live engine and the batch run part (docs/streaming.md, "The same estimator as a batch run").

When the run estimated the camera's heading noise from the gyro's (``--set fusion.visual_noise.estimate=true``)
the estimate is printed under the row.

Usage::

    python benchmarks/fusion.py [--only square,circle] [--seeds N] [--sensors camera,wheel] [--live]
        [--config FILE] [--set KEY=VALUE ...] [--out DIR]

Generation renders every frame: the whole set takes several minutes on two cores (``--out`` keeps it).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from common import FUSED, add_out, add_settings, ate_mm, describe_settings, names, parser, run_config, standard, work_dir

from fusion_vo.backends import fuse, streams_from_recording
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.evaluation import evaluate_run
from fusion_vo.odometry import run_visual_odometry
from fusion_vo.pipeline import run_pipeline
from fusion_vo.recording import Recording
from fusion_vo.simulation.standard import STANDARD

SINGLE = ("vo", "wheel")
#: standard recordings without a camera-and-wheels drive to compare (calibration manoeuvres, no motion)
SKIP = ("standstill", "turn_in_place", "straight", "umbmark_cw", "umbmark_ccw")


def leg_gap(metrics: dict, name: str) -> float:
    """Largest |leg error of ``name`` - leg error of vo| [percentage points] (NaN without legs)."""
    vo, other = metrics["vo"].get("legs") or [], metrics[name].get("legs") or []
    gaps = [abs(a["error_pct"] - b["error_pct"]) for a, b in zip(vo, other)]
    return max(gaps) if gaps else float("nan")


def compare(seq, run_dir, config) -> dict:
    """Run the pipeline on ``seq`` and return the figures of one table row."""
    run_pipeline(seq, run_dir, config)
    summary = json.loads((run_dir / "summary.json").read_text())
    metrics = evaluate_run(run_dir, seq)
    ate = {k: metrics[k]["ate_m"] * 1e3 for k in (*SINGLE, *FUSED) if k in metrics}
    best = min(ate[k] for k in SINGLE if k in ate)
    return {"ate": ate, "best": best, "legs": {k: leg_gap(metrics, k) for k in FUSED if k in metrics},
            "fused_le_best": all(ate[k] <= best for k in FUSED if k in ate),
            "smoothed_le_ekf": ate.get("ekf_smoothed", 0) <= ate.get("ekf", 0),
            "batch_le_online": ate.get("gtsam", 0) <= ate.get("gtsam_online", 0),
            "visual_noise": (summary.get("fusion") or {}).get("visual_noise") or {}}


def live_beside_batch(seq, config) -> str:
    """The live engine fed ``seq``'s streams in time order beside the batch run's online tracks: per backend the
    largest position difference over their common nodes [m] and both ATEs [mm]."""
    rec = Recording(seq)
    vo = run_visual_odometry(rec, config.odometry_config()) if rec.has("cam0") else None
    streams = streams_from_recording(rec, vo, config.sensors, config.fusion)
    batch = fuse(streams, "all", config.fusion)
    truth = rec.groundtruth()
    cells = []
    for backend, name in (("ekf", "EKF"), ("gtsam", "iSAM2")):
        track_name = "ekf" if backend == "ekf" else "gtsam_online"
        fusion = streaming_for(streams, backend, config.fusion)
        fusion.feed(time_ordered_messages(streams))
        live, ref = fusion.finish().trajectories[track_name], batch.trajectories[track_name]
        common = np.intersect1d(live.t, ref.t)
        a, b = live.xyyaw[np.isin(live.t, common), :2], ref.xyyaw[np.isin(ref.t, common), :2]
        gap = float(np.max(np.linalg.norm(a - b, axis=1))) if len(common) else float("nan")
        cells.append(f"{name} live - batch {gap:.1e} m on {len(common)}/{len(ref.t)} nodes, ATE batch "
                     f"{ate_mm(truth, ref):.3f} / live {ate_mm(truth, live):.3f} mm")
    return "    live: " + "; ".join(cells)


def relative(rows: list[dict], track: str, reference: str) -> np.ndarray:
    """Per seed the relative ATE difference ``track / reference - 1`` (``reference`` may be ``"best"``, the
    best single input of that seed), seeds where ``reference``'s ATE is 0 left out."""
    def value(r, k):
        return r["best"] if k == "best" else r["ate"].get(k)

    return np.array([value(r, track) / value(r, reference) - 1.0 for r in rows
                     if value(r, track) is not None and value(r, reference) is not None and value(r, reference) > 0])


def comparison(rows: list[dict], track: str, reference: str, label: str) -> str:
    """``label``, the mean relative ATE difference [%] of ``track`` against ``reference`` and on how many
    seeds ``track`` is at most ``reference`` (empty when neither is there)."""
    d = relative(rows, track, reference)
    if not len(d):
        return ""
    return f"{label} {100 * d.mean():+.1f} % on average, at most on {int(np.sum(d <= 0))} of {len(d)}"


def seed_summary(rows: list[dict]) -> list[str]:
    """Lines summarising several seeds of one drive: the mean ATE [mm] of every track; each fused track against
    the best single input; the smoothers against their filters and GTSAM batch against the EKF."""
    tracks = [k for k in (*SINGLE, "best", *FUSED) if all(k == "best" or k in r["ate"] for r in rows)]
    means = ", ".join(f"{k} {np.mean([r['best'] if k == 'best' else r['ate'][k] for r in rows]):.3f}" for k in tracks)
    return [f"mean ATE [mm] {means}",
            "fused vs best input: " + "; ".join(c for k in FUSED if (c := comparison(rows, k, "best", k))),
            "; ".join(c for c in (comparison(rows, "ekf_smoothed", "ekf", "RTS vs EKF"),
                                  comparison(rows, "gtsam", "gtsam_online", "batch vs iSAM2"),
                                  comparison(rows, "gtsam", "ekf", "batch vs EKF")) if c)]


def _num(value, fmt: str = ".2f") -> str:
    return "-" if value is None else format(value, fmt)


def visual_noise_line(label: str, vn: dict) -> str:
    return (f"    {label} camera heading noise estimated: variance scale {_num(vn.get('scale'))} ± "
            f"{_num(vn.get('scale_se'))} ({'applied' if vn.get('scale_applied') else 'not applied'}), lag-1 "
            f"correlation {_num(vn.get('correlation'), '+.2f')} ± {_num(vn.get('correlation_se'))} -> f "
            f"{_num(vn.get('frame_error'))} ({'applied' if vn.get('frame_error_applied') else 'not applied'}), "
            f"{vn.get('intervals')} intervals")


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--only", help="comma-separated standard recordings (default: all with camera and wheels)")
    ap.add_argument("--seeds", type=int, default=0, help="also generate every recording with this many other seeds")
    ap.add_argument("--sensors", help="comma-separated sensors to fuse (default: the camera, wheels and IMU)")
    ap.add_argument("--live", action="store_true", help="also the live engine beside the batch run's online tracks")
    add_settings(ap)
    add_out(ap)
    args = ap.parse_args(argv)
    chosen = names(args.only, [n for n in STANDARD if n not in SKIP])
    fixed = {"backend": "all", "evaluate": False}
    if args.sensors:
        fixed["sensors"] = [s.strip() for s in args.sensors.split(",") if s.strip()]
    config = run_config(args, **fixed)
    print(f"ATE [mm] after SE(2) alignment, {describe_settings(args)}"
          + (f", sensors {args.sensors}" if args.sensors else ""))
    print("| recording | " + " | ".join([*SINGLE, "best", *FUSED, "fused <= best", "RTS <= EKF", "batch <= iSAM2",
                                         "leg gap [points]"]) + " |")
    print("|" + "---|" * 12, flush=True)
    with work_dir(args.out, "fusion-") as out:
        for name in chosen:
            seed = STANDARD[name][1]
            rows = []
            for i in range(args.seeds + 1):
                t0 = time.perf_counter()
                label = name if i == 0 else f"{name} (seed {seed + 100 * i})"
                folder = "" if i == 0 else f"_seed{seed + 100 * i}"
                seq = standard(out, name, 100 * i, folder)
                r = compare(seq, out / f"run_{name}{folder}", config)
                rows.append(r)
                cells = [label, *(f"{r['ate'].get(k, float('nan')):.3f}" for k in SINGLE), f"{r['best']:.3f}",
                         *(f"{r['ate'].get(k, float('nan')):.3f}" for k in FUSED),
                         *("yes" if r[k] else "NO" for k in ("fused_le_best", "smoothed_le_ekf", "batch_le_online")),
                         f"{max(r['legs'].values()):.3f}"]
                print("| " + " | ".join(cells) + f" |   ({time.perf_counter() - t0:.0f} s)", flush=True)
                if r["visual_noise"]:
                    print(visual_noise_line(label, r["visual_noise"]), flush=True)
                if args.live:
                    print(live_beside_batch(seq, config), flush=True)
            if args.seeds:
                for line in seed_summary(rows):
                    print(f"    {name}, {len(rows)} seeds: {line}", flush=True)
    print("leg gap: largest difference of a fused track's leg-length error from visual odometry's")
    return 0


if __name__ == "__main__":
    sys.exit(main())
