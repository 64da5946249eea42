"""Noise parameters by maximum likelihood from the EKF's own innovations, checked where the truth is known.

For a set of noise parameters ``θ`` (configuration keys such as ``imu.gyro_random_walk``) the EKF's
prediction-error log-likelihood is

    L(θ) = -1/2 Σ_k (log det S_k + ν_kᵀ S_k⁻¹ ν_k + m_k log 2π)

over the filter's updates ``k`` (``ν_k`` the stacked innovation of the blocks the gate accepted, ``S_k``
its covariance, ``m_k`` its size), read from filterpy's filter after each update of the default
pipeline (:func:`fusion_vo.backends.fuse` with ``"ekf"``; the consistency monitor, the odometry's time
offset and the gate act as usual). Nothing else is used: no ground truth, no GPS. ``θ`` is estimated by
maximising ``L`` over ``log10 θ`` with scipy (a bounded 1-D search, or Nelder-Mead for several keys).

This script checks the method on generated drives whose gyro bias walk is known
(:func:`fusion_vo.sensors.synthetic.synthetic_streams`, with a bias random walk added to the gyro as
the generator of :mod:`fusion_vo.simulation.sensors` draws it: ``σ_bw/√f`` times a cumulative sum of
standard normals at the gyro rate ``f``), for a few true walks and seeds, in two sensor sets:
camera + wheels + gyro, and wheels + gyro + AHRS (the Husky's set, with encoders instead of a twist).
It prints the estimate, the 95 % likelihood-ratio interval (where ``L`` is within 1.92 of its
maximum), ``L`` at the true walk less the maximum, the estimates of the walk and of the gyro's white noise
density when both are estimated together (Nelder-Mead), and the streams the consistency monitor dropped
(then the estimate is about what is left).

Usage::

    python benchmarks/noise_likelihood.py [--seeds 3 | --seeds 0,3] [--duration 120] [--walks 2e-5,2e-4,1e-3] [--sets SETS]

The profile on the Husky's log is section 10 of ``benchmarks/husky_diagnosis.py``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
import time
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.optimize import minimize, minimize_scalar

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.backends import ekf as ekf_mod
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

#: sensor sets of the generated drives
SENSOR_SETS = ("camera+wheels+gyro", "wheels+gyro+ahrs")
#: log10 bounds of the searched parameters
BOUNDS = {"imu.gyro_random_walk": (-7.0, -2.0), "imu.gyro_noise_density": (-4.0, -1.5),
          "imu.ahrs_yaw_sigma": (-3.0, -0.5)}
#: L within this of its maximum: the 95 % likelihood-ratio interval of one parameter (chi2(1) 0.95 / 2)
LR_95 = 1.92


@dataclass
class Likelihood:
    """Sum of the innovation log-likelihood over the filter's updates."""

    value: float = 0.0
    rows: int = 0
    updates: int = 0

    def add(self, y: np.ndarray, S: np.ndarray) -> None:
        y = np.asarray(y, dtype=np.float64).ravel()
        factor = cho_factor(S)
        logdet = 2.0 * float(np.sum(np.log(np.diag(factor[0]))))
        self.value -= 0.5 * (logdet + float(y @ cho_solve(factor, y)) + len(y) * np.log(2.0 * np.pi))
        self.rows += len(y)
        self.updates += 1


@contextlib.contextmanager
def innovation_likelihood():
    """Within the block every EKF update adds its innovation's log-likelihood to the yielded :class:`Likelihood`."""
    total = Likelihood()
    update = ekf_mod.PlanarEkf.update

    def patched(self, blocks):
        self.kf.S = None  # filterpy sets S (and y) only when an update is applied
        update(self, blocks)
        if self.kf.S is not None:
            total.add(self.kf.y, self.kf.S)

    ekf_mod.PlanarEkf.update = patched
    try:
        yield total
    finally:
        ekf_mod.PlanarEkf.update = update


def with_values(options: dict, values: dict) -> dict:
    """``options`` (a FusionConfig mapping) with dotted keys set, e.g. ``{"imu.gyro_random_walk": 1e-4}``."""
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in options.items()}
    for key, value in values.items():
        section, name = key.split(".")
        out.setdefault(section, {})[name] = float(value)
    return out


def log_likelihood(streams: SensorStreams, values: dict, options: dict | None = None) -> tuple[float, dict]:
    """``L`` of the default EKF on ``streams`` with the keys ``values`` set; returns it and the fusion result."""
    config = FusionConfig.from_dict(with_values(options or {}, values))
    with innovation_likelihood() as total:
        result = fuse(streams, "ekf", config)
    return total.value, result


def without_recorded_walk(streams: SensorStreams) -> SensorStreams:
    """``streams`` whose IMU does not state its noise (the recording's keys would override the searched ones)."""
    if streams.imu is None:
        return streams
    return dataclasses.replace(streams, imu=dataclasses.replace(streams.imu, noise={}))


def estimate(streams: SensorStreams, keys: tuple[str, ...], options: dict | None = None,
             start: dict | None = None) -> tuple[dict, float, int]:
    """Maximum-likelihood values of ``keys``; returns them, the maximum of ``L`` and the number of evaluations."""
    calls = 0

    def cost(logs) -> float:
        nonlocal calls
        calls += 1
        return -log_likelihood(streams, {k: 10.0**v for k, v in zip(keys, np.atleast_1d(logs))}, options)[0]

    if len(keys) == 1:
        lo, hi = BOUNDS[keys[0]]
        best = minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 0.02})
        return {keys[0]: 10.0**best.x}, -best.fun, calls
    x0 = [np.log10(start[k]) if start and k in start else np.mean(BOUNDS[k]) for k in keys]
    best = minimize(cost, x0, method="Nelder-Mead", options={"xatol": 0.02, "fatol": 0.05})
    return {k: 10.0**v for k, v in zip(keys, best.x)}, -best.fun, calls


def profile(streams: SensorStreams, key: str, values, options: dict | None = None) -> np.ndarray:
    """``L`` at each of ``values`` of ``key``."""
    return np.array([log_likelihood(streams, {key: v}, options)[0] for v in values])


def interval(values, profile_l, best: float, l_max: float) -> tuple[float, float]:
    """Range of the profiled ``values`` and the maximum ``best`` whose ``L`` is within :data:`LR_95` of the
    maximum ``l_max`` (log-linear interpolation between the profiled values)."""
    order = np.argsort(np.append(values, best))
    values = np.append(values, best)[order]
    profile_l = np.append(profile_l, l_max)[order]
    l_max = float(profile_l.max())
    inside = profile_l >= l_max - LR_95
    if not inside.any():
        return float("nan"), float("nan")
    idx = np.flatnonzero(inside)
    lv = np.log10(values)

    def edge(i_in: int, i_out: int) -> float:
        if i_out < 0 or i_out >= len(values):
            return float(values[i_in])
        a, b = profile_l[i_in] - (l_max - LR_95), profile_l[i_out] - (l_max - LR_95)
        return float(10.0 ** (lv[i_in] + (lv[i_out] - lv[i_in]) * a / (a - b)))

    return edge(idx[0], idx[0] - 1), edge(idx[-1], idx[-1] + 1)


def generated(walk: float, seed: int, duration: float, sensors: str) -> SensorStreams:
    """A generated drive with a gyro bias random walk ``walk`` [rad/s/√s] (see the module docstring)."""
    ahrs = "ahrs" in sensors
    options = SyntheticOptions(duration=duration, ahrs_sigma=0.02 if ahrs else None)
    s = synthetic_streams(options, seed=seed)
    rng = np.random.default_rng([seed, 7])
    imu = s.imu
    rate = imu.rate_hz
    gyro = np.array(imu.gyro, dtype=np.float64)
    gyro[:, 2] += np.cumsum(rng.standard_normal(len(gyro))) * walk / np.sqrt(rate)
    imu = dataclasses.replace(imu, gyro=gyro, noise={})
    return SensorStreams(visual=None if ahrs else s.visual, camera_height=s.camera_height, wheel=s.wheel, imu=imu)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", default="3", help="number of seeds (0, 1, ...), or a comma-separated list of seeds")
    parser.add_argument("--duration", type=float, default=120.0, help="length of each generated drive [s]")
    parser.add_argument("--walks", default="2e-5,2e-4,1e-3", help="true gyro bias walks [rad/s/sqrt(s)]")
    parser.add_argument("--sets", default=",".join(SENSOR_SETS), help="sensor sets (comma-separated)")
    args = parser.parse_args(argv)
    walks = [float(w) for w in args.walks.split(",")]
    seeds = [int(v) for v in args.seeds.split(",")] if "," in args.seeds else list(range(int(args.seeds)))
    grid = np.logspace(-7.0, -2.0, 11)
    print(f"ML gyro bias random walk from the EKF's innovations, generated {args.duration:g} s drives "
          "(true gyro white noise 2e-3 rad/s/sqrt(Hz), stated to the filter)")
    print(f"{'sensors':24s} {'true walk':>9s} {'seed':>4s} {'ML walk':>9s} {'95% interval':>21s} "
          f"{'L(true)-Lmax':>12s} {'joint walk, density':>22s} {'s':>5s}")
    for sensors in args.sets.split(","):
        for walk in walks:
            for seed in seeds:
                t0 = time.process_time()
                streams = generated(walk, seed, args.duration, sensors)
                opts = {"imu": {"gyro_noise_density": 2e-3}}
                best, l_max, _ = estimate(streams, ("imu.gyro_random_walk",), opts)
                prof = profile(streams, "imu.gyro_random_walk", grid, opts)
                lo, hi = interval(grid, prof, best["imu.gyro_random_walk"], l_max)
                l_max = max(l_max, float(prof.max()))
                l_true, result = log_likelihood(streams, {"imu.gyro_random_walk": walk}, opts)
                dropped = [n.split(" inconsistent")[0] for n in result.notes if "inconsistent" in n]
                joint, _, _ = estimate(streams, ("imu.gyro_random_walk", "imu.gyro_noise_density"), {},
                                       start={"imu.gyro_random_walk": best["imu.gyro_random_walk"],
                                              "imu.gyro_noise_density": 2e-3})
                print(f"{sensors:24s} {walk:9.1e} {seed:4d} {best['imu.gyro_random_walk']:9.2e} "
                      f"[{lo:9.2e}, {hi:9.2e}] {l_true - l_max:12.2f} "
                      f"{joint['imu.gyro_random_walk']:10.2e}, {joint['imu.gyro_noise_density']:9.2e} "
                      f"{time.process_time() - t0:5.0f}" + (f"  monitor dropped: {'; '.join(dropped)}" if dropped else ""),
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
