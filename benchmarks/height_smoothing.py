"""The camera height from a range finder: each frame's own readings, or all readings with the frames' scale.

For each standard generated recording with a range finder (``tilted``: 0.1 m high, 1 mm vibration at
3 Hz, readings at 40 Hz with 0.5 mm noise; ``real_gravel_focal_only``: 9-11 cm at 0.2 Hz;
``real_fisheye_checker``: 0.15-0.35 m at 0.05 Hz through a fisheye), visual odometry (KLT, default
configuration) runs twice from the same frames:

- **baseline** (``odometry: {range_smoothing: false}``): each frame's translation scaled by the readings
  interpolated at its time, as a plain script would do;
- **smoothed** (the default): the heights of :mod:`fusion_vo.geometry.height`, every reading together with
  the frames' height ratios.

Printed per recording: the heights' RMS error against the simulator's ``camera_height + vibration ·
sin(2π f t)`` and the median stated standard deviation, visual odometry's ATE, and the fused tracks' ATE
(camera, wheels and IMU; EKF / EKF + RTS / GTSAM batch / iSAM2), all in mm after SE(2) alignment.

Usage::

    python benchmarks/height_smoothing.py [--out DIR] [--only tilted,...]

Generation renders every frame: about a minute on two cores for all three.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fusion_vs_best import ate_against, recording  # noqa: E402

from fusion_vo import backends  # noqa: E402
from fusion_vo.odometry import OdometryConfig, run_visual_odometry  # noqa: E402
from fusion_vo.recording import Recording  # noqa: E402
from fusion_vo.simulation.standard import STANDARD  # noqa: E402

RECORDINGS = ("tilted", "real_gravel_focal_only", "real_fisheye_checker")
FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")


def true_height(seq: Path):
    """The simulator's camera height as a function of time (from ``simulation.yaml``)."""
    o = yaml.safe_load((seq / "simulation.yaml").read_text())["options"]

    def h(t):
        return o["camera_height"] + o["height_vibration"] * np.sin(2 * math.pi * o["vibration_frequency"] * t)

    return h


def one(seq: Path) -> dict:
    rec = Recording(seq)
    ate = ate_against(rec)
    h = true_height(seq)
    out = {}
    for label, smoothing in (("baseline", False), ("smoothed", True)):
        vo = run_visual_odometry(rec, OdometryConfig(range_smoothing=smoothing))
        err = vo.frame_height - h(vo.frame_t)
        fused = backends.run_backends(rec, vo, backend="all")
        out[label] = {
            "height_rms": 1e3 * float(np.sqrt(np.mean(err**2))),
            "height_sigma": 1e3 * float(np.median(vo.frame_height_sigma)),
            "vo": ate(vo.track),
            **{k: ate(fused.trajectories[k]) for k in FUSED},
        }
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=None, help="where to keep the generated recordings")
    parser.add_argument("--only", default=None, help="comma-separated recording names")
    args = parser.parse_args(argv)
    names = args.only.split(",") if args.only else list(RECORDINGS)
    base = args.out or Path(tempfile.mkdtemp(prefix="height_smoothing_"))
    print("recording | heights | height RMS error | stated sigma (median) | VO ATE | EKF / RTS / batch / iSAM2 ATE")
    print("---|---|---|---|---|---")
    for name in names:
        profile, seed, options, _ = STANDARD[name]
        seq = recording(base, name, profile, seed, options)
        res = one(seq)
        for label in ("baseline", "smoothed"):
            r = res[label]
            fused = " / ".join(f"{r[k]:.3f}" for k in FUSED)
            print(f"{name} | {label} | {r['height_rms']:.4f} mm | {r['height_sigma']:.4f} mm | {r['vo']:.3f} | {fused}")
    print("ATE in mm after SE(2) alignment; baseline: readings interpolated at each frame's time")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
