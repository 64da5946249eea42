"""Thesis table 5.1: velocity error over floor textures and illumination, on generated recordings.

In the thesis ("real image with simulated motion", section 5.1) a photograph of the floor was shifted
along a circular pattern in MATLAB and the estimated velocity compared with the commanded one, for four
photographs that differed mainly in illumination: two in good light, one with two spots of light in the
middle of the image, one dark. The spots (and, to a lesser degree, the dark image) made the error grow.

Here the simulator renders the same experiment properly: a camera 0.1 m above a photographed floor
(scikit-image's gravel, grass and brick, CC0), 0.25 m ahead of the axle of a robot that drives one
circle of 0.4 m radius at 0.15 m/s (the standard recording ``circle``: the image moves along a circular
pattern and turns with it), in three lighting variants:

* ``good light``: even illumination, normal exposure and sensor noise;
* ``spotlights``: a saturated specular highlight of 40 px radius fixed in the image (a lamp's reflection
  on a glossy floor, thesis 5.3.1) that does not move with the floor;
* ``dark``: a quarter of the exposure gain with three times the sensor noise (3 grey levels).

Both visual frontends (KLT tracking and feature matching) run on every recording. Per frame ``k`` with a
motion estimate, the body velocity ``v_k = (vx, vy)`` [m/s] is the SE(2) logarithm of the frame's
increment divided by the frame interval; ``u_k`` is the same quantity of the ground truth over the same
interval. With ``e_k = |v_k - u_k|`` (Euclidean norm):

* ``error %`` = ``100 * mean(e_k) / mean(|u_k|)`` (the thesis' average error %);
* ``variance %`` = ``100 * std(e_k) / mean(|u_k|)``: how much the error scatters from frame to frame,
  in the same unit as the error % (the thesis gives no formula for its variance %; this is our reading);
* ``yaw-rate err %``: ``100 * mean|w_k - w_true,k| / mean|w_true,k|`` for the yaw rate;
* ``failed``: frames the frontend could not use (no estimate; they are left out of the errors).

Beside the frontends, each recording is run through the plain OpenCV script of :mod:`fusion_vo.baseline`
(the baseline of ``benchmarks/visual.py``, rows ``plain script``), scored the same way.

Run::

    python examples/thesis_table_5_1.py [--out DIR] [--seed N] [--quick] [--realistic] [--textures gravel,grass]

``--quick`` uses the gravel floor only and a circle of 0.1 m radius. ``--realistic`` renders through the
independent camera (``examples/common.py``: a barrel lens the estimator only approximates, defocus, motion
blur, noise, auto-exposure); its renderer has no specular highlight, so the spotlight rows are left out.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np

from common import (FRONTENDS, LIGHTING, example_parser, fmt, format_table, generate, output_dir, realistic_options,
                    true_twist)
from fusion_vo import baseline
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData
from fusion_vo.odometry import OdometryConfig, OdometryResult, run_visual_odometry
from fusion_vo.recording import Recording

TEXTURES = ("gravel", "grass", "brick")

#: changes to the standard circle recording for the quick run: a small, fast circle rendered with fewer rays
QUICK_CIRCLE = {"radius": 0.1, "max_turn_rate": 1.5, "supersample": 1}


def velocity_errors(vo: OdometryResult, gt: PoseData) -> dict:
    """Velocity error figures of one run (see the module docstring for the definitions)."""
    est, true = [], []
    for inc in vo.increments:
        if not inc.ok or inc.dt <= 0:
            continue
        est.append(se2.log(inc.delta) / inc.dt)
        true.append(true_twist(gt, inc.t0, inc.t1))
    if not est:
        return {"frames": 0, "error_pct": float("nan"), "variance_pct": float("nan"),
                "yaw_error_pct": float("nan")}
    est, true = np.asarray(est), np.asarray(true)
    e = np.linalg.norm(est[:, :2] - true[:, :2], axis=1)
    speed = np.linalg.norm(true[:, :2], axis=1)
    yaw_error = np.abs(est[:, 2] - true[:, 2])
    yaw_rate = np.mean(np.abs(true[:, 2]))
    mean_speed = float(np.mean(speed))
    return {
        "frames": len(e),
        "error_pct": 100.0 * float(np.mean(e)) / mean_speed if mean_speed > 0 else float("nan"),
        "variance_pct": 100.0 * float(np.std(e)) / mean_speed if mean_speed > 0 else float("nan"),
        "yaw_error_pct": 100.0 * float(np.mean(yaw_error) / yaw_rate) if yaw_rate > 0 else float("nan"),
    }


def plain_script(rec: Recording) -> tuple[list, int]:
    """The baseline: the plain OpenCV script of :mod:`fusion_vo.baseline` (Shi-Tomasi corners, pyramidal LK,
    a RANSAC similarity; no undistortion) on the same frames, its similarities turned into body increments
    through the same ground geometry with a pinhole of the recording's focal length
    (:func:`fusion_vo.baseline.odometry`). Returns the increments and the frames it failed."""
    _, increments, results, _ = baseline.odometry(rec)
    return increments, sum(m is None for _, _, m in results)


def main(argv=None) -> int:
    parser = example_parser(__doc__.split("\n\n")[0])
    parser.add_argument("--textures", default=",".join(TEXTURES), help="comma-separated floor photographs")
    args = parser.parse_args(argv)
    textures = [t for t in args.textures.split(",") if t]
    if not textures or any(t not in TEXTURES for t in textures):
        parser.error(f"--textures takes some of {', '.join(TEXTURES)}")
    textures = textures[:1] if args.quick else textures
    circle = QUICK_CIRCLE if args.quick else {}
    rows = []
    with output_dir(args.out) as out:
        t_start = time.perf_counter()
        for texture in textures:
            for light, options in LIGHTING.items():
                if args.realistic:
                    options = realistic_options(light, texture)
                    if options is None:
                        continue
                name = f"{texture}-{light.replace(' ', '-')}"
                seq = generate("circle", out / name, args.seed, texture=texture, **circle, **options)
                rec = Recording(seq)
                gt = rec.groundtruth()
                for frontend in FRONTENDS:
                    vo = run_visual_odometry(rec, OdometryConfig(frontend=frontend))
                    errors = velocity_errors(vo, gt)
                    rows.append([texture, light, frontend, str(vo.n_frames), str(sum(vo.failures.values())),
                                 fmt(errors["error_pct"], 3), fmt(errors["variance_pct"], 3),
                                 fmt(errors["yaw_error_pct"], 3)])
                increments, failed = plain_script(rec)
                errors = velocity_errors(SimpleNamespace(increments=increments), gt)
                rows.append([texture, light, "plain script", str(len(rec)), str(failed), fmt(errors["error_pct"], 3),
                             fmt(errors["variance_pct"], 3), fmt(errors["yaw_error_pct"], 3)])
                print(f"{name}: {len(rec)} frames done ({time.perf_counter() - t_start:.0f} s)", flush=True)
        print()
        print(format_table("Table 5.1: velocity error by floor texture and lighting",
                           ["texture", "lighting", "frontend", "frames", "failed", "error %", "variance %",
                            "yaw-rate err %"], rows))
        print(f"\ntotal time {time.perf_counter() - t_start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
