"""Cost of a pause in every stream: work must scale with the samples, not with the seconds between them.

A small generated recording (33 frames of 160x120, 0.05 m of straight drive, wheels, IMU) is run with the
logger stopped for ``P`` seconds after 0.8 s (every stream's later rows shifted by ``P``), for each pause
length and backend, in a fresh subprocess each (so memory is that run's). Printed per run: the poses of
the fused trajectory, the CPU time and the peak memory of the whole ``fusion-vo run`` (visual odometry
included, no evaluation), and the pauses ``summary.json`` reports. The run without a pause is the
baseline in the same table.

Usage::

    python benchmarks/bench_pause.py [--pauses 0,60,3600] [--backends ekf,gtsam] [--code DIR]

``--code DIR`` runs the ``fusion_vo`` and ``frontends`` packages found in DIR (an older checkout, e.g.
``git archive REV | tar -x -C DIR``) instead of the installed ones, to measure the same table before a
change.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

SMALL = {"width": 160, "height": 120, "fu": 200.0, "fv": 200.0, "cu": 79.5, "cv": 59.5, "supersample": 1,
         "length": 0.05, "gt_rate": 50.0, "imu_rate": 100.0}


#: runs the command and reports its own CPU time and peak memory on stderr
_CHILD = ("import resource, sys\n"
          "from fusion_vo.cli.main import main\n"
          "status = main(sys.argv[1:])\n"
          "r = resource.getrusage(resource.RUSAGE_SELF)\n"
          "print('USAGE', r.ru_utime + r.ru_stime, r.ru_maxrss, file=sys.stderr)\n"
          "sys.exit(status)\n")


def _code_from(folder: str | None) -> str:
    """The child's preamble that imports the packages from ``folder`` rather than the (editable) install."""
    if not folder:
        return ""
    return ("import sys\n"
            "sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in repr(f).lower()]\n"
            f"sys.path.insert(0, {str(Path(folder).resolve())!r})\n")


def one_run(rec: Path, out: Path, backend: str, code: str | None = None, timeout: float = 600.0) -> dict:
    """``fusion-vo run`` in a fresh subprocess; its CPU seconds and peak memory."""
    try:
        proc = subprocess.run([sys.executable, "-c", _code_from(code) + _CHILD, "-q", "run", str(rec), "--out",
                               str(out), "--backend", backend, "--no-evaluate"], capture_output=True, text=True,
                              timeout=timeout)
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pauses", default="0,60,3600", help="pause lengths [s], comma-separated")
    parser.add_argument("--backends", default="ekf,gtsam")
    parser.add_argument("--code", metavar="DIR", help="run the packages in DIR (an older checkout) instead")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds a run may take (default 600)")
    args = parser.parse_args()
    from fusion_vo.simulation import simulate
    from fusion_vo.simulation.pause import pause

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        print(f"{'pause [s]':>9}  {'backend':8} {'poses':>6} {'CPU [s]':>8} {'peak [MB]':>9}  pauses reported")
        for seconds in [float(s) for s in args.pauses.split(",")]:
            rec = simulate(tmp / f"rec{seconds:g}", profile="straight", seed=4, **SMALL)
            if seconds:
                pause(rec, 0.8, seconds)
            for backend in args.backends.split(","):
                r = one_run(rec, tmp / f"out{seconds:g}{backend}", backend, args.code, args.timeout)
                if "error" in r:
                    print(f"{seconds:9g}  {backend:8} failed: {r['error']}")
                    continue
                where = ", ".join(f"{p['seconds']:.0f} s ({p['joined']})" for p in r["pauses"]) or "-"
                print(f"{seconds:9g}  {backend:8} {r['poses']:6d} {r['cpu_s']:8.2f} {r['peak_mb']:9.0f}  {where}")


if __name__ == "__main__":
    main()
