"""Speed of ``fusion-vo batch`` on a local Dask cluster beside a plain loop of ``fusion-vo run`` (the baseline).

Generates ``--recordings`` (default 8) random drives of ``--seconds`` (default 8 s, 640 x 360 frames at
20 Hz), then measures, in wall-clock time and interleaved ``--repeat`` times (loop, 1 worker,
2 workers, 2 workers, 1 worker, loop, ...):

* ``loop``       ``fusion-vo run REC --out DIR`` for each recording, one after the other (the baseline);
* ``1 worker``   ``fusion-vo batch REC... --workers 1`` (cluster start-up included);
* ``2 workers``  ``fusion-vo batch REC... --workers 2``.

A ``fusion-vo run`` may use several threads (OpenCV, BLAS); a batch worker uses one, as there is one
worker per core.

It prints the speed-up of 2 workers over 1 (target >= 1.7 on 2 cores), the overhead per task of a
batch against the loop ((batch with 1 worker - loop) / recordings; negative when the batch saves the
interpreter start-up that every ``fusion-vo run`` pays), the batch's own cost per task (wall clock of
the 1-worker batch minus the seconds spent inside its tasks), and the time to plan and submit the task
graph of 10,000 recordings to a scheduler (target < 10 s). Every batch writes into a new folder, so
nothing is reused from an earlier one. Usage::

    python benchmarks/batch.py [--recordings 8] [--seconds 8] [--repeat 2] [--work DIR]
"""

from __future__ import annotations

import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import load, parser, recording

from fusion_vo.batch import plan_batch, run_task
from fusion_vo.config import RunConfig

#: seeds of random drives that move from the start (a few seeds begin with a long stop)
SEEDS = (3, 4, 6, 11, 13, 14, 15, 16, 17, 18, 19, 21)


def _fusion_vo(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "fusion_vo.cli.main", "-q", *args], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def make_recordings(root: Path, n: int, seconds: float) -> list[Path]:
    """The first ``n`` drives of :data:`SEEDS`, ``seconds`` long, generated in ``root`` unless already there."""
    return [recording(root, f"drive{seed:02d}", "random", seed, {"duration": seconds}) for seed in SEEDS[:n]]


def graph_seconds(root: Path, n: int = 10_000) -> tuple[float, float]:
    """Seconds to plan ``n`` tasks (folders checked, names made) and to submit them to a scheduler."""
    from distributed import Client, LocalCluster  # the batch extra

    fleet = root / "fleet"
    paths = [fleet / f"{i // 100:03d}" / f"drive{i:05d}" for i in range(n)]
    for p in paths:
        p.mkdir(parents=True, exist_ok=True)
    with LocalCluster(n_workers=0, dashboard_address=None) as cluster, Client(cluster) as client:
        start = time.perf_counter()
        tasks = plan_batch(paths, RunConfig(), root / "fleet-out")
        planned = time.perf_counter() - start
        futures = client.map(run_task, tasks, pure=False)
        while client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)) < n:
            time.sleep(0.05)
        submitted = time.perf_counter() - start
        client.cancel(futures)
    shutil.rmtree(fleet, ignore_errors=True)
    return planned, submitted


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--recordings", type=int, default=8, help="number of generated recordings (at most 12)")
    ap.add_argument("--seconds", type=float, default=8.0, help="length of each drive [s]")
    ap.add_argument("--repeat", type=int, default=2, help="interleaved repetitions of the three measurements")
    ap.add_argument("--work", help="folder for the recordings and outputs (default: a temporary folder)")
    args = ap.parse_args(argv)
    if not 1 <= args.recordings <= len(SEEDS) or args.repeat < 1:
        ap.error(f"--recordings must be 1 to {len(SEEDS)} and --repeat at least 1")
    print(f"load average {load()} before", flush=True)
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="bench-batch-"))
    recordings = make_recordings(work / "recordings", min(args.recordings, len(SEEDS)), args.seconds)
    shutil.rmtree(work / "out", ignore_errors=True)  # outputs of an earlier benchmark would be reused
    names = [str(r) for r in recordings]
    times: dict[str, list[float]] = {"loop": [], "1 worker": [], "2 workers": []}
    count = 0

    def out() -> str:
        nonlocal count
        count += 1
        return str(work / "out" / f"{count:03d}")

    def loop() -> None:
        base = out()
        for r in recordings:
            _fusion_vo("run", str(r), "--out", f"{base}/{r.name}")

    inside: dict[str, list[float]] = {"1 worker": [], "2 workers": []}  # seconds inside the tasks of each batch

    def batch(workers: int):
        def go() -> None:
            import pandas as pd  # the batch extra

            folder = out()
            _fusion_vo("batch", *names, "--out", folder, "--workers", str(workers), "--no-dashboard")
            table = pd.read_csv(Path(folder) / "results.csv").drop_duplicates("recording")
            inside["1 worker" if workers == 1 else "2 workers"].append(float(table["seconds"].sum()))
        return go

    order = [("loop", loop), ("1 worker", batch(1)), ("2 workers", batch(2))]
    for k in range(args.repeat):
        for name, fn in (order if k % 2 == 0 else order[::-1]):
            seconds = _timed(fn)
            times[name].append(seconds)
            print(f"  {name:>9}: {seconds:6.1f} s", flush=True)
    n = len(recordings)
    best = {k: min(v) for k, v in times.items()}
    print(f"\n{n} recordings of {args.seconds:g} s; wall-clock seconds over {args.repeat} interleaved runs "
          "(best / median):")
    for name, values in times.items():
        print(f"  {name:>9}: {best[name]:6.1f} / {statistics.median(values):6.1f} s  ({best[name] / n:.2f} s per recording)")
    print(f"speed-up of 2 workers over 1: {best['1 worker'] / best['2 workers']:.2f}x (target >= 1.7)")
    print(f"overhead per task, batch with 1 worker against the loop: {(best['1 worker'] - best['loop']) / n:+.2f} s")
    k = times["1 worker"].index(best["1 worker"])
    print(f"batch machinery per task (1 worker: wall clock - time inside the tasks, cluster start-up and "
          f"report included): {(best['1 worker'] - inside['1 worker'][k]) / n:.2f} s")
    for name in ("1 worker", "2 workers"):
        k = times[name].index(best[name])
        print(f"  {name:>9}: {inside[name][k] / n:.2f} s inside each task on average, "
              f"{inside[name][k] / best[name]:.2f} tasks running at once on average")
    print("(with 2 workers each task takes about twice as long as with 1 when the machine has no second core free)")
    planned, submitted = graph_seconds(work)
    print(f"task graph of 10,000 recordings: planned in {planned:.2f} s, on the scheduler after {submitted:.2f} s "
          "(target < 10 s)")
    print(f"load average {load()} after")
    if not args.work:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
