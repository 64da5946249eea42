"""``fusion-vo sweep RECORDING... --grid GRID.yaml --out DIR``: every recording with every parameter set."""

from __future__ import annotations

import argparse
import time

from fusion_vo.batch.columns import METRICS
from fusion_vo.errors import InputError
from fusion_vo.cli.batch import (add_common, announce, batch_progress, client_options, finish, load_run_config,
                                  quiet_dask)


def register(sub) -> None:
    p = sub.add_parser("sweep", help="run recordings with many parameter sets on a Dask cluster",
                       description="Run each recording with each parameter set of GRID.yaml (dotted configuration "
                                   "keys and the values to try, or 'random: N' samples from ranges; see "
                                   "examples/thesis_sweep.yaml). Writes DIR/<recording>/<set>/, results.csv and "
                                   "results.parquet (one column per swept key) and report.html (each metric "
                                   "against each key, the best set named). Exit status 1 when a task failed.")
    add_common(p)
    p.add_argument("--grid", "-g", required=True, metavar="GRID.yaml", help="the keys to sweep and their values")
    p.add_argument("--rank", choices=METRICS, default="ate_m",
                   help="metric that ranks the parameter sets (mean over the recordings; default: ate_m)")
    p.add_argument("--trajectory", help="trajectory whose metric ranks the sets (default: vo)")
    p.add_argument("--optimize", choices=METRICS, metavar="METRIC",
                   help=f"search the ranges of GRID.yaml with Optuna instead of running every set ({', '.join(METRICS)})")
    p.add_argument("--trials", type=int, default=20, help="Optuna trials with --optimize (default: 20)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fusion_vo.batch.cluster import open_client, require_dask

    require_dask()
    quiet_dask()
    from fusion_vo.batch.grid import load_grid
    from fusion_vo.batch.runner import plan_sweep, run_sweep

    started = time.monotonic()
    config = load_run_config(args)
    if args.optimize:
        from fusion_vo.batch.optimize import load_search, optimize

        space = load_search(args.grid, config, args.trials)
        plan_sweep(args.recordings, space.probe_grid(), args.out)  # every input error before the cluster starts
        with open_client(announce=announce, **client_options(args)) as client, batch_progress() as update:
            frame, best = optimize(args.recordings, space, config, client, out=args.out, metric=args.optimize,
                                   trajectory=args.trajectory, trials=args.trials, progress=update)
        print(f"best: {best}")
        return finish(frame, args.out, started)
    grid = load_grid(args.grid, config)
    if len(grid.sets) < grid.drawn:  # random draws among few choices repeat: each distinct set runs once
        print(f"note: {args.grid}: 'random: {grid.drawn}' drew {len(grid.sets)} distinct parameter sets; "
              "each runs once")
    plan_sweep(args.recordings, grid, args.out)  # every input error before the cluster starts
    with open_client(announce=announce, **client_options(args)) as client, batch_progress() as update:
        frame = run_sweep(args.recordings, args.grid, config, client, out=args.out, rank=args.rank,
                          rank_trajectory=args.trajectory, progress=update)
    problem = _print_best(frame, args.rank, args.trajectory)
    status = finish(frame, args.out, started)
    if problem:  # the sets ran and are in results.csv, but the ranking asked for cannot be made
        raise InputError(problem)
    return status


def _print_best(frame, metric: str, trajectory: str | None) -> str | None:
    """Print the best parameter set; returns why none can be ranked when that is the user's option's doing."""
    from fusion_vo.batch.ranking import best_sets, describe_set

    ranked, used = best_sets(frame, metric, trajectory)
    if len(ranked) and ranked["recordings"].iloc[0] > 0 and ranked["mean"].notna().iloc[0]:
        name = ranked["parameter_set"].iloc[0]
        print(f"best parameter set: {name} ({describe_set(frame, name)}): mean {metric} of {used} "
              f"{ranked['mean'].iloc[0]:.5g} over {ranked['recordings'].iloc[0]} recordings")
        return None
    ok = frame[frame["status"] == "ok"]
    names = list(dict.fromkeys(ok["trajectory"].dropna())) if "trajectory" in ok else []
    if len(ok) and trajectory is not None and trajectory not in names:
        return (f"--trajectory {trajectory}: no run has this trajectory (they have: {', '.join(names) or 'none'}); "
                "the parameter sets are not ranked")
    if len(ok) and (metric not in ok or ok[metric].isna().all()):
        print(f"parameter sets not ranked: no run has {metric} (not evaluated: --no-evaluate, or no ground truth)")
        return None
    print("no parameter set completed on every recording")
    return None
