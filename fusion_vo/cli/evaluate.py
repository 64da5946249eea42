"""``fusion-vo evaluate RUN_DIR [--gt SEQ]``: errors of a run's trajectories against ground truth."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="compare a run's trajectories with ground truth (metrics.json, plots, report.html)",
        description="Compute ATE, RPE, drift, end-point, heading, velocity and per-leg errors for every "
                    "trajectory (*.tum) in RUN_DIR, write metrics.json, PNG figures and a "
                    "self-contained report.html into RUN_DIR and print the table.",
    )
    parser.add_argument("run_dir", metavar="RUN_DIR", help="folder written by 'fusion-vo run'")
    parser.add_argument("--gt", metavar="SEQ", default=None,
                        help="recording with state_groundtruth_estimate0/, or without it but with gps0/ "
                             "to score against the GPS fixes (default: run.yaml's sequence)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from fusion_vo.evaluation import evaluate_run
    from fusion_vo.evaluation.evaluate import OUTPUTS
    from fusion_vo.evaluation.io import find_trajectories
    from fusion_vo.outputs import StagedFiles

    run_dir = Path(args.run_dir)
    find_trajectories(run_dir)  # a missing folder or one without trajectories: an error before anything is locked
    # written into a staging folder and moved in only when all succeeded: a failure leaves the old results
    with StagedFiles(run_dir, replaces=OUTPUTS) as staged:
        metrics = evaluate_run(run_dir, args.gt, out_dir=staged.path)
        staged.commit()
    show_metrics(metrics, Path(args.run_dir).resolve().name)
    print(f"report: {Path(args.run_dir) / 'report.html'}")
    return 0


def console():
    """A rich console for tables: the terminal's width, or wide enough never to cut a number in a file or pipe."""
    import sys

    from rich.console import Console

    return Console() if sys.stdout.isatty() else Console(width=1000)


def show_metrics(metrics: dict, name: str) -> None:
    """Print the position, velocity and per-leg error tables of one run."""
    from fusion_vo.evaluation.table import POSE_COLUMNS, VELOCITY_COLUMNS, legs_table, metrics_table

    console = globals()["console"]()
    if any("gps_rms_m" in figures for figures in metrics.values()):
        from rich import box
        from rich.table import Table

        from fusion_vo.evaluation.gps import gps_frame, gps_table

        headers, rows = gps_table(metrics)
        table = Table(title=f"Errors of {name} against GPS fixes (no ground truth)", box=box.SIMPLE_HEAD,
                      caption=f"trajectories {gps_frame(metrics)}; outliers: fixes > 5 robust sigma off")
        for h in headers:
            table.add_column(h, justify="left" if h == "trajectory" else "right")
        for row in rows:
            table.add_row(*row)
        console.print(table)
        return
    console.print(metrics_table(metrics, f"Position errors of {name}", columns=POSE_COLUMNS))
    console.print(metrics_table(metrics, f"Velocity errors of {name}", columns=VELOCITY_COLUMNS))
    legs = legs_table(metrics)
    if legs is not None:
        console.print(legs)
