"""``fusion-vo compare RUN_DIR... [--out DIR]``: several runs in one table and one overlay plot."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "compare",
        help="put several runs in one table and one overlay plot (compare.png)",
        description="Evaluate the trajectories of each RUN_DIR against its recording's ground truth, print "
                    "one table (rows run/trajectory) and write compare.json, compare.csv (every figure at "
                    "full precision) and compare.png into --out.",
    )
    parser.add_argument("run_dirs", metavar="RUN_DIR", nargs="+", help="folders written by 'fusion-vo run'")
    parser.add_argument("--out", metavar="DIR", default=".", help="output folder (default: current folder)")
    parser.add_argument("--gt", metavar="SEQ", default=None,
                        help="recording with the ground truth for all runs (default: each run.yaml's sequence)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from fusion_vo.cli.evaluate import console
    from fusion_vo.evaluation import compare_runs
    from fusion_vo.evaluation.table import POSE_COLUMNS, VELOCITY_COLUMNS, metrics_table

    table = compare_runs(args.run_dirs, args.out, args.gt)
    rows = {f"{label} / {name}": figures for label, runs in table.items() for name, figures in runs.items()}
    out = console()
    out.print(metrics_table(rows, "Position errors", "run / trajectory", POSE_COLUMNS))
    out.print(metrics_table(rows, "Velocity errors", "run / trajectory", VELOCITY_COLUMNS))
    print(f"table: {Path(args.out) / 'compare.csv'}")
    print(f"overlay: {Path(args.out) / 'compare.png'}")
    return 0
