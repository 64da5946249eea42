"""Monte-Carlo consistency of the fused covariances: average NEES of (x, y, yaw) against the truth.

Each seed generates a drive with known sensor noise (:func:`fusion_vo.sensors.synthetic.synthetic_streams`:
camera increments, wheel encoders, gyro; no images, so a seed takes a fraction of a second), fuses it
with both backends (default configuration) and compares every fused pose with the truth, the track
anchored at the start as the backends are::

    e_k = (x̂_k - x_k, ŷ_k - y_k, wrap(ψ̂_k - ψ_k)),     NEES_k = e_kᵀ P_k⁻¹ e_k

(``P_k`` the pose covariance the backend reports, the same numbers ``fusion-vo run`` writes to
``NAME.cov.csv``). For a consistent estimator ``NEES_k`` is chi-square with 3 degrees of freedom: its
average over ``N`` seeds at one time lies in the 95 % band ``[χ²₃ₙ(0.025), χ²₃ₙ(0.975)] / N``. The table
prints, per backend, the NEES averaged over seeds and over the poses (the first second skipped: the
anchored start has no error), the fraction of times at which the seed-average lies inside the band,
and the band. A NEES above the band means the claimed uncertainty is too small (overconfident);
below, too large.

Usage::

    python benchmarks/consistency.py [--seeds 25] [--duration 30]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from scipy.stats import chi2

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.geometry import se2
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")


def nees_track(track, cov: np.ndarray, truth) -> np.ndarray:
    """NEES (N,) of each pose of ``track`` with covariances ``cov`` (N, 3, 3) against ``truth``."""
    gt = np.stack([np.interp(track.t, truth.t, truth.xyyaw[:, i]) for i in range(2)], axis=1)
    yaw = np.interp(track.t, truth.t, np.unwrap(truth.xyyaw[:, 2]))
    e = np.column_stack([track.xyyaw[:, :2] - gt, se2.wrap_angle(track.xyyaw[:, 2] - yaw)])
    out = np.full(len(e), np.nan)
    for k in range(len(e)):
        try:
            out[k] = float(e[k] @ np.linalg.solve(cov[k], e[k]))
        except np.linalg.LinAlgError:
            pass
    return out


def run(seeds: int, duration: float, sensors=("camera", "wheel", "imu")) -> dict[str, np.ndarray]:
    """Per backend, the NEES of every seed on a common time grid: (seeds, T)."""
    grid = np.arange(1.0, duration - 0.5, 0.25)
    out: dict[str, list] = {name: [] for name in FUSED}
    for seed in range(seeds):
        s = synthetic_streams(SyntheticOptions(duration=duration), seed=seed)
        streams = SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)
        result = fuse(streams.select(list(sensors)), "all", FusionConfig())
        for name in FUSED:
            track = result.trajectories[name]
            nees = nees_track(track, result.covariances[name], s.truth)
            out[name].append(np.interp(grid + track.t[0], track.t, nees))
    return {k: np.array(v) for k, v in out.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=25)
    parser.add_argument("--duration", type=float, default=30.0)
    args = parser.parse_args(argv)
    t0 = time.process_time()
    nees = run(args.seeds, args.duration)
    n = args.seeds
    lo, hi = chi2.ppf([0.025, 0.975], 3 * n) / n
    print(f"NEES of (x, y, yaw), {n} seeds of a {args.duration:.0f} s generated drive (camera, wheels, gyro), "
          f"{time.process_time() - t0:.1f} s CPU")
    print(f"consistent: 3; 95 % band of a {n}-seed average: [{lo:.2f}, {hi:.2f}]")
    print(f"  {'backend':14s} {'mean NEES':>10s} {'median':>8s} {'in band':>8s}  verdict")
    for name, v in nees.items():
        avg = np.nanmean(v, axis=0)
        mean = float(np.nanmean(avg))
        inside = float(np.mean((avg >= lo) & (avg <= hi)))
        verdict = "consistent" if lo <= mean <= hi else ("overconfident" if mean > hi else "pessimistic")
        print(f"  {name:14s} {mean:10.2f} {float(np.nanmedian(avg)):8.2f} {100 * inside:7.0f} %  {verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
