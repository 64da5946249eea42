"""The heading test of thesis section 5.2.1: one full circle, heading error at the end.

In the thesis the camera was moved once around a circle, tangent to the path, ending where it started;
the estimated heading after the revolution was compared with the true 360 degrees: 0.5859 % of a turn
(2.1 degrees).

Here the simulator drives the robot once around a circle (profile ``circle``) over a photographed gravel
floor and visual odometry runs with the KLT and the feature frontend. Figures, from
:func:`fusion_vo.evaluation.metrics.evaluate_trajectory` with the visual track anchored at the
ground-truth start pose:

* turned: the ground truth's total heading change [deg];
* estimated: the visual track's total heading change (unwrapped) [deg];
* heading error: ``|estimated - turned|`` [deg], and as % of the turned angle (the thesis' figure);
* end: end-point position error [cm] and as % of the path length.

``heading.png`` shows the heading over time against ground truth (figure 5.13).

Run::

    python examples/thesis_heading.py [--out DIR] [--seed N] [--quick]

``--realistic`` renders through the independent camera (``examples/common.py``).
``--quick`` drives a smaller, faster circle.
"""

from __future__ import annotations

import math
import time

import numpy as np

from common import FRONTENDS, example_parser, fmt, format_table, generate, output_dir, realistic_options, to_trajectory
from fusion_vo.evaluation.metrics import evaluate_trajectory, to_planar
from fusion_vo.evaluation.plots import plot_heading
from fusion_vo.measurements import PoseData
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording

#: thesis 5.2.1: heading error after one revolution [% of 360 deg]
THESIS_HEADING_PCT = 0.5859


def turned_between(gt: PoseData, t0: float, t1: float) -> float:
    """Ground-truth heading change between ``t0`` and ``t1`` [deg] (unwrapped, absolute)."""
    yaw = np.interp([t0, t1], gt.t, np.unwrap(gt.xyyaw[:, 2]))
    return math.degrees(abs(yaw[1] - yaw[0]))


def main(argv=None) -> int:
    parser = example_parser(__doc__.split("\n\n")[0])
    args = parser.parse_args(argv)
    options = {"radius": 0.15, "supersample": 1} if args.quick else {}
    if args.realistic:
        options.update(realistic_options("good light"))
    with output_dir(args.out) as out:
        t_start = time.perf_counter()
        seq = generate("circle", out / "circle", args.seed, **options)
        rec = Recording(seq)
        gt = rec.groundtruth()
        turned = turned_between(gt, gt.t[0], gt.t[-1])
        print(f"generated {len(rec)} frames of the circle in {time.perf_counter() - t_start:.1f} s: "
              f"the robot turns {turned:.2f} deg")
        reference = to_trajectory(gt, "groundtruth")
        rows, anchored = [], {}
        for frontend in FRONTENDS:
            vo = run_visual_odometry(rec, OdometryConfig(frontend=frontend))
            result = evaluate_trajectory(reference, to_trajectory(vo.track, frontend))
            anchored[frontend] = result.anchored
            fig = result.figures
            ref_turn = turned_between(gt, vo.track.t[0], vo.track.t[-1])
            est_yaw = np.unwrap(vo.track.xyyaw[:, 2])
            est_turn = math.degrees(abs(est_yaw[-1] - est_yaw[0]))
            rows.append([frontend, str(vo.n_frames), str(sum(vo.failures.values())), fmt(ref_turn, 2),
                         fmt(est_turn, 3), fmt(fig["heading_deg"], 4),
                         fmt(100 * fig["heading_deg"] / ref_turn, 4), fmt(100 * fig["end_m"], 2),
                         fmt(fig["end_pct"], 3), fmt(THESIS_HEADING_PCT, 4)])
        print()
        print(format_table("Heading after one full circle (thesis 5.2.1)",
                           ["frontend", "frames", "failed", "turned deg", "estimated deg", "error deg",
                            "error %", "end cm", "end %", "thesis %"], rows))
        png = plot_heading(to_planar(reference), anchored, out / "heading.png")
        print(f"\nwrote {png}" if args.out is not None else "\n(pass --out DIR to keep the plot)")
        print(f"total time {time.perf_counter() - t_start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
