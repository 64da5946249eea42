"""The camera's heading noise estimated from the gyro's, beside the truth, and what each does to the fused tracks.

For every standard generated recording with a camera, wheels and a gyro (or those named with ``--only``) this
runs visual odometry once (default configuration, KLT) and prints:

* the truth-based values: the mean ``e²/σ²`` of the single-interval increments' heading errors against
  their stated variance, and the lag-1 correlation of consecutive heading errors (what
  ``fusion_vs_best.py --sensors`` prints), and ``f = -2 ρ`` clipped to ``[0, 0.9]``;
* the estimate of :mod:`fusion_vo.sensors.visual_noise` (no ground truth), with its standard errors and
  what it applies;
* the fused ATE [mm] (EKF / EKF + RTS / GTSAM batch / iSAM2) of the same increments with the default
  configuration, with ``fusion.visual_noise.estimate``, with the estimate applied however uncertain, and
  with the truth-based scale and ``f`` (what a perfect estimate would give; not something a user has).

Run::

    python benchmarks/visual_noise.py [--out DIR] [--only square,gps_outage]

``--out`` keeps the recordings (a recording already there is reused).
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import tempfile
from pathlib import Path

import numpy as np

from fusion_vs_best import FUSED, SKIP, ate_against

from fusion_vo import backends
from fusion_vo.backends.batch import as_config, streams_from_recording, with_recorded_noise
from fusion_vo.backends.timeline import build_intervals
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.simulation.standard import STANDARD, make_standard

#: fusion options of the runs that need no change of the increments
RUNS = {
    "default": {},
    "estimate": {"visual_noise": {"estimate": True}},
    "forced": {"visual_noise": {"estimate": True, "scale_tolerance": 1e9, "frame_error_tolerance": 1e9}},
}


def truth_values(rec: Recording, increments) -> tuple[float, float]:
    """``(e²/σ², lag-1 correlation)`` of the single-interval increments' heading errors on the backends' grid."""
    config = as_config(None)
    streams = streams_from_recording(rec, increments, None, config)
    iv = build_intervals(streams, with_recorded_noise(config, streams))
    gt = rec.groundtruth()
    yaw = np.interp(iv.t, gt.t, np.unwrap(gt.xyyaw[:, 2]))
    single = iv.vis_i1 == iv.vis_i0 + 1
    error = np.full(iv.n_steps, np.nan)
    variance = np.full(iv.n_steps, np.nan)
    error[iv.vis_i0[single]] = iv.vis_delta[single, 2] - np.diff(yaw)[iv.vis_i0[single]]
    variance[iv.vis_i0[single]] = iv.vis_cov[single, 2, 2]
    a, b = error[:-1], error[1:]
    pair = np.isfinite(a) & np.isfinite(b)
    return float(np.nanmean(error**2 / variance)), float(np.corrcoef(a[pair], b[pair])[0, 1])


def scaled_heading(increments, scale: float):
    """``increments`` with their heading variance times ``scale`` (heading covariances times ``√scale``)."""
    root = np.sqrt(scale)
    factor = np.array([[1.0, 1.0, root], [1.0, 1.0, root], [root, root, scale]])
    return [dataclasses.replace(v, covariance=np.asarray(v.covariance) * factor) if v.ok else v for v in increments]


def _described(e: dict) -> str:
    """One line of an estimate (``FusionResult.visual_noise``)."""
    if e.get("scale") is None:
        return "none (too few intervals)"
    used = [w for w, on in (("scale", e["scale_applied"]), (f"f {e['frame_error']:.2f}", e["frame_error_applied"])) if on]
    return (f"scale {e['scale']:.2f} ± {e['scale_se']:.2f}, lag-1 correlation {e['correlation']:+.2f} ± "
            f"{e['correlation_se']:.2f}; used: {', '.join(used) or 'nothing'}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="keep (and reuse) the recordings here (default: a temporary folder)")
    parser.add_argument("--only", help="comma-separated standard recordings (default: all with camera and wheels)")
    args = parser.parse_args(argv)
    names = args.only.split(",") if args.only else [n for n in STANDARD if n not in SKIP]
    out = args.out or Path(tempfile.mkdtemp(prefix="visual-noise-"))
    print("ATE in mm, EKF / EKF + RTS / GTSAM batch / iSAM2")
    try:
        for name in names:
            seq = out / name
            if not (seq / "simulation.yaml").exists():
                seq = make_standard(name, seq)
            rec = Recording(seq)
            if not rec.has_imu():
                print(f"{name}: no gyro, skipped")
                continue
            vo = run_visual_odometry(rec, OdometryConfig())
            ate = ate_against(rec)
            z2, rho = truth_values(rec, vo.increments)
            f = float(np.clip(-2.0 * rho, 0.0, 0.9))
            print(f"{name}: vo {ate(vo.track):.3f}; truth: heading e²/σ² {z2:.2f}, lag-1 correlation {rho:+.2f} "
                  f"(f {f:.2f})", flush=True)
            for label, options in RUNS.items():
                result = backends.run_backends(rec, vo, backend="all", options=options)
                estimate = result.visual_noise
                if label == "estimate" and estimate:
                    print(f"    estimate: {_described(estimate)}")
                print(f"    {label:9s} " + " / ".join(f"{ate(result.trajectories[k]):.3f}" for k in FUSED), flush=True)
            truth = dataclasses.replace(vo, increments=scaled_heading(vo.increments, z2))
            result = backends.run_backends(rec, truth, backend="all", options={"visual_frame_error": f})
            print(f"    {'truth':9s} " + " / ".join(f"{ate(result.trajectories[k]):.3f}" for k in FUSED), flush=True)
    finally:
        if args.out is None:
            shutil.rmtree(out, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
