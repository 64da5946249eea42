"""Fused tracks beside the best single sensor on the standard generated recordings.

For every recording of ``fusion_vo.simulation.standard`` that has a camera and wheels (or the ones
named with ``--only``), this generates it, runs ``fusion-vo run --backend all`` on it (default
configuration, KLT frontend) and prints, per recording:

* the ATE [mm] (RMS position error after SE(2) alignment) of visual odometry (``vo``), wheel dead
  reckoning (``wheel``), the best of those two, and every fused track;
* whether each fused track's ATE is at most the best single sensor's, the RTS-smoothed EKF at most the
  EKF, and GTSAM batch at most iSAM2;
* the largest difference [percentage points] between a fused track's leg-length error and visual
  odometry's over the straight legs of the ground truth (``legs`` of ``metrics.json``).

Run::

    python benchmarks/fusion_vs_best.py [--out DIR] [--only square,circle]

Generation renders every frame, so the whole set takes several minutes on two cores.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from fusion_vo.config import RunConfig
from fusion_vo.evaluation import evaluate_run
from fusion_vo.pipeline import run_pipeline
from fusion_vo.simulation.standard import STANDARD, make_standard

FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
SINGLE = ("vo", "wheel")
#: standard recordings without a camera-and-wheels drive to compare (calibration manoeuvres, no motion)
SKIP = ("standstill", "turn_in_place", "straight", "umbmark_cw", "umbmark_ccw")


def leg_gap(metrics: dict, name: str) -> float:
    """Largest |leg error of ``name`` - leg error of vo| [percentage points] (NaN without legs)."""
    vo, other = metrics["vo"].get("legs") or [], metrics[name].get("legs") or []
    gaps = [abs(a["error_pct"] - b["error_pct"]) for a, b in zip(vo, other)]
    return max(gaps) if gaps else float("nan")


def compare(seq: Path, run_dir: Path) -> dict:
    """Run the pipeline on ``seq`` and return the figures of one table row per track."""
    run_pipeline(seq, run_dir, RunConfig(backend="all", evaluate=False))
    metrics = evaluate_run(run_dir, seq)
    ate = {k: metrics[k]["ate_m"] * 1e3 for k in (*SINGLE, *FUSED) if k in metrics}
    best = min(ate[k] for k in SINGLE if k in ate)
    return {
        "ate": ate,
        "best": best,
        "legs": {k: leg_gap(metrics, k) for k in FUSED if k in metrics},
        "fused_le_best": all(ate[k] <= best for k in FUSED if k in ate),
        "smoothed_le_ekf": ate.get("ekf_smoothed", 0) <= ate.get("ekf", 0),
        "batch_le_online": ate.get("gtsam", 0) <= ate.get("gtsam_online", 0),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="keep the recordings and runs here (default: a temporary folder)")
    parser.add_argument("--only", help="comma-separated standard recordings (default: all with camera and wheels)")
    args = parser.parse_args(argv)
    names = args.only.split(",") if args.only else [n for n in STANDARD if n not in SKIP]
    out = args.out or Path(tempfile.mkdtemp(prefix="fusion-vs-best-"))
    header = ["recording", *SINGLE, "best", *FUSED, "fused<=best", "rts<=ekf", "batch<=isam2", "max leg gap %"]
    print(" | ".join(header))
    try:
        for name in names:
            t0 = time.perf_counter()
            seq = make_standard(name, out / name)
            r = compare(seq, out / f"run_{name}")
            cells = [name, *(f"{r['ate'].get(k, float('nan')):.3f}" for k in SINGLE), f"{r['best']:.3f}",
                     *(f"{r['ate'].get(k, float('nan')):.3f}" for k in FUSED),
                     *("yes" if r[k] else "NO" for k in ("fused_le_best", "smoothed_le_ekf", "batch_le_online")),
                     f"{max(r['legs'].values()):.3f}"]
            print(" | ".join(cells), f"  ({time.perf_counter() - t0:.0f} s)", flush=True)
    finally:
        if args.out is None:
            shutil.rmtree(out, ignore_errors=True)
    print("ATE in mm; leg gap: largest difference of a fused track's leg-length error from visual odometry's")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
