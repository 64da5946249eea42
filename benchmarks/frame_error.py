"""The camera's frame errors (``fusion.visual_frame_error``) on the standard recordings and on generated streams.

For each standard recording named (default: those of ``benchmarks/fusion_vs_best.py``), this generates it
(or reuses it from ``--out``), runs visual odometry once (default configuration, KLT) and fuses the same
increments with the default configuration and with each ``visual_frame_error`` of ``--values``, printing the
ATE [mm] of every fused track beside visual odometry's. ``--synthetic`` also fuses streams generated with
frame errors (:class:`fusion_vo.sensors.synthetic.SyntheticOptions`, ``visual_frame_error`` 0.5, 4 seeds of a
20 s drive with camera, wheels and gyro) with and without the model, printing each backend's RMS position
error and the mean NEES of its heading (1 when the heading covariance is honest).

Run::

    python benchmarks/frame_error.py [--out DIR] [--only square,gps_outage] [--values 0.5] [--synthetic]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from fusion_vo import backends
from fusion_vo.backends import FusionConfig, fuse
from fusion_vo.odometry import run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams
from fusion_vo.simulation.standard import STANDARD, make_standard

sys.path.insert(0, str(Path(__file__).parent))
from fusion_vs_best import FUSED, SKIP, ate_against  # noqa: E402

TRUE_FRAME_ERROR = 0.5


def recordings(names: list[str], out: Path, values: list[float]) -> None:
    print("recording | vo | frame error | " + " | ".join(FUSED) + "   (ATE mm)")
    for name in names:
        seq = out / name
        if not (seq / "simulation.yaml").exists():
            make_standard(name, seq)
        rec = Recording(seq)
        vo = run_visual_odometry(rec)
        ate = ate_against(rec)
        vo_ate = ate(vo.track)
        for f in [0.0, *values]:
            result = backends.run_backends(rec, vo, backend="all", options={"visual_frame_error": f})
            print(f"{name} | {vo_ate:.3f} | {f:g} | " + " | ".join(f"{ate(result.trajectories[k]):.3f}" for k in FUSED),
                  flush=True)


def synthetic(seeds: int = 4) -> None:
    rows = {}
    for model in (0.0, TRUE_FRAME_ERROR):
        for seed in range(seeds):
            s = synthetic_streams(SyntheticOptions(duration=20.0, visual_frame_error=TRUE_FRAME_ERROR,
                                                   visual_sigma_yaw=0.003), seed=seed)
            streams = backends.SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)
            result = fuse(streams.select(["camera", "wheel", "imu"]), "all", FusionConfig(visual_frame_error=model))
            for name in FUSED:
                track, cov = result.trajectories[name], result.covariances[name]
                truth = np.stack([np.interp(track.t, s.truth.t, s.truth.xyyaw[:, i]) for i in range(2)]
                                 + [np.interp(track.t, s.truth.t, np.unwrap(s.truth.xyyaw[:, 2]))], axis=1)
                rms = float(np.sqrt(np.mean(np.sum((track.xyyaw[:, :2] - truth[:, :2]) ** 2, axis=1))))
                yaw = np.angle(np.exp(1j * (track.xyyaw[:, 2] - truth[:, 2])))
                nees = float(np.mean(yaw[10:] ** 2 / cov[10:, 2, 2]))
                rows.setdefault((model, name), []).append((rms, nees))
    print(f"generated streams with frame errors ({TRUE_FRAME_ERROR}), {seeds} seeds of 20 s; RMS position error [mm] "
          "and mean heading NEES (1 if honest):")
    for name in FUSED:
        cells = []
        for model in (0.0, TRUE_FRAME_ERROR):
            a = np.array(rows[(model, name)])
            cells.append(f"model {model:g}: {1e3 * a[:, 0].mean():.2f} mm, NEES {a[:, 1].mean():.2f}")
        print(f"  {name:14s} " + "; ".join(cells))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="keep (or reuse) the recordings here (default: a temporary folder)")
    parser.add_argument("--only", help="comma-separated standard recordings")
    parser.add_argument("--values", default="0.5", help="comma-separated visual_frame_error values (default 0.5)")
    parser.add_argument("--synthetic", action="store_true", help="also fuse generated streams with frame errors")
    args = parser.parse_args(argv)
    names = args.only.split(",") if args.only else [n for n in STANDARD if n not in SKIP]
    out = args.out or Path(tempfile.mkdtemp(prefix="frame-error-"))
    try:
        recordings(names, out, [float(v) for v in args.values.split(",")])
    finally:
        if args.out is None:
            shutil.rmtree(out, ignore_errors=True)
    if args.synthetic:
        synthetic()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
