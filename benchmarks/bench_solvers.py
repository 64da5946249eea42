"""GTSAM's own optimizers against the batch solver's Levenberg–Marquardt loop, on one graph.

The graph is the batch graph of the 60 s drive of ``benchmarks/bench_fusion.py`` (camera, wheels and gyro,
self-calibration on), started from the iSAM2 estimate as ``fusion_vo.backends.graph.run_graph`` does. The
loop (:func:`fusion_vo.backends.graph.levenberg_marquardt`) evaluates the sensor-model factors in numpy
and hands them to GTSAM as linear factors; GTSAM's ``LevenbergMarquardtOptimizer``,
``GaussNewtonOptimizer`` and ``DoglegOptimizer`` get the same factors as ``gtsam.CustomFactor`` s
(:meth:`fusion_vo.backends.factors.ModelFactor.custom_factor`), with the same iteration limit and relative
tolerance. Printed: CPU time (min–max over ``--repeat`` interleaved runs), iterations, final cost, and the
largest position difference from the loop's solution.

Usage::

    python benchmarks/bench_solvers.py [--seconds 60] [--repeat 3]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import time

import gtsam
import numpy as np

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.backends import graph as G
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


def capture(seconds: float):
    """The batch graph, its start values and settings, as run_graph hands them to the loop."""
    s = synthetic_streams(SyntheticOptions(duration=seconds, visual_scale=1.02), seed=1)
    streams = SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)
    captured = {}
    loop = G.levenberg_marquardt

    def grab(graph, values, dims, max_iterations, tolerance, groups):
        captured.update(graph=graph, values=values, dims=dims, args=(max_iterations, tolerance), groups=groups)
        return loop(graph, values, dims, max_iterations, tolerance, groups)

    G.levenberg_marquardt = grab
    try:
        fuse(streams, "gtsam", FusionConfig())
    finally:
        G.levenberg_marquardt = loop
    return captured


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    c = capture(args.seconds)
    graph, v0, dims, groups = c["graph"], c["values"], c["dims"], c["groups"]
    max_iterations, tolerance = c["args"]
    full = gtsam.NonlinearFactorGraph(graph)  # the same factors, the sensor models as CustomFactors
    for g in groups:
        for f in g.factors:
            full.add(f.custom_factor())
    n = sum(1 for k in dims if chr(gtsam.Symbol(k).chr()) == "x")

    def positions(values):
        return np.array([[values.atPose2(G.X(i)).x(), values.atPose2(G.X(i)).y()] for i in range(n)])

    def run(name):
        t0 = time.process_time()
        if name == "loop":
            solution, iterations, _ = G.levenberg_marquardt(graph, v0, dims, max_iterations, tolerance, groups)
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

    names = ["loop", "LevenbergMarquardt", "GaussNewton", "Dogleg"]
    rows = {name: [] for name in names}
    for _ in range(args.repeat):
        for name in names:
            rows[name].append(run(name))
    reference = rows["loop"][0][3]
    print(f"{args.seconds:.0f} s drive: {full.size()} factors ({sum(len(g) for g in groups)} sensor-model factors), "
          f"start cost {full.error(v0):.6g}; CPU time over {args.repeat} interleaved runs")
    print(f"{'solver':>20} {'CPU [ms]':>17} {'iterations':>10} {'final cost':>12} {'max |Δp| vs loop [m]':>21}")
    for name in names:
        t = [r[0] for r in rows[name]]
        _, iterations, cost, p = rows[name][0]
        print(f"{name:>20} {1e3 * min(t):8.1f}–{1e3 * max(t):7.1f} {iterations:>10d} {cost:>12.6g} "
              f"{np.abs(p - reference).max():>21.2e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
