"""Where the time of ``fusion-vo run --backend all`` goes, stage by stage, beside the whole command.

Runs the pipeline of ``fusion-vo run SEQ --backend all`` in this process ``--repeat`` times and prints, per
stage, the wall time and the CPU time of this process: the input checks, visual odometry (the frontend
and the ground geometry), the fusion (split into the backends by their own CPU timing: streams merged,
EKF, RTS smoother, iSAM2, GTSAM batch), writing the trajectories and covariances, and the evaluation
(metrics, figures, report). Then the whole command as a subprocess (start-up and imports included), the
same number of times, interleaved with the in-process runs. The real-time rate is the recording's length
over the wall time; the EKF's CPU time is printed beside GTSAM's, its simple baseline.

Usage::

    fusion-vo simulate /tmp/random60 --standard random60
    nice -n -15 python benchmarks/bench_run.py /tmp/random60 [--repeat 3] [--no-evaluate]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from contextlib import contextmanager
from pathlib import Path


class Stages:
    """Wall and CPU seconds of wrapped functions, summed per stage name; a stage's time excludes that of
    the stages called inside it (the evaluation's metrics, figures and report inside the evaluation)."""

    def __init__(self):
        self.wall: dict[str, float] = defaultdict(float)
        self.cpu: dict[str, float] = defaultdict(float)
        self._stack: list[list[float]] = []  # per open stage: time spent in the stages inside it
        self.wrapped: list = []  # (module, attribute, original) to restore

    def restore(self) -> None:
        for module, attribute, inner in reversed(self.wrapped):
            setattr(module, attribute, inner)
        self.wrapped.clear()

    def wrap(self, module, attribute: str, stage: str) -> None:
        inner = getattr(module, attribute)
        self.wrapped.append((module, attribute, inner))

        def timed(*args, **kwargs):
            self._stack.append([0.0, 0.0])
            w, c = time.perf_counter(), time.process_time()
            try:
                return inner(*args, **kwargs)
            finally:
                dw, dc = time.perf_counter() - w, time.process_time() - c
                nested = self._stack.pop()
                self.wall[stage] += dw - nested[0]
                self.cpu[stage] += dc - nested[1]
                if self._stack:
                    self._stack[-1][0] += dw
                    self._stack[-1][1] += dc

        setattr(module, attribute, timed)


@contextmanager
def _out_dir():
    path = Path(tempfile.mkdtemp(prefix="bench_run_"))
    try:
        yield path / "out"
    finally:
        shutil.rmtree(path, ignore_errors=True)


def in_process(seq: Path, evaluate: bool) -> tuple[Stages, dict, float, float]:
    """One run of the pipeline with its stages timed; returns the stages, the backends' CPU split and the
    whole run's wall and CPU seconds."""
    from fusion_vo import pipeline
    from fusion_vo.evaluation import evaluate as ev, figures, influence, plots, run_report
    from fusion_vo.config import RunConfig

    stages = Stages()
    stages.wrap(pipeline, "check_inputs", "input checks")
    stages.wrap(pipeline, "run_visual_odometry", "visual odometry")
    stages.wrap(pipeline, "_run_backends", "fusion (all backends)")
    for name in ("write_tum", "write_pose_covariances", "write_velocities", "write_atomic"):
        stages.wrap(pipeline, name, "writing outputs")
    stages.wrap(ev, "evaluate_trajectories", "evaluation: metrics")
    for module in (plots, figures):
        for name in dir(module):
            if name.startswith("plot_"):
                stages.wrap(module, name, "evaluation: figures")
    stages.wrap(influence, "leave_one_out", "report: influence (fused without each input)")
    stages.wrap(run_report, "write_report", "evaluation: report")
    stages.wrap(run_report, "build_report", "evaluation: the rest (imports, reading)")
    config = RunConfig(backend="all", evaluate=evaluate)
    try:
        with _out_dir() as out:
            w, c = time.perf_counter(), time.process_time()
            summary = pipeline.run_pipeline(seq, out, config)
            wall, cpu = time.perf_counter() - w, time.process_time() - c
    finally:
        stages.restore()
    return stages, dict(summary.backend_seconds), wall, cpu


def whole_command(seq: Path, evaluate: bool) -> float:
    with _out_dir() as out:
        cmd = ["fusion-vo", "run", str(seq), "--out", str(out), "--backend", "all"] + ([] if evaluate else ["--no-evaluate"])
        w = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return time.perf_counter() - w


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("sequence", type=Path, help="recording folder (e.g. the generated random60)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-evaluate", action="store_true", help="as fusion-vo run --no-evaluate")
    args = parser.parse_args()
    evaluate = not args.no_evaluate
    from fusion_vo.recording import Recording

    rec = Recording(args.sequence)
    t = rec.frame_times if rec.has_camera() else None
    seconds = float(t[-1] - t[0]) if t is not None and len(t) > 1 else None
    runs, commands = [], []
    for i in range(args.repeat):  # interleaved: in-process run, whole command
        runs.append(in_process(args.sequence, evaluate))
        commands.append(whole_command(args.sequence, evaluate))
        print(f"run {i + 1}: in process {runs[-1][2]:.2f} s wall, {runs[-1][3]:.2f} s CPU; command {commands[-1]:.2f} s wall; "
              f"load average {os.getloadavg()[0]:.1f}", flush=True)
    names = list(dict.fromkeys(name for r in runs for name in r[0].wall))
    med = statistics.median
    print(f"\n{'stage':40s} {'wall [s]':>9s} {'CPU [s]':>9s}   (median of {args.repeat} runs)")
    for name in names:
        print(f"{name:40s} {med(r[0].wall.get(name, 0.0) for r in runs):9.3f} {med(r[0].cpu.get(name, 0.0) for r in runs):9.3f}")
    print(f"{'sum of the stages':40s} {med(sum(r[0].wall.values()) for r in runs):9.3f} "
          f"{med(sum(r[0].cpu.values()) for r in runs):9.3f}")
    print(f"{'whole pipeline in process':40s} {med(r[2] for r in runs):9.3f} {med(r[3] for r in runs):9.3f}")
    print(f"{'whole command (fusion-vo run)':40s} {med(commands):9.3f}")
    print("\nfusion split (CPU seconds, the backends' own timing):")
    keys = list(dict.fromkeys(k for r in runs for k in r[1]))
    print("  " + ", ".join(f"{k} {med(r[1].get(k, 0.0) for r in runs):.3f}" + (" ms" if k.endswith("_ms") else " s") for k in keys))
    if seconds:
        print(f"\nrecording {seconds:.1f} s: whole command {seconds / med(commands):.1f}x real time; "
              f"GTSAM batch {seconds / med(r[1].get('gtsam', float('nan')) for r in runs):.0f}x, "
              f"EKF + RTS {seconds / med(r[1].get('ekf', 0.0) + r[1].get('ekf_smoothed', 0.0) for r in runs):.0f}x "
              "real time (CPU)")
    print(f"load average {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
