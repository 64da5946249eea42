"""``fusion-vo compare RUN_DIR... [--out DIR]``: several runs in one table, one overlay plot and their differences."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "compare",
        help="put several runs side by side: tables, an overlay plot (compare.png) and their differences over time",
        description="Compare the trajectories of each RUN_DIR with those of the first run (distance over time, "
                    "compare_differences.png) and, where a run's recording has ground truth, with the ground truth; "
                    "print the tables and each run's verdict and write compare.json, compare.csv (every figure at "
                    "full precision), compare.png (overlay) and compare_verdicts.txt into --out.",
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
    from fusion_vo.evaluation.table import DIFFERENCE_COLUMNS, POSE_COLUMNS, VELOCITY_COLUMNS, metrics_table

    table = compare_runs(args.run_dirs, args.out, args.gt)
    rows = {f"{label} / {name}": figures for label, runs in table.items() for name, figures in runs.items()}
    out = console()
    if any("ate_m" in figures for figures in rows.values()):
        accurate = {k: v for k, v in rows.items() if "ate_m" in v}
        out.print(metrics_table(accurate, "Position errors", "run / trajectory", POSE_COLUMNS))
        out.print(metrics_table(accurate, "Velocity errors", "run / trajectory", VELOCITY_COLUMNS))
    differing = {k: v for k, v in rows.items() if "diff_rms_m" in v}
    if differing:
        first = next(iter(table))
        out.print(metrics_table(differing, f"Distance from the same trajectory of {first}", "run / trajectory",
                                DIFFERENCE_COLUMNS))
    print((Path(args.out) / "compare_verdicts.txt").read_text(encoding="utf-8"), end="")
    print(f"table: {Path(args.out) / 'compare.csv'}")
    print(f"overlay: {Path(args.out) / 'compare.png'}")
    if differing:
        print(f"differences: {Path(args.out) / 'compare_differences.png'}")
    return 0
