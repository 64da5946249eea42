"""``fusion-vo batch RECORDING... --out DIR``: every recording as ``fusion-vo run`` would, on a Dask cluster."""

from __future__ import annotations

import argparse
import sys
import time
from contextlib import contextmanager
from typing import Callable, Iterator

from fusion_vo.cli.arguments import non_empty, worker_count
from fusion_vo.config import BACKENDS, SENSORS


def add_common(p: argparse.ArgumentParser) -> None:
    """Options shared by ``batch`` and ``sweep``: outputs, run configuration, cluster."""
    p.add_argument("recordings", metavar="RECORDING", nargs="+", help="recording folders (paths every worker can see)")
    p.add_argument("--out", "-o", required=True, help="output folder: one run folder per task, results.csv, "
                                                      "results.parquet, report.html")
    p.add_argument("--config", "-c", type=non_empty("a configuration file"),
                   help="YAML run configuration (see fusion-vo run --print-config)")
    p.add_argument("--frontend", choices=["klt", "features"], help="visual frontend (default: klt)")
    p.add_argument("--backend", choices=BACKENDS, help="fusion backend (default: all)")
    p.add_argument("--sensors", help=f"comma-separated sensors to use, of {','.join(SENSORS)} or any registered sensor (default: what each recording has)")
    p.add_argument("--no-evaluate", action="store_true", help="skip the evaluation against ground truth")
    cluster = p.add_mutually_exclusive_group()
    cluster.add_argument("--workers", "-j", type=worker_count, metavar="N",
                         help="worker processes of the local Dask cluster (default: one per core)")
    cluster.add_argument("--scheduler", metavar="ADDRESS", help="address of a running Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--no-dashboard", action="store_true", help="do not serve the Dask dashboard of the local cluster")


def register(sub) -> None:
    p = sub.add_parser("batch", help="run many recordings on a Dask cluster into one table",
                       description="Run each recording as 'fusion-vo run' would (one task each, on a local Dask "
                                   "cluster or a running scheduler) and write DIR/<recording>/, DIR/results.csv, "
                                   "DIR/results.parquet and DIR/report.html. Unchanged tasks of an earlier batch "
                                   "into the same DIR are not run again. Exit status 1 when a recording failed.")
    add_common(p)
    p.set_defaults(func=run)


def load_run_config(args: argparse.Namespace):
    from fusion_vo.cli.run import apply_overrides
    from fusion_vo.config import load_config

    return apply_overrides(load_config(args.config), args)


@contextmanager
def batch_progress(enabled: bool | None = None) -> Iterator[Callable[[int, int, int], None]]:
    """``update(done, failed, total)``: one bar on a terminal, a line every 5 % otherwise."""
    if enabled is None:
        enabled = sys.stderr.isatty()
    start = time.monotonic()
    if not enabled:
        state = {"next": 0}

        def line(done: int, failed: int, total: int) -> None:
            if done < state["next"] and done != total:
                return
            state["next"] = done + max(1, total // 20)
            elapsed = time.monotonic() - start
            eta = f", about {elapsed / done * (total - done):.0f} s left" if 0 < done < total else ""
            print(f"batch: {done}/{total} done, {failed} failed, {total - done} remaining{eta}", file=sys.stderr)

        yield line
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    with Progress(TextColumn("tasks"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[failed]} failed"),
                  TextColumn("{task.fields[remaining]} remaining"), TimeElapsedColumn(), TimeRemainingColumn(),
                  transient=False) as bar:
        task = bar.add_task("tasks", total=None, failed=0, remaining="?")

        def update(done: int, failed: int, total: int) -> None:
            bar.update(task, completed=done, total=total, failed=failed, remaining=total - done)

        yield update


def quiet_dask() -> None:
    """Dask's own INFO logging (scheduler and worker start-up) only with -vv."""
    import logging

    if logging.getLogger().getEffectiveLevel() > logging.DEBUG:
        logging.getLogger("distributed").setLevel(logging.WARNING)


def announce(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def client_options(args: argparse.Namespace) -> dict:
    from fusion_vo.errors import InputError

    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be at least 1, not {args.workers}")
    return {"workers": args.workers, "scheduler": args.scheduler, "dashboard": not args.no_dashboard}


def finish(frame, out: str, started: float) -> int:
    """Print the failed tasks and one summary line; exit status 1 when any task failed."""
    keys = ["recording", "parameter_set"] if "parameter_set" in frame.columns else ["recording"]
    tasks = frame.drop_duplicates(keys)
    failed = tasks[tasks["status"] != "ok"]
    for row in failed.to_dict("records"):
        name = "/".join(str(row[k]) for k in keys)
        print(f"failed: {name}: {row['error']}")
    reused = int(tasks["cached"].sum())
    print(f"{len(tasks)} tasks: {len(tasks) - len(failed)} ok ({reused} unchanged, not run again), {len(failed)} failed; "
          f"{time.monotonic() - started:.1f} s -> {out}/results.csv, {out}/report.html")
    return 1 if len(failed) else 0


def run(args: argparse.Namespace) -> int:
    from fusion_vo.batch.cluster import open_client, require_dask

    require_dask()
    quiet_dask()
    from fusion_vo.batch.runner import plan_batch, run_batch

    started = time.monotonic()
    config = load_run_config(args)
    plan_batch(args.recordings, config, args.out)  # every input error before the cluster starts
    opts = client_options(args)
    with open_client(announce=announce, **opts) as client, batch_progress() as update:
        frame = run_batch(args.recordings, config, client, out=args.out, progress=update)
    return finish(frame, args.out, started)
