"""The wheels' curvature bias with nothing but the wheels and a gyro: estimated or not, beside the wheels alone.

Generated drives (:func:`fusion_vo.sensors.synthetic.synthetic_streams`, 120 s, gyro bias 0.01 rad/s, no camera,
no AHRS heading, no GPS) are fused with the encoder wheels and the gyro, with the left wheel's radius stated
``e`` too large and the right one's ``e`` too small (a true curvature bias of ``-2 e / b``), for ``e`` = 0,
0.5 % and 1 % (the default prior on each radius is 1 %, ``wheel_scale_sigma``). For each ``e`` it prints
the RMS position error [mm] over the seeds (each seed's RMS error against the truth, same start, no
alignment) of the wheels alone and of every fused track, with the curvature bias estimated
(``fusion.wheel.estimate_curvature: true``) and not (``false``); ``"auto"``, the default, does not estimate
it in this configuration (:func:`fusion_vo.sensors.wheel.curvature_observable`).

Run::

    python benchmarks/curvature_without_heading.py [--seeds 4] [--duration 120]

About 1 minute per seed on two cores.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

TRACKS = ("wheel", "ekf", "ekf_smoothed", "gtsam", "gtsam_online")
ERRORS = (0.0, 0.005, 0.01)


def rms_error(track, truth) -> float:
    """RMS position error [m] of ``track`` against ``truth`` at the track's times (same start, no alignment)."""
    gt = np.stack([np.interp(track.t, truth.t, truth.xyyaw[:, i]) for i in range(2)], axis=1)
    return float(np.sqrt(np.mean(np.sum((track.xyyaw[:, :2] - gt) ** 2, axis=1))))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=4, help="seeds 1..N (default 4)")
    parser.add_argument("--duration", type=float, default=120.0, help="drive length [s] (default 120)")
    args = parser.parse_args(argv)
    errors: dict[tuple, list[float]] = {}
    for e in ERRORS:
        for seed in range(1, args.seeds + 1):
            s = synthetic_streams(SyntheticOptions(duration=args.duration), seed=seed)
            cfg = s.wheel.config
            wheel = dataclasses.replace(s.wheel, config=dataclasses.replace(
                cfg, wheel_radius_left=cfg.wheel_radius_left * (1 + e), wheel_radius_right=cfg.wheel_radius_right * (1 - e)))
            streams = SensorStreams(wheel=wheel, imu=s.imu)
            for on in (True, False):
                result = fuse(streams, "all", FusionConfig.from_dict({"wheel": {"estimate_curvature": on}}))
                for name in TRACKS:
                    errors.setdefault((e, on, name), []).append(rms_error(result.trajectories[name], s.truth))
    print(f"RMS position error [mm] over seeds 1-{args.seeds}, {args.duration:.0f} s wheel + gyro drives")
    print(f"  {'radius error e':>14s} {'curvature':>9s} " + " ".join(f"{n:>13s}" for n in TRACKS))
    for e in ERRORS:
        for on in (True, False):
            row = [1000 * float(np.sqrt(np.mean(np.square(errors[(e, on, n)])))) for n in TRACKS]
            print(f"  {100 * e:13.1f}% {'estimated' if on else 'fixed 0':>9s} " + " ".join(f"{v:13.0f}" for v in row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
