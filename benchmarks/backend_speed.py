"""Speed of the fusion backends on generated measurement streams, offline and live, each beside its baseline.

The streams are a generated drive (``fusion_vo.sensors.synthetic``: camera increments at 20 Hz, wheel
encoders at 50 Hz, IMU at 200 Hz, a 2 % camera-height error so that self-calibration is active; no images),
so the figures are the backends' alone. Numerical libraries run on one thread; CPU times describe one core
even on a shared machine.

Subcommands:

offline   CPU time of the EKF (streams merged, filter, RTS smoother), GTSAM batch (streams merged, graph,
          Levenberg-Marquardt, marginal covariances) and iSAM2 (per camera frame) on a drive of ``--seconds``
          and on one ``--scale`` times as long (the cost is linear in length); the split of the batch into its
          stages, wall beside CPU time. The EKF is the baseline of the graph (the same problem, the cheapest
          solver). Targets: EKF >= 150x real time, GTSAM batch >= 300x, iSAM2 < 0.5 ms per camera frame.
          ``--profile N`` adds the N costliest functions of one batch run (cProfile).
solvers   the batch problem of the same drive solved by the graph's own Levenberg-Marquardt loop with its
          block-tridiagonal solve (``fusion_vo.backends.chain``, what a run uses), beside GTSAM's own
          ``LevenbergMarquardtOptimizer`` (what a graph that is not a chain gets), ``GaussNewtonOptimizer`` and
          ``DoglegOptimizer`` given the same factors as ``gtsam.CustomFactor`` s, the same iteration limit and
          tolerance: CPU time (range over interleaved runs), iterations, final cost, largest position
          difference from the first's solution.
latency   ``StreamingFusion`` fed the drive in arrival order (the camera's increments ``--camera-delay`` late,
          as a frontend delivers them), ``current_estimate()`` after every sample: latency percentiles of one
          ``add_*()`` + ``current_estimate()`` call (wall clock, what the caller waits, and the caller's CPU
          time), the age of the returned pose and of the held-back processed state, the returned pose's error
          against the truth; EKF, iSAM2 on the caller's thread and iSAM2 on a worker thread, interleaved
          ``--repeat`` times, beside plain wheel dead reckoning done the same way (the cheapest "pose for
          now"). Targets: p99 <= 2 ms, worst <= 10 ms. ``--gc-freeze`` calls ``gc.freeze()`` after start-up, as
          a live process should (CPython's full collections then skip the ~100 000 start-up objects).

engine    ``StreamingFusion`` fed every sample in time order beside the batch run's online track of the same streams
          (``fuse`` with the EKF's smoother and the GTSAM batch solution off): CPU time of each, how far apart
          their node times are, and the largest position difference (the engine's track interpolated at the batch
          run's nodes), on the generated drive (camera, wheels,
          IMU) and on robot_localization's Jackal and Husky bags (wheel odometry and IMU). The decisions a batch
          run takes in hindsight (the consistency monitor over the whole log, the twist's delay from the whole
          log) are off, so both run the same per-node steps (``docs/decisions/0039-batch-online-tracks-share-the-engines-steps.md``).

``--config`` and ``--set`` change the backends' configuration (its ``fusion`` section), e.g. ``--set
fusion.visual_frame_error=0.5``.

Usage::

    python benchmarks/backend_speed.py offline [--seconds 60] [--scale 10] [--repeat 3] [--profile 25]
    python benchmarks/backend_speed.py solvers [--seconds 60] [--repeat 3]
    python benchmarks/backend_speed.py latency [--seconds 60] [--repeat 3] [--camera-delay 0.15] [--gc-freeze]
    python benchmarks/backend_speed.py engine [--seconds 60] [--repeat 3] [--out DIR]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # single-threaded numerical libraries (before numpy loads)

import cProfile
import gc
import pstats
import statistics
import sys
import time
from pathlib import Path

import gtsam
import numpy as np

from common import (JACKAL_BAG, Stages, add_settings, cpu_seconds, fusion_settings, import_husky, load, parser, table,
                    with_settings, work_dir)

from fusion_vo.backends import FusionConfig, SensorStreams, StreamingFusion, batch, chain, fuse, graph, graph_builder
from fusion_vo.backends.batch import streams_from_recording
from fusion_vo.backends.streaming import message_sensor, streaming_for, time_ordered_messages
from fusion_vo.recording import Recording
from fusion_vo.recording.rosbag import import_bag
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


def drive(seconds: float):
    """The generated drive (seed 1) and its streams."""
    s = synthetic_streams(SyntheticOptions(duration=seconds, visual_scale=1.02), seed=1)
    return s, SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)


# ------------------------------------------------------------------------------------------- offline
def measure(seconds: float, repeat: int, fusion: dict) -> dict:
    """CPU seconds of each backend on a drive of ``seconds`` (median of ``repeat`` runs) and the batch's split."""
    _, streams = drive(seconds)
    ekf = FusionConfig.from_dict(fusion)
    batch_only = FusionConfig.from_dict(with_settings(fusion, ["graph.online=false"]))
    online_only = FusionConfig.from_dict(with_settings(fusion, ["graph.batch=false"]))
    fuse(streams, "gtsam", FusionConfig.from_dict({"graph": {"batch": False, "online": False}}))  # warm up imports
    runs = []
    for _ in range(repeat):  # the backends one after the other, repeated
        ekf_s, _ = cpu_seconds(lambda: fuse(streams, "ekf", ekf))
        gtsam_s, result = cpu_seconds(lambda: fuse(streams, "gtsam", batch_only))
        isam_ms = fuse(streams, "gtsam", online_only).timing["gtsam_online_per_node_ms"]
        split = {k: result.timing.get(k, 0.0) for k in ("timeline", "gtsam_build", "gtsam_solve", "gtsam_marginals")}
        runs.append({"ekf": ekf_s, "gtsam": gtsam_s, "isam_ms": isam_ms, "split": split})
    med = statistics.median
    out = {"seconds": seconds, "frames": len(streams.visual), "runs": runs}
    for key in ("ekf", "gtsam", "isam_ms"):
        out[key] = med(r[key] for r in runs)
    out["split"] = {k: med(r["split"][k] for r in runs) for k in runs[0]["split"]}
    return out


def stage_split(seconds: float, repeat: int, fusion: dict) -> list[tuple[str, float, float]]:
    """Wall and CPU seconds of the batch's stages (median of ``repeat`` runs), from timers wrapped around the
    functions that do them."""
    _, streams = drive(seconds)
    config = FusionConfig.from_dict(with_settings(fusion, ["graph.online=false"]))
    names = {(batch, "build_intervals"): "streams merged", (graph, "run_graph"): "graph built (and the rest of run_graph)",
             (graph, "group"): "factors grouped into arrays", (chain, "ChainProblem"): "system laid out",
             (chain, "levenberg_marquardt"): "Levenberg-Marquardt", (chain, "pose_marginals"): "marginal covariances"}
    runs = []
    for _ in range(repeat):
        stages = Stages()
        for (module, attribute), name in names.items():
            stages.wrap(module, attribute, name)
        try:
            fuse(streams, "gtsam", config)
        finally:
            stages.restore()
        runs.append(stages)
    med = statistics.median
    return [(name, med(r.wall.get(name, 0.0) for r in runs), med(r.cpu.get(name, 0.0) for r in runs))
            for name in names.values()]


def offline(args) -> int:
    fusion = fusion_settings(args)
    print(f"load average {load()} before")
    rows = [measure(args.seconds, args.repeat, fusion), measure(args.seconds * args.scale, args.repeat, fusion)]
    print(table(["drive", "camera frames", "EKF + RTS [s]", "x real time", "GTSAM batch [s]", "x real time",
                 "iSAM2 [ms per frame]"],
                [[f"{r['seconds']:.0f} s", r["frames"], f"{r['ekf']:.3f}", f"{r['seconds'] / r['ekf']:.0f}",
                  f"{r['gtsam']:.3f}", f"{r['seconds'] / r['gtsam']:.0f}", f"{r['isam_ms']:.3f}"] for r in rows]))
    if args.repeat > 1:
        for r in rows:
            print(f"  {r['seconds']:.0f} s, every run: EKF " + ", ".join(f"{x['ekf']:.3f}" for x in r["runs"])
                  + " s; GTSAM batch " + ", ".join(f"{x['gtsam']:.3f}" for x in r["runs"])
                  + " s; iSAM2 " + ", ".join(f"{x['isam_ms']:.3f}" for x in r["runs"]) + " ms/frame")
    a, b = rows
    print(f"cost ratio {args.scale}x length: EKF {b['ekf'] / a['ekf']:.1f}x, GTSAM batch {b['gtsam'] / a['gtsam']:.1f}x, "
          f"iSAM2 per frame {b['isam_ms'] / a['isam_ms']:.2f}x")
    print(f"\nstages of the GTSAM batch on {args.seconds:.0f} s (median of {args.repeat}):")
    print(table(["stage", "wall [s]", "CPU [s]"],
                [[name, f"{w:.4f}", f"{c:.4f}"] for name, w, c in stage_split(args.seconds, args.repeat, fusion)]))
    if args.profile:
        _, streams = drive(args.seconds)
        config = FusionConfig.from_dict(with_settings(fusion, ["graph.online=false"]))
        prof = cProfile.Profile()
        prof.enable()
        fuse(streams, "gtsam", config)
        prof.disable()
        print("\ncProfile of one GTSAM batch run (cumulative; the profiler's own overhead inflates it):")
        pstats.Stats(prof, stream=sys.stdout).sort_stats("cumulative").print_stats(args.profile)
    met = a["seconds"] / a["ekf"] >= 150 and a["seconds"] / a["gtsam"] >= 300 and a["isam_ms"] < 0.5
    print("targets (EKF >= 150x real time, GTSAM batch >= 300x, iSAM2 < 0.5 ms/frame):", "met" if met else "NOT met")
    print(f"load average {load()} after")
    return 0


# ------------------------------------------------------------------------------------------- solvers
def capture(seconds: float, fusion: dict) -> dict:
    """The batch problem, its start values and settings, as ``run_graph`` hands them to its solver: the
    chain's (``problem``) or, for a graph that is not a chain, GTSAM's optimizer's (``graph``, ``groups``)."""
    _, streams = drive(seconds)
    captured = {}
    loop, fallback = chain.levenberg_marquardt, graph.gtsam_levenberg_marquardt

    def grab(problem, values, max_iterations=20, relative_tolerance=1e-3):
        captured.update(problem=problem, graph=problem.graph, groups=problem.groups, values=values,
                        args=(max_iterations, relative_tolerance))
        return loop(problem, values, max_iterations, relative_tolerance)

    def grab_fallback(factors, groups, values, max_iterations=20, relative_tolerance=1e-3):
        captured.update(problem=None, graph=factors, groups=groups, values=values,
                        args=(max_iterations, relative_tolerance))
        return fallback(factors, groups, values, max_iterations, relative_tolerance)

    chain.levenberg_marquardt, graph.gtsam_levenberg_marquardt = grab, grab_fallback
    try:
        fuse(streams, "gtsam", FusionConfig.from_dict(with_settings(fusion, ["graph.online=false"])))
    finally:
        chain.levenberg_marquardt, graph.gtsam_levenberg_marquardt = loop, fallback
    return captured


#: the solvers compared, the graph's own first (the one ``run_graph`` uses on a chain-shaped graph)
SOLVERS = ("block-tridiagonal loop (fusion-vo's)", "LevenbergMarquardt", "GaussNewton", "Dogleg")


def solvers(args) -> int:
    c = capture(args.seconds, fusion_settings(args))
    problem, v0 = c["problem"], c["values"]
    names = SOLVERS if problem is not None else SOLVERS[1:]  # a graph that is not a chain: GTSAM's alone
    if problem is None:
        print("the batch graph is not a chain: run_graph solves it with GTSAM's LevenbergMarquardt")
    max_iterations, tolerance = c["args"]
    full = gtsam.NonlinearFactorGraph(c["graph"])  # the same factors, the sensor models as CustomFactors
    for group in c["groups"]:
        for f in group.factors:
            full.add(f.custom_factor())
    n = 0
    while v0.exists(graph_builder.X(n)):
        n += 1

    def positions(values):
        return np.array([[values.atPose2(graph_builder.X(i)).x(), values.atPose2(graph_builder.X(i)).y()] for i in range(n)])

    def run(name):
        t0 = time.process_time()
        if name == SOLVERS[0]:
            solution, iterations, _ = chain.levenberg_marquardt(problem, v0, max_iterations, tolerance)
        else:
            params = {"LevenbergMarquardt": gtsam.LevenbergMarquardtParams, "GaussNewton": gtsam.GaussNewtonParams,
                      "Dogleg": gtsam.DoglegParams}[name]()
            params.setMaxIterations(max_iterations)
            params.setRelativeErrorTol(tolerance)
            params.setAbsoluteErrorTol(0.0)
            optimizer = getattr(gtsam, f"{name}Optimizer")(full, v0, params)
            solution = optimizer.optimize()
            iterations = optimizer.iterations()
        return time.process_time() - t0, iterations, full.error(solution), positions(solution)

    rows = {name: [] for name in names}
    for _ in range(args.repeat):
        for name in names:
            rows[name].append(run(name))
    reference = rows[names[0]][0][3]
    print(f"{args.seconds:.0f} s drive: {full.size()} factors ({sum(len(group) for group in c['groups'])} "
          f"sensor-model factors), start cost {full.error(v0):.6g}; CPU time over {args.repeat} interleaved runs; "
          f"load average {load()}")
    out = []
    for name in names:
        t = [r[0] for r in rows[name]]
        _, iterations, cost, p = rows[name][0]
        out.append([name, f"{1e3 * min(t):.1f}-{1e3 * max(t):.1f} ms", iterations, f"{cost:.6g}",
                    f"{np.abs(p - reference).max():.2e}"])
    print(table(["solver", "CPU time", "iterations", "final cost", "largest position difference [m]"], out))
    return 0


# ------------------------------------------------------------------------------------------- latency
def truth_at(s, t: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(t, s.truth.t, s.truth.xyyaw[:, 0]), np.interp(t, s.truth.t, s.truth.xyyaw[:, 1])])


def run_backend(s, msgs, backend: str, config: FusionConfig, background: bool = False) -> dict:
    """Feed ``msgs`` to a ``StreamingFusion``, timing every ``add()`` + ``current_estimate()``."""
    fusion = StreamingFusion(backend, config, ["camera", "wheel", "imu"], wheel_config=s.wheel.config,
                             imu_noise=s.imu.noise, background=background)
    lat, cpu, age, age_held, t_new, pos = [], [], [], [], [], []
    newest = -np.inf
    for _, kind, m in msgs:
        sensor = message_sensor(kind)
        c0, p0 = time.perf_counter(), time.thread_time()
        fusion.add(sensor, m)
        est = fusion.current_estimate()
        lat.append(time.perf_counter() - c0)
        cpu.append(time.thread_time() - p0)
        newest = max(newest, m.t1 if kind == "visual" else m.t)
        if est is not None:
            held = fusion.processed_estimate()
            age.append(newest - est.t)
            age_held.append(newest - held.t)
            t_new.append(newest)
            pos.append(est.pose[:2])
    result = fusion.finish()
    name = "ekf" if backend == "ekf" else "gtsam_online"
    err = np.linalg.norm(np.array(pos) - truth_at(s, np.array(t_new)), axis=1)
    return {"lat": np.array(lat), "cpu": np.array(cpu), "age": np.array(age), "age_held": np.array(age_held),
            "err": err, "late": sum(c.late for c in result.counts[name].values()), "rewinds": fusion.rewinds}


def run_dead_reckoning(s, msgs) -> dict:
    """The baseline: the pose integrated from each pair of wheel ticks, returned after every sample."""
    cfg = s.wheel.config
    per_tick = 2.0 * np.pi / cfg.ticks_per_revolution
    pose, prev, t_last = np.zeros(3), None, None
    lat, cpu, t_new, pos = [], [], [], []
    for _, kind, m in msgs:
        c0, p0 = time.perf_counter(), time.thread_time()
        if kind == "wheel":
            if prev is not None:
                dl = ((int(m.left - prev[0]) + 2**31) % 2**32 - 2**31) * per_tick * cfg.wheel_radius_left
                dr = ((int(m.right - prev[1]) + 2**31) % 2**32 - 2**31) * per_tick * cfg.wheel_radius_right
                d, dyaw = 0.5 * (dl + dr), (dr - dl) / cfg.wheel_base
                mid = pose[2] + 0.5 * dyaw
                pose = pose + np.array([d * np.cos(mid), d * np.sin(mid), dyaw])
            prev, t_last = (m.left, m.right), m.t
        out = pose.copy()
        lat.append(time.perf_counter() - c0)
        cpu.append(time.thread_time() - p0)
        if prev is not None:
            t_new.append(t_last)
            pos.append(out[:2])
    err = np.linalg.norm(np.array(pos) - truth_at(s, np.array(t_new)), axis=1)
    return {"lat": np.array(lat), "cpu": np.array(cpu), "err": err}


def latency(args) -> int:
    before = load()
    fusion = fusion_settings(args)
    s, streams = drive(args.seconds)
    msgs = time_ordered_messages(streams, args.camera_delay)
    windows = {"ekf": args.window, "gtsam": args.camera_delay + 0.05, "gtsam background": args.camera_delay + 0.05}
    configs = {name: FusionConfig.from_dict({**fusion, "reorder_window": w}) for name, w in windows.items()}
    for backend in ("ekf", "gtsam"):  # warm up: imports and first-call caches (a live stack starts once)
        run_backend(s, msgs[:500], backend, FusionConfig.from_dict({**fusion, "reorder_window": 0.2}))
    if args.gc_freeze:
        gc.collect()
        gc.freeze()
    print(f"objects the garbage collector tracks: {len(gc.get_objects())}"
          + (f" (+ {gc.get_freeze_count()} frozen)" if args.gc_freeze else ""))
    runs: dict[str, list] = {"wheel dead reckoning (baseline)": [], "ekf": [], "gtsam": [], "gtsam background": []}
    for _ in range(args.repeat):
        runs["wheel dead reckoning (baseline)"].append(run_dead_reckoning(s, msgs))
        for name in ("ekf", "gtsam", "gtsam background"):
            runs[name].append(run_backend(s, msgs, name.split()[0], configs[name], name.endswith("background")))
    print(f"load average (1 min) {before} before, {load()} after, on {os.cpu_count()} cores; {args.seconds:.0f} s "
          f"drive, {len(msgs)} samples (camera 20 Hz arriving {args.camera_delay * 1e3:.0f} ms late, wheels 50 Hz, "
          f"IMU 200 Hz), {args.repeat} interleaved runs pooled; latency = add_*() + current_estimate()")
    rows = []
    for name, rs in runs.items():
        lat = np.concatenate([r["lat"] for r in rs]) * 1e3
        cpu = np.concatenate([r["cpu"] for r in rs]) * 1e3
        err = np.concatenate([r["err"] for r in rs]) * 100
        p50, p90, p99 = np.percentile(lat, [50, 90, 99])
        row = [name, "–" if name not in windows else f"{windows[name]:.2f} s",
               f"{p50:.3f} / {p90:.3f} / {p99:.3f} / {lat.max():.3f}", f"{np.percentile(cpu, 99):.3f} / {cpu.max():.3f}"]
        if name in windows:
            age = np.concatenate([r["age"] for r in rs]) * 1e3
            held = np.concatenate([r["age_held"] for r in rs]) * 1e3
            row += [f"{np.median(age):.1f} / {age.max():.1f} ms", f"{np.median(held):.1f} ms",
                    f"{sum(r['late'] for r in rs) // len(rs)}", f"{sum(r['rewinds'] for r in rs) // len(rs)}"]
        else:
            row += ["0 / 0 ms", "–", "–", "–"]
        rows.append(row + [f"{np.median(err):.2f} cm"])
    print(table(["per call", "reorder window", "wall p50 / p90 / p99 / max [ms]", "caller's CPU p99 / max [ms]",
                 "age of the pose (p50 / max)", "age of the held-back state (p50)", "late", "rewinds",
                 "returned pose vs truth, p50"], rows))
    return 0


# ------------------------------------------------------------------------------------------- engine
def engine_streams(root, fusion: dict) -> list[tuple[str, SensorStreams, FusionConfig]]:
    """The generated drive and the two robot logs, with the configuration both runs share (hindsight off)."""
    settings = with_settings(fusion, ["monitor=false", "sync_odometry=false"])
    config = FusionConfig.from_dict(settings)
    out = [(f"generated drive, {root['seconds']:.0f} s (camera, wheels, IMU)", drive(root["seconds"])[1], config)]
    jackal = root["dir"] / "jackal"
    if not (jackal / "imu0").is_dir():
        import_bag(JACKAL_BAG, jackal, imu_topic="/imu/data", odom_topic="/jackal_velocity_controller/odom",
                   overwrite=True)
    husky = import_husky(root["dir"] / "husky")
    for name, folder in (("Jackal bag (odometry, IMU)", jackal), ("Husky bag (odometry, IMU)", husky)):
        out.append((name, streams_from_recording(Recording(folder), None, ["odom", "imu"], config), config))
    return out


def engine(args) -> int:
    fusion = fusion_settings(args)
    print(f"load average {load()} before")
    rows = []
    with work_dir(args.out) as folder:  # (the streams are read into memory)
        cases = engine_streams({"seconds": args.seconds, "dir": folder}, fusion)
    for name, streams, config in cases:
        msgs = time_ordered_messages(streams)
        for backend, track, off in (("ekf", "ekf", ["ekf.smoother=false"]),
                                    ("gtsam", "gtsam_online", ["graph.batch=false", "graph.marginals=false"])):
            batch_config = FusionConfig.from_dict(with_settings(config.model_dump(mode="json"), off))
            times_b, times_e = [], []
            for _ in range(args.repeat):  # interleaved
                t, result = cpu_seconds(lambda: fuse(streams, backend, batch_config))
                times_b.append(t)

                def live():
                    fusion_ = streaming_for(streams, backend, config)
                    fusion_.feed(msgs)
                    return fusion_.finish()

                t, streamed = cpu_seconds(live)
                times_e.append(t)
            a, b = result.trajectories[track], streamed.trajectories[track]
            nodes = f"{len(a.t)}" if len(a.t) == len(b.t) else f"{len(a.t)} / {len(b.t)}"
            apart = f"{np.max(np.abs(a.t - b.t)):.0e}" if len(a.t) == len(b.t) else "-"
            inside = (a.t >= b.t[0]) & (a.t <= b.t[-1])  # the engine's positions interpolated at the batch's nodes
            at = np.column_stack([np.interp(a.t[inside], b.t, b.xyyaw[:, i]) for i in (0, 1)])
            diff = float(np.max(np.linalg.norm(a.xyyaw[inside, :2] - at, axis=1)))
            tb, te = statistics.median(times_b), statistics.median(times_e)
            rows.append([name, track, nodes, apart, f"{tb:.2f}", f"{te:.2f}", f"{te / tb:.1f}", f"{diff:.1e}"])
    print(table(["streams", "track", "nodes", "node times apart [s]", "batch run [s CPU]",
                 "engine, in time order [s CPU]", "engine / batch", "largest position difference [m]"], rows))
    print(f"(median of {args.repeat} interleaved runs)\nload average {load()} after")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("offline", help="EKF, GTSAM batch and iSAM2 CPU time on a drive and one ten times as long")
    p.add_argument("--seconds", type=float, default=60.0, help="length of the base drive [s]")
    p.add_argument("--scale", type=int, default=10, help="length factor of the long drive")
    p.add_argument("--repeat", type=int, default=1, help="runs of each measurement (the median is shown)")
    p.add_argument("--profile", type=int, default=0, metavar="N", help="print the N costliest functions of a batch run")
    add_settings(p)
    p.set_defaults(func=offline)
    p = sub.add_parser("solvers", help="the graph's own Levenberg-Marquardt loop beside GTSAM's optimizers")
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--repeat", type=int, default=3)
    add_settings(p)
    p.set_defaults(func=solvers)
    p = sub.add_parser("latency", help="StreamingFusion per-call latency and estimate age beside dead reckoning")
    p.add_argument("--seconds", type=float, default=60.0, help="length of the drive [s]")
    p.add_argument("--repeat", type=int, default=3, help="interleaved repetitions")
    p.add_argument("--camera-delay", type=float, default=0.15, help="camera increments arrive this late [s]")
    p.add_argument("--window", type=float, default=0.05,
                   help="reorder window of the EKF [s]; iSAM2 uses camera-delay + 0.05 (it cannot rewind)")
    p.add_argument("--gc-freeze", action="store_true", help="gc.freeze() after start-up, as a live process should")
    add_settings(p)
    p.set_defaults(func=latency)
    p = sub.add_parser("engine", help="StreamingFusion fed in time order beside the batch run's online tracks")
    p.add_argument("--seconds", type=float, default=60.0, help="length of the generated drive [s]")
    p.add_argument("--repeat", type=int, default=3, help="interleaved repetitions (the median is shown)")
    p.add_argument("--out", type=Path, help="folder for the imported bags (default: a temporary folder)")
    add_settings(p)
    p.set_defaults(func=engine)
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
