"""``fusion-vo evaluate RUN_DIR [--gt SEQ]``: rebuild a run's report, with its accuracy where the recording has
ground truth or GPS fixes."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="rebuild a run's report (report.html), with the errors against ground truth or GPS where there are any",
        description="Rebuild the report of RUN_DIR from its files (report.html and PNG figures): every source's "
                    "track beside the fused ones, the normalised innovations, what was dropped, the calibration and "
                    "the verdict. Where the recording has ground truth (or GPS fixes), also compute ATE, RPE, drift, "
                    "end-point, heading, velocity and per-leg errors for every trajectory (*.tum), write "
                    "metrics.json and print the table.",
    )
    parser.add_argument("run_dir", metavar="RUN_DIR", help="folder written by 'fusion-vo run'")
    parser.add_argument("--gt", metavar="SEQ", default=None,
                        help="recording with state_groundtruth_estimate0/, or without it but with gps0/ "
                             "to score against the GPS fixes (default: run.yaml's sequence)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from fusion_vo.evaluation.io import find_trajectories
    from fusion_vo.evaluation.run_report import OUTPUTS, build_report
    from fusion_vo.outputs import StagedFiles

    run_dir = Path(args.run_dir)
    find_trajectories(run_dir)  # a missing folder or one without trajectories: an error before anything is locked
    # written into a staging folder and moved in only when all succeeded: a failure leaves the old results
    with StagedFiles(run_dir, replaces=OUTPUTS) as staged:
        content, metrics = build_report(run_dir, args.gt, out_dir=staged.path, name=run_dir.resolve().name)
        staged.commit()
    if metrics:
        show_metrics(metrics, run_dir.resolve().name)
    show_verdict(content.verdict, content.accuracy_line)
    print(f"report: {run_dir / 'report.html'}")
    return 0


def show_verdict(verdict: list[str], accuracy_line: str | None) -> None:
    """Print a report's verdict and, where it has no accuracy figures, why."""
    for sentence in verdict:
        print(f"verdict: {sentence}")
    if accuracy_line:
        print(f"note: {accuracy_line}")


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
