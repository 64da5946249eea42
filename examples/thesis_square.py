"""The 0.9 m square of thesis table 5.2, on a generated recording, for both visual frontends.

In the thesis a robot drove one square of 90 cm sides on a corridor floor; the path was cut into its four
straight legs (A-B, B-C, C-D, D-end) and each leg's estimated length compared with the actual 90 cm:
1.51 %, 2.67 %, 4.3 % and 2.9 %.

Here the simulator renders the same square (the standard recording ``square``: a camera 0.1 m above a
photographed gravel floor, 0.25 m ahead of the axle, legs driven at up to 0.2 m/s, turns in place at
the corners) and visual odometry runs on it
with the KLT and the feature frontend. The legs are found in the ground truth at its turns and measured
with :func:`fusion_vo.evaluation.metrics.detect_legs` and :func:`~fusion_vo.evaluation.metrics.leg_errors`:

* start, end: ground-truth position [cm] at the leg's ends;
* actual: ground-truth straight-line length of the leg [cm];
* estimated: the visual track's straight-line length between the same instants [cm];
* error: ``|estimated - actual| / actual`` [%], the thesis' figure.

A second table gives the whole run: end-point error (anchored at the start) as % of the path length and
the heading error at the end. ``square.png`` overlays the tracks on the ground truth (figures 5.8-5.9).

Run::

    python examples/thesis_square.py [--out DIR] [--seed N] [--quick]

``--realistic`` renders through the independent camera (``examples/common.py``).
``--quick`` drives a square of 0.3 m sides instead of 0.9 m.
"""

from __future__ import annotations

import math
import time

from common import FRONTENDS, example_parser, fmt, format_table, generate, output_dir, realistic_options, to_trajectory
from fusion_vo.evaluation.metrics import detect_legs, evaluate_trajectory, leg_errors, to_planar
from fusion_vo.evaluation.plots import plot_trajectories
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording

#: thesis table 5.2: error of each 90 cm leg [%] and the leg's name there
THESIS_LEG_ERROR_PCT = (1.51, 2.67, 4.3, 2.9)
THESIS_LEG_NAMES = ("A-B", "B-C", "C-D", "D-end")


def cm(xy) -> str:
    return f"({100 * xy[0]:.1f}, {100 * xy[1]:.1f})"


def main(argv=None) -> int:
    parser = example_parser(__doc__.split("\n\n")[0])
    args = parser.parse_args(argv)
    options = {"side": 0.3, "supersample": 1} if args.quick else {}
    if args.realistic:
        options.update(realistic_options("good light"))
    with output_dir(args.out) as out:
        t_start = time.perf_counter()
        seq = generate("square", out / "square", args.seed, **options)
        rec = Recording(seq)
        gt = rec.groundtruth()
        reference = to_trajectory(gt, "groundtruth")
        legs = detect_legs(reference)
        t_sim = time.perf_counter() - t_start
        print(f"generated {len(rec)} frames of the square in {t_sim:.1f} s: {len(legs)} legs in the ground truth")

        leg_rows, run_rows, anchored = {}, [], {}
        for frontend in FRONTENDS:
            vo = run_visual_odometry(rec, OdometryConfig(frontend=frontend))
            track = to_trajectory(vo.track, frontend)
            result = evaluate_trajectory(reference, track)
            anchored[frontend] = result.anchored
            fig = result.figures
            for leg in leg_errors(reference, track, legs):
                leg_rows.setdefault(leg["leg"], {"leg": leg})[frontend] = leg
            run_rows.append([frontend, str(vo.n_frames), str(sum(vo.failures.values())),
                             fmt(fig["path_length_m"], 3), fmt(100 * fig["end_m"], 2), fmt(fig["end_pct"], 3),
                             fmt(fig["heading_deg"], 3), f"{vo.fps:.0f}"])

        rows = []
        for number in sorted(leg_rows):
            leg = leg_rows[number]["leg"]
            thesis = THESIS_LEG_ERROR_PCT[number - 1] if number <= len(THESIS_LEG_ERROR_PCT) else math.nan
            label = f"{number} ({THESIS_LEG_NAMES[number - 1]})" if number <= len(THESIS_LEG_NAMES) else str(number)
            row = [label, cm(leg["start"]), cm(leg["end"]), fmt(100 * leg["actual_m"], 1)]
            for frontend in FRONTENDS:
                this = leg_rows[number].get(frontend)
                row += [fmt(100 * this["estimated_m"], 2) if this else "-",
                        fmt(this["error_pct"], 3) if this else "-"]
            row.append(fmt(thesis, 2))
            rows.append(row)
        headers = ["leg", "start cm", "end cm", "actual cm"]
        for frontend in FRONTENDS:
            headers += [f"{frontend} cm", f"{frontend} err %"]
        headers.append("thesis err %")
        print()
        print(format_table("Table 5.2: legs of the square", headers, rows))
        print()
        print(format_table("Whole square: end point and heading",
                           ["frontend", "frames", "failed", "path m", "end cm", "end %", "heading deg", "fps"],
                           run_rows))
        png = plot_trajectories(to_planar(reference), anchored, out / "square.png",
                                title="The square of table 5.2 (thesis figures 5.8-5.9)")
        print(f"\nwrote {png}" if args.out is not None else "\n(pass --out DIR to keep the plot)")
        print(f"total time {time.perf_counter() - t_start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
