"""The wheels' per-interval increments against the generator's truth: what the wheel model does not describe.

For each generated recording it rebuilds the generator's exact motion (same seed: the motion is drawn
first), puts the recorded encoder ticks on the backends' node grid exactly as the backends do
(:func:`fusion_vo.backends.timeline.build_intervals` with the camera's frame times as nodes), and
splits the error of each node interval's wheel travel into

* ``travel``: recorded travel of each wheel minus the true rolled distance scaled by the true radius
  error (``d_true · r_nominal / r_true``): slip, tick quantisation, interpolation at the node times,
  and any timing offset between the wheel samples and the truth;
* ``arc``: the arc model's increment from those true travels minus the model's prediction
  ``h(δ_true, k_r, k_b, c)`` at the true calibration (the error of the model's geometry alone);

and prints, per component, the mean, the standard deviation, the mean square normalised by the
variance the wheel model states (1 when honest) at the generator's true noise (``k`` = slip, ``σ_0`` =
one tick / √6, the rest as configured) and at the default noise, the correlation with speed, yaw rate
and acceleration, the lag-1 autocorrelation, and the "whiteness" (variance of sums over 16 intervals
divided by 16 times the variance of one: 1 for white errors).

Run::

    python benchmarks/wheel_residuals.py [--out DIR] [--only random60,square]

(``--out``: a folder holding the standard recordings, e.g. one kept by ``fusion_vs_best.py --out``;
missing ones are generated there.)
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import tempfile
from pathlib import Path

import numpy as np
import yaml

from fusion_vo.backends.batch import as_config, streams_from_recording, with_recorded_noise
from fusion_vo.backends.timeline import build_intervals
from fusion_vo.geometry import se2
from fusion_vo.recording import Recording
from fusion_vo.sensors.wheel import CURVED_WHEEL, WHEEL, arc_covariance, arc_increment
from fusion_vo.simulation.generate import SimulationOptions, _motion_for
from fusion_vo.simulation.robot import Motion
from fusion_vo.simulation.standard import make_standard

DEFAULT = ("random60", "square", "circle", "gps_outage", "hard", "short")


def generator_motion(seq: Path) -> tuple[Motion, dict]:
    """The generator's exact :class:`Motion` of ``seq`` (rebuilt from its seed) and its ``simulation.yaml``."""
    sim = yaml.safe_load((seq / "simulation.yaml").read_text())
    fields = {f.name for f in dataclasses.fields(SimulationOptions)}
    opts = SimulationOptions(**{k: v for k, v in sim["options"].items() if k in fields})
    motion = _motion_for(sim["profile"], opts, np.random.default_rng(sim["seed"]))
    return motion, sim


def true_travel(motion: Motion, base: float, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """True rolled distance of the left and right wheels (base ``base``) from the start to ``times``."""
    dt = motion.dt
    d_r = (motion.v + motion.w * base / 2) * dt
    d_l = (motion.v - motion.w * base / 2) * dt
    cum_r = np.concatenate([[0.0], np.cumsum(d_r[:-1])])
    cum_l = np.concatenate([[0.0], np.cumsum(d_l[:-1])])
    return np.interp(times, motion.t, cum_l), np.interp(times, motion.t, cum_r)


def stats(e: np.ndarray, var_true: np.ndarray, var_default: np.ndarray, regressors: dict) -> str:
    e = np.asarray(e, dtype=np.float64)
    out = [f"mean {e.mean():+.2e}", f"std {e.std():.2e}",
           f"e²/σ² true {np.mean(e**2 / var_true):.2f}", f"default {np.mean(e**2 / var_default):.3f}"]
    for name, x in regressors.items():
        c = np.corrcoef(e, x)[0, 1] if np.std(x) > 0 and np.std(e) > 0 else float("nan")
        out.append(f"corr {name} {c:+.2f}")
    lag = np.corrcoef(e[:-1], e[1:])[0, 1] if np.std(e) > 0 else float("nan")
    n = 16
    m = len(e) // n * n
    white = np.var(e[:m].reshape(-1, n).sum(axis=1)) / (n * np.var(e)) if m >= 8 * n else float("nan")
    out += [f"lag-1 {lag:+.2f}", f"whiteness(16) {white:.2f}"]
    return ", ".join(out)


def residuals(seq: Path) -> dict[str, str]:
    """Residual statistics of the wheel increments of the recording ``seq`` (see the module docstring)."""
    rec = Recording(seq)
    motion, sim = generator_motion(seq)
    o, truth = sim["options"], sim["truth"]
    config = as_config(None)
    streams = streams_from_recording(rec, None, ["wheel"], config)
    config = with_recorded_noise(config, streams)
    t_start = o["start_time_ns"] * 1e-9
    frames = np.asarray(rec.frame_times, dtype=np.float64)
    iv = build_intervals(streams, config, nodes=frames)
    T = iv.t - t_start  # the generator's clock
    ok = iv.wheel_ok
    # truth on the node grid
    pose = motion.pose_at(T)
    true_inc = np.array([se2.between(pose[k], pose[k + 1]) for k in range(len(T) - 1)])
    tl, tr = true_travel(motion, truth["wheel_base"], T)
    dtl, dtr = np.diff(tl), np.diff(tr)
    r0 = o["wheel_radius"]
    el, er = truth["wheel_radius_left"] / r0 - 1.0, truth["wheel_radius_right"] / r0 - 1.0
    exp_l, exp_r = dtl / (1 + el), dtr / (1 + er)  # what perfect encoders of the true wheels would report
    e_l, e_r = iv.wheel_dl - exp_l, iv.wheel_dr - exp_r
    # calibration of the model at the truth
    b_nom = iv.wheel_base
    k_r = 0.5 * (1 / (1 + el) + 1 / (1 + er))
    k_b = truth["wheel_base"] / b_nom * 0.5 * (1 / (1 + el) + 1 / (1 + er))
    c = (1 / (1 + er) - 1 / (1 + el)) / b_nom
    n = len(true_inc)
    pred = WHEEL.evaluate(true_inc, np.full((n, 1), k_r), np.full((n, 1), k_b))[0]
    pred_curved = CURVED_WHEEL.evaluate(true_inc, np.full((n, 1), k_r), np.full((n, 1), k_b), np.full((n, 1), c),
                                        np.full(n, b_nom))[0]
    arc_true = arc_increment(exp_l, exp_r, b_nom)
    e_arc = arc_true - pred_curved
    arc_meas = arc_increment(iv.wheel_dl, iv.wheel_dr, b_nom)
    e_all = arc_meas - pred
    e_curved = arc_meas - pred_curved
    # regressors
    dt = np.diff(T)
    mid = 0.5 * (T[:-1] + T[1:])
    v, w = np.interp(mid, motion.t + 0.5 * motion.dt, motion.v), np.interp(mid, motion.t + 0.5 * motion.dt, motion.w)
    acc = np.gradient(v, mid)
    reg = {"speed": v[ok], "yaw rate": w[ok], "|yaw rate|": np.abs(w[ok]), "accel": acc[ok]}
    wheel_cfg = config.wheel_model(iv.twist)[0]
    tick = 2 * math.pi * o["wheel_radius"] / o["ticks_per_revolution"]
    honest = dataclasses.replace(wheel_cfg, k=max(o["slip"], 1e-6), sigma_floor=tick / math.sqrt(6))
    var_t = honest.k**2 * np.abs(iv.wheel_dl) + honest.sigma_floor**2
    var_d = wheel_cfg.k**2 * np.abs(iv.wheel_dl) + wheel_cfg.sigma_floor**2
    var_tr = honest.k**2 * np.abs(iv.wheel_dr) + honest.sigma_floor**2
    var_dr = wheel_cfg.k**2 * np.abs(iv.wheel_dr) + wheel_cfg.sigma_floor**2
    cov_t = arc_covariance(iv.wheel_dl, iv.wheel_dr, b_nom, honest, dt)
    cov_d = arc_covariance(iv.wheel_dl, iv.wheel_dr, b_nom, wheel_cfg, dt)
    out = {
        "intervals": f"{int(ok.sum())} of {len(ok)} used, dt median {np.median(dt) * 1e3:.1f} ms, wheel rate "
                     f"{o['wheel_rate']:.0f} Hz, slip {o['slip']}, tick {tick * 1e6:.1f} um",
        "travel left": stats(e_l[ok], var_t[ok], var_d[ok], reg),
        "travel right": stats(e_r[ok], var_tr[ok], var_dr[ok], reg),
        "travel sum": stats((e_l + e_r)[ok], (var_t + var_tr)[ok], (var_d + var_dr)[ok], reg),
        "travel diff": stats((e_r - e_l)[ok], (var_t + var_tr)[ok], (var_d + var_dr)[ok], reg),
    }
    for i, name in enumerate(("x", "y", "yaw")):
        out[f"arc geometry {name}"] = stats(e_arc[ok, i], cov_t[ok, i, i], cov_d[ok, i, i], reg)
    for i, name in enumerate(("x", "y", "yaw")):
        out[f"increment {name}"] = stats(e_all[ok, i], cov_t[ok, i, i], cov_d[ok, i, i], reg)
    for i, name in enumerate(("x", "y", "yaw")):
        out[f"curved model {name}"] = stats(e_curved[ok, i], cov_t[ok, i, i], cov_d[ok, i, i], reg)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="folder of the standard recordings (generated there if missing)")
    parser.add_argument("--only", help="comma-separated standard recordings (default: %s)" % ",".join(DEFAULT))
    args = parser.parse_args(argv)
    names = args.only.split(",") if args.only else list(DEFAULT)
    out = args.out or Path(tempfile.mkdtemp(prefix="wheel-residuals-"))
    for name in names:
        seq = out / name
        if not (seq / "simulation.yaml").exists():
            make_standard(name, seq)
        print(name)
        for key, text in residuals(seq).items():
            print(f"  {key:20s} {text}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
