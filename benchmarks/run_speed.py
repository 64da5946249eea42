"""Speed of the ``fusion-vo`` commands as a user runs them: start-up, a run stage by stage, pauses, the generator.

Subcommands, each with its baseline measured in the same run:

startup     wall time (median of the repeats) of ``python -c pass`` and ``python -c "import numpy, cv2"`` (the
            interpreter and the libraries every run needs: the floor), ``fusion-vo --help`` and ``fusion-vo run
            --help`` (they load neither numpy nor OpenCV), importing the EKF's libraries beside numpy alone, the
            whole ``fusion-vo run SEQ --backend none --no-evaluate`` and the part of it outside visual odometry,
            writing the visual odometry outputs in this process, and the plain OpenCV script as a whole command
            (``python -m fusion_vo.baseline SEQ``) interleaved with the run: both commands' frame rates.
stages      where the time of ``fusion-vo run SEQ --backend all`` goes: the pipeline run in this process with
            timers around the functions of each stage (input checks, visual odometry, all backends, writing
            outputs, the evaluation's metrics, figures and report), wall and CPU time; the backends' own CPU
            split (the EKF's beside GTSAM's); the whole command as a subprocess, interleaved; the real-time rate.
pause       the cost of a pause in every stream: a small generated recording (33 frames of 160 x 120, 0.05 m of
            straight drive, wheels, IMU) with the logger stopped for P seconds after 0.8 s, one fresh
            ``fusion-vo run`` process per pause and backend; poses, CPU time and peak memory of the whole
            process, and the pauses ``summary.json`` reports. The run without a pause is the baseline.
simulation  frames per second of the recording generator on one core, per stage (ray casting the floor,
            photometry, PNG writing), beside the PNG writing alone (what storing a frame costs at least).

Usage::

    python benchmarks/run_speed.py startup [--sequence SEQ] [--repeats 5]
    python benchmarks/run_speed.py stages [--sequence SEQ] [--repeats 3] [--no-evaluate]
    python benchmarks/run_speed.py pause [--pauses 0,60,3600] [--backends ekf,gtsam]
    python benchmarks/run_speed.py simulation [--frames 200] [--supersample 2] [--tilt 3] [--blur 1]

Without ``--sequence``, ``startup`` generates the standard ``short`` recording (5 s) and ``stages`` the
standard ``random60`` (60 s). Run under ``nice -n -15`` where allowed: the wall times include waiting for a core.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # single-threaded numerical libraries (before numpy loads)

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from common import Stages, load, parser, standard, table, work_dir

from fusion_vo import pipeline
from fusion_vo.config import RunConfig
from fusion_vo.evaluation import evaluate as ev, figures, influence, plots, run_report
from fusion_vo.geometry.camera import CameraModel
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording, write_tum
from fusion_vo.simulation import simulate
from fusion_vo.simulation.floor import Floor
from fusion_vo.simulation.mount import body_pose, camera_mount
from fusion_vo.simulation.pause import pause as pause_recording
from fusion_vo.simulation.photometry import Photometric, Photometry
from fusion_vo.simulation.render import Renderer

PY = sys.executable
CLI = [PY, "-m", "fusion_vo.cli.main"]


def wall(argv: list[str], repeats: int = 1) -> float:
    """Median wall time [s] of a command."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


# ------------------------------------------------------------------------------------------- startup
def startup(args) -> int:
    with work_dir(None) as tmp:
        seq = Path(args.sequence) if args.sequence else standard(tmp, "short")
        rows = [(label, wall(argv, args.repeats)) for label, argv in (
            ("python -c pass", [PY, "-c", "pass"]),
            ("python -c 'import numpy, cv2'", [PY, "-c", "import numpy, cv2"]),
            ("fusion-vo --help", [*CLI, "--help"]),
            ("fusion-vo run --help", [*CLI, "run", "--help"]),
            ("python -c 'import numpy'", [PY, "-c", "import numpy"]),
            ("python -c 'import numpy, filterpy.kalman, scipy.stats'",
             [PY, "-c", "import numpy, filterpy.kalman, scipy.stats"]))]
        out = tmp / "out"
        run = [*CLI, "-q", "run", str(seq), "--out", str(out), "--backend", "none", "--no-evaluate"]
        plain = [PY, "-m", "fusion_vo.baseline", str(seq)]
        total, inside, script = [], [], []
        for _ in range(args.repeats):  # interleaved: the run, then the plain script
            start = time.perf_counter()
            subprocess.run(run, check=True, stdout=subprocess.DEVNULL)
            total.append(time.perf_counter() - start)
            inside.append(json.loads((out / "summary.json").read_text())["vo_seconds"])
            script.append(wall(plain))
        frames = json.loads((out / "summary.json").read_text())["frames"]
        rows.append((f"fusion-vo run --backend none ({frames} frames)", statistics.median(total)))
        rows.append(("  of which outside visual odometry", statistics.median(t - v for t, v in zip(total, inside))))
        rows.append((f"python -m fusion_vo.baseline, the plain script ({frames} frames)", statistics.median(script)))
        vo = run_visual_odometry(Recording(seq), OdometryConfig())
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            write_tum(tmp / "vo.tum", vo.track.t, vo.track.xyyaw)
            pipeline.write_velocities(tmp / "velocities.csv", vo)
            times.append(time.perf_counter() - start)
        rows.append((f"writing vo.tum + velocities.csv ({frames} frames)", statistics.median(times)))
    ratios = [s / t for s, t in zip(script, total)]
    print(f"load average {load()} at the end")
    print(table(["what", f"wall time, median of {args.repeats}"], [[name, f"{1000 * s:.0f} ms"] for name, s in rows]))
    print(f"whole commands: fusion-vo run {frames / statistics.median(total):.0f} frames/s, plain script "
          f"{frames / statistics.median(script):.0f} frames/s; ratio {statistics.median(ratios):.2f} "
          f"({min(ratios):.2f}-{max(ratios):.2f}) between commands run next to each other")
    return 0


# ------------------------------------------------------------------------------------------- stages
def in_process(seq: Path, evaluate: bool, out: Path) -> tuple[Stages, dict, float, float]:
    """One run of the pipeline with its stages timed: the stages, the backends' CPU split, wall and CPU seconds."""
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
    try:
        w, c = time.perf_counter(), time.process_time()
        summary = pipeline.run_pipeline(seq, out, RunConfig(backend="all", evaluate=evaluate), force=True)
        wall_s, cpu_s = time.perf_counter() - w, time.process_time() - c
    finally:
        stages.restore()
    return stages, dict(summary.backend_seconds), wall_s, cpu_s


def stages(args) -> int:
    with work_dir(None) as tmp:
        seq = Path(args.sequence) if args.sequence else standard(tmp, "random60")
        rec = Recording(seq)
        t = rec.frame_times if rec.has("cam0") else None
        seconds = float(t[-1] - t[0]) if t is not None and len(t) > 1 else None
        evaluate = not args.no_evaluate
        runs, commands = [], []
        for i in range(args.repeats):  # interleaved: in-process run, whole command
            runs.append(in_process(seq, evaluate, tmp / "in-process"))
            cmd = [*CLI, "run", str(seq), "--out", str(tmp / "command"), "--backend", "all"]
            commands.append(wall(cmd + ([] if evaluate else ["--no-evaluate"])))
            print(f"run {i + 1}: in process {runs[-1][2]:.2f} s wall, {runs[-1][3]:.2f} s CPU; command "
                  f"{commands[-1]:.2f} s wall; load average {load()}", flush=True)
    med = statistics.median
    names = list(dict.fromkeys(name for r in runs for name in r[0].wall))
    rows = [[name, f"{med(r[0].wall.get(name, 0.0) for r in runs):.3f}", f"{med(r[0].cpu.get(name, 0.0) for r in runs):.3f}"]
            for name in names]
    rows.append(["sum of the stages", f"{med(sum(r[0].wall.values()) for r in runs):.3f}",
                 f"{med(sum(r[0].cpu.values()) for r in runs):.3f}"])
    rows.append(["whole pipeline in process", f"{med(r[2] for r in runs):.3f}", f"{med(r[3] for r in runs):.3f}"])
    rows.append(["whole command (fusion-vo run)", f"{med(commands):.3f}", "–"])
    print(f"\nmedian of {args.repeats} runs:")
    print(table(["stage", "wall [s]", "CPU [s]"], rows))
    keys = list(dict.fromkeys(k for r in runs for k in r[1]))
    print("\nfusion split (CPU, the backends' own timing): " + ", ".join(
        f"{k} {med(r[1].get(k, 0.0) for r in runs):.3f}" + (" ms" if k.endswith("_ms") else " s") for k in keys))
    if seconds:
        print(f"recording {seconds:.1f} s: whole command {seconds / med(commands):.1f}x real time; GTSAM batch "
              f"{seconds / med(r[1].get('gtsam', float('nan')) for r in runs):.0f}x, EKF + RTS "
              f"{seconds / med(r[1].get('ekf', 0.0) + r[1].get('ekf_smoothed', 0.0) for r in runs):.0f}x real time (CPU)")
    return 0


# ------------------------------------------------------------------------------------------- pause
SMALL = {"width": 160, "height": 120, "fu": 200.0, "fv": 200.0, "cu": 79.5, "cv": 59.5, "supersample": 1,
         "length": 0.05, "gt_rate": 50.0, "imu_rate": 100.0}

#: runs the command and reports its own CPU time and peak memory on stderr
_CHILD = ("import resource, sys\n"
          "from fusion_vo.cli.main import main\n"
          "status = main(sys.argv[1:])\n"
          "r = resource.getrusage(resource.RUSAGE_SELF)\n"
          "print('USAGE', r.ru_utime + r.ru_stime, r.ru_maxrss, file=sys.stderr)\n"
          "sys.exit(status)\n")


def one_run(rec: Path, out: Path, backend: str, timeout: float) -> dict:
    """``fusion-vo run`` in a fresh process: its poses, CPU seconds, peak memory and reported pauses."""
    try:
        proc = subprocess.run([PY, "-c", _CHILD, "-q", "run", str(rec), "--out", str(out), "--backend", backend,
                               "--no-evaluate"], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"stopped after {timeout:g} s"}
    usage = [line.split() for line in proc.stderr.splitlines() if line.startswith("USAGE ")]
    if proc.returncode != 0 or not usage:
        lines = [line for line in proc.stderr.splitlines() if not line.startswith("USAGE ")]
        return {"error": lines[-1] if lines else f"exit {proc.returncode}"}
    summary = json.loads((out / "summary.json").read_text())
    return {"cpu_s": float(usage[0][1]), "peak_mb": int(usage[0][2]) / 1024,
            "poses": len(np.loadtxt(out / f"{backend}.tum", ndmin=2)),
            "pauses": summary.get("fusion", {}).get("pauses", [])}


def pauses(args) -> int:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for seconds in [float(s) for s in args.pauses.split(",")]:
            rec = simulate(tmp / f"rec{seconds:g}", profile="straight", seed=4, **SMALL)
            if seconds:
                pause_recording(rec, 0.8, seconds)
            for backend in args.backends.split(","):
                r = one_run(rec, tmp / f"out{seconds:g}{backend}", backend, args.timeout)
                if "error" in r:
                    rows.append([f"{seconds:g}", backend, "failed", r["error"], "", ""])
                    continue
                where = ", ".join(f"{p['seconds']:.0f} s ({p['joined']})" for p in r["pauses"]) or "-"
                rows.append([f"{seconds:g}", backend, r["poses"], f"{r['cpu_s']:.2f}", f"{r['peak_mb']:.0f}", where])
                print(f"pause {seconds:g} s, {backend}: done", flush=True)
    print(table(["pause [s]", "backend", "poses", "CPU [s]", "peak memory [MB]", "pauses reported"], rows))
    print("(the rows of pause 0 are the baseline: the same drive without a pause)")
    return 0


# ------------------------------------------------------------------------------------------- simulation
def simulation(args) -> int:
    cv2.setNumThreads(1)
    t0 = time.process_time()
    floor = Floor.photographed("gravel")
    T_BS = camera_mount(0.25, 0.10, tilt_x_deg=args.tilt)
    camera = CameraModel(640, 360, 420.0, 420.0, 319.5, 179.5, "radial-tangential", [-0.03, 0.01, 0.0005, -0.0003],
                         T_BS)
    renderer = Renderer(camera, floor, args.supersample)
    photo = Photometric(Photometry(), camera.width, camera.height)
    setup = time.process_time() - t0
    rng = np.random.default_rng(0)
    # a drive of 15 mm and 1.2 degrees per frame, with a blur exposure of a fifth of that
    poses = [[body_pose(0.015 * (i + k / 5), 0.002 * (i + k / 5), 0.02 * (i + k / 5)) @ T_BS
              for k in range(args.blur)] for i in range(args.frames)]
    png = [cv2.IMWRITE_PNG_COMPRESSION, args.png_compression]
    if args.png_compression == 0:  # as the simulator: no row filters for stored (uncompressed) data
        png += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]
    render = photometry = write = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for i, frame_poses in enumerate(poses):
            a = time.process_time()
            radiance = renderer.radiance_blurred(frame_poses)
            b = time.process_time()
            image = photo.apply(radiance, 0.05 * i, rng)
            c = time.process_time()
            cv2.imwrite(str(Path(tmp) / f"{i:06d}.png"), image, png)
            d = time.process_time()
            render, photometry, write = render + b - a, photometry + c - b, write + d - c
    n, total = args.frames, render + photometry + write
    print(f"640x360, supersample {args.supersample}, tilt {args.tilt:g} deg, {args.blur} render(s) per frame, "
          f"{n} frames, one core, setup {setup:.2f} s (texture, rays)")
    print(table(["stage", "CPU per frame", "frames/s"],
                [["render", f"{1000 * render / n:.2f} ms", f"{n / render:.1f}"],
                 ["photometry", f"{1000 * photometry / n:.2f} ms", f"{n / photometry:.1f}"],
                 ["PNG writing (the baseline: storing a frame)", f"{1000 * write / n:.2f} ms", f"{n / write:.1f}"],
                 ["total", f"{1000 * total / n:.2f} ms", f"**{n / total:.1f}**"]]))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("startup", help="start-up and output cost beside a bare interpreter and the plain script")
    p.add_argument("--sequence", help="recording for the run (default: generate the standard 'short')")
    p.add_argument("--repeats", type=int, default=5)
    p.set_defaults(func=startup)
    p = sub.add_parser("stages", help="fusion-vo run --backend all stage by stage, beside the whole command")
    p.add_argument("--sequence", help="recording folder (default: generate the standard 'random60')")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--no-evaluate", action="store_true", help="as fusion-vo run --no-evaluate")
    p.set_defaults(func=stages)
    p = sub.add_parser("pause", help="a pause in every stream costs nothing: CPU and memory beside no pause")
    p.add_argument("--pauses", default="0,60,3600", help="pause lengths [s], comma-separated")
    p.add_argument("--backends", default="ekf,gtsam")
    p.add_argument("--timeout", type=float, default=600.0, help="seconds a run may take (default 600)")
    p.set_defaults(func=pauses)
    p = sub.add_parser("simulation", help="frames per second of the recording generator, per stage")
    p.add_argument("--frames", type=int, default=200)
    p.add_argument("--supersample", type=int, default=2)
    p.add_argument("--tilt", type=float, default=0.0, help="camera tilt about its x axis [deg]")
    p.add_argument("--blur", type=int, default=1, help="renders averaged per frame")
    p.add_argument("--png-compression", type=int, default=0)
    p.set_defaults(func=simulation)
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
