"""Visual odometry accuracy of both frontends on the standard generated recordings.

Prints, per frontend, the figures the tests assert (tests/end_to_end/test_vo_accuracy.py), computed
with the project's evaluation (evo-based, estimate anchored at the start):

* square     end-point error [% of the 3.6 m path] and heading error [deg] (thesis: 1.5-4.3 % per leg)
* circle     heading error after one full turn [deg] (thesis: 0.59 % of 360 deg = 2.1 deg)
* standstill largest estimated motion of a single frame [mm] and final drift [mm]
* random60   end-point error [%] and heading error [deg] on a 60 s drive at up to 0.3 m/s, 0.9 rad/s

Usage::

    python benchmarks/vo_accuracy.py [--out DIR]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from fusion_vo.config import RunConfig
from fusion_vo.odometry import run_visual_odometry
from fusion_vo.pipeline import run_pipeline
from fusion_vo.recording import Recording
from fusion_vo.simulation.standard import make_standard


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="keep recordings and runs here (default: a temporary folder)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="vo-accuracy-") as tmp:
        root = Path(args.out or tmp)
        recs = {name: make_standard(name, root / name) for name in ("square", "circle", "standstill", "random60")}
        print(f"{'frontend':<9} {'square end %':>12} {'square hdg deg':>14} {'circle hdg deg':>14} "
              f"{'still max mm/frame':>18} {'still drift mm':>14} {'random end %':>12} {'random hdg deg':>14} {'fps':>6}")
        for fe in ("klt", "features"):
            m = {}
            fps = []
            for name in ("square", "circle", "random60"):
                s = run_pipeline(recs[name], root / f"run_{fe}_{name}", RunConfig(frontend=fe, backend="none"))
                m[name] = s.metrics["vo"]
                fps.append(s.vo_fps)
            vo = run_visual_odometry(Recording(recs["standstill"]), RunConfig(frontend=fe).odometry_config())
            still = max(float(np.hypot(*inc.delta[:2])) for inc in vo.increments if inc.ok) * 1000
            drift = float(np.hypot(*vo.track.xyyaw[-1, :2])) * 1000
            print(f"{fe:<9} {m['square']['end_pct']:12.3f} {m['square']['heading_deg']:14.3f} "
                  f"{m['circle']['heading_deg']:14.3f} {still:18.4f} {drift:14.4f} "
                  f"{m['random60']['end_pct']:12.3f} {m['random60']['heading_deg']:14.3f} {np.mean(fps):6.0f}")


if __name__ == "__main__":
    main()
