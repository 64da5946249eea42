"""Monte-Carlo consistency of the fused covariances and of each sensor's noise model.

Each seed generates a drive with known sensor noise (:func:`fusion_vo.sensors.synthetic.synthetic_streams`:
camera increments, wheel encoders, gyro; no images) and calibration errors drawn from the priors the
backends are given (:func:`drawn_options`), fuses it with every backend and compares every fused pose with
the truth, the track anchored at the start as the backends are::

    e_k = (x̂_k - x_k, ŷ_k - y_k, wrap(ψ̂_k - ψ_k)),     NEES_k = e_kᵀ P_k⁻¹ e_k

(``P_k`` the pose covariance the backend reports, the numbers ``fusion-vo run`` writes to ``NAME.cov.csv``).
For a consistent estimator ``NEES_k`` is chi-square with 3 degrees of freedom, and its average over ``N``
seeds at one time lies in the 95 % band ``[χ²₃ₙ(0.025), χ²₃ₙ(0.975)] / N`` (:func:`band`). A Monte-Carlo
NEES is only chi-square when every uncertain quantity the covariance accounts for is drawn from its prior:
with exact calibrations the claimed scale and bias uncertainty would make every backend look pessimistic.

Each sensor's normalised innovation squared (NIS) comes from the EKF's own measurement blocks
(:func:`ekf_nis`): each block of a step is tested against the state predicted *and updated with the other
sensors of that step*, ``r = y - H δx₋ᵢ``, ``NIS = rᵀ (H P₋ᵢ Hᵀ + R)⁻¹ r`` (:func:`leave_one_out_nis`).
Against the prediction alone the innovation covariance of every sensor is dominated by the constant-twist
model's process noise, so a sensor whose stated noise is ten times too small would not show; against the
other sensors it does. For a consistent sensor model the NIS is chi-square with the block's size as degrees
of freedom (camera and wheels 3, gyro 1). The factor graph has no innovations: its NIS is each sensor's
residual at the solution normalised by the residual's own covariance, ``rᵀ (R - H P Hᵀ)⁻¹ r``
(:mod:`fusion_vo.backends.residuals`, ``GraphConfig.residuals``, which changes no estimate).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.stats import chi2

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.backends import ekf as ekf_mod
from fusion_vo.backends.batch import with_recorded_noise
from fusion_vo.backends.timeline import build_intervals
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

#: the fused trajectories whose NEES is computed
FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
#: the backends whose per-sensor NIS is computed
NIS_BACKENDS = ("ekf", "gtsam", "gtsam_online")
#: the calibration each seed's drive states ([m]: 1 mm of a 0.1 m camera height, 0.25 mm of a 5 cm wheel radius)
HEIGHT_SIGMA = 1e-3
RADIUS_SIGMA = 2.5e-4


def nees_track(track: PoseData, cov: np.ndarray, truth: PoseData) -> np.ndarray:
    """NEES (N,) of each pose of ``track`` with covariances ``cov`` (N, 3, 3) against ``truth`` (NaN where
    a covariance is singular)."""
    gt = np.stack([np.interp(track.t, truth.t, truth.xyyaw[:, i]) for i in range(2)], axis=1)
    yaw = np.interp(track.t, truth.t, np.unwrap(truth.xyyaw[:, 2]))
    e = np.column_stack([track.xyyaw[:, :2] - gt, se2.wrap_angle(track.xyyaw[:, 2] - yaw)])
    out = np.full(len(e), np.nan)
    for k in range(len(e)):
        try:
            out[k] = float(e[k] @ np.linalg.solve(cov[k], e[k]))
        except np.linalg.LinAlgError:
            pass
    return out


def drawn_options(duration: float, seed: int) -> SyntheticOptions:
    """A drive whose calibration errors are drawn from the priors the backends are given: camera height
    (:data:`HEIGHT_SIGMA`), common wheel radius (:data:`RADIUS_SIGMA`), wheel base (``wheel_base_sigma``) and
    gyro bias (``imu.gyro_bias_sigma``)."""
    base = SyntheticOptions(duration=duration)
    cfg = FusionConfig()
    rng = np.random.default_rng(10_000 + seed)
    z = rng.standard_normal(4)
    h_true = base.camera_height + HEIGHT_SIGMA * z[0]
    return dataclasses.replace(base, visual_scale=base.camera_height / h_true,
                               wheel_radius_factor=1.0 + RADIUS_SIGMA / base.wheel_radius * z[1],
                               wheel_base_factor=1.0 + cfg.wheel_base_sigma * z[2],
                               gyro_bias=cfg.imu.gyro_bias_sigma * z[3])


def leave_one_out_nis(P: np.ndarray, blocks: list) -> list[tuple[str, int, float]]:
    """``(sensor, dof, NIS)`` of each block of one EKF step against the prediction ``P`` updated with the
    other blocks (module docstring). ``blocks``: the step's ``(sensor, z, h, H, R, angle rows)``."""
    rows = []
    for sensor, z, h, H, R, angle in blocks:
        y = np.asarray(z, dtype=float) - h
        if angle is not None:
            y[angle] = se2.wrap_angle(y[angle])
        rows.append((sensor, y, H, R))
    out = []
    for i, (sensor, y, H, R) in enumerate(rows):
        others = [r for j, r in enumerate(rows) if j != i]
        dx, Pi = np.zeros(P.shape[0]), P
        if others:
            Ho = np.vstack([r[2] for r in others])
            yo = np.concatenate([r[1] for r in others])
            Ro = np.zeros((len(yo), len(yo)))
            a = 0
            for r in others:
                m = len(r[1])
                Ro[a:a + m, a:a + m] = r[3]
                a += m
            K = np.linalg.solve(Ho @ P @ Ho.T + Ro, Ho @ P).T
            dx, Pi = K @ yo, P - K @ Ho @ P
        r = y - H @ dx
        out.append((sensor, len(y), float(r @ np.linalg.solve(H @ Pi @ H.T + R, r))))
    return out


def ekf_nis(streams: SensorStreams, config: FusionConfig) -> dict[str, tuple[int, np.ndarray]]:
    """Sensor -> (dof, (M, 2) rows ``(t, NIS)``) over one EKF pass (:func:`leave_one_out_nis` at every step)."""
    config = with_recorded_noise(config, streams)
    iv = build_intervals(streams, config)
    readings = ekf_mod.interval_readings(iv, config)
    f = ekf_mod.filter_for(iv, config, readings)  # the filter of a batch run (ekf.run_ekf)
    out: dict[str, tuple[int, list]] = {}

    def nis(blocks):
        for sensor, dof, value in leave_one_out_nis(f.P, blocks):
            out.setdefault(sensor, (dof, []))[1].append((f.time, value))

    for k in range(iv.n_steps):
        f.step(readings, k, inspect=nis)
    return {k: (m, np.array(v)) for k, (m, v) in out.items()}


def with_residuals(config: FusionConfig | None) -> FusionConfig:
    """``config`` with the factor graph's per-sensor residuals on (no estimate changes)."""
    config = config or FusionConfig()
    return config.model_copy(update={"graph": config.graph.model_copy(update={"residuals": True})})


def run(seeds: int, duration: float, sensors=("camera", "wheel", "imu"), config: FusionConfig | None = None,
        nis: dict | None = None) -> dict[str, np.ndarray]:
    """Per fused trajectory (:data:`FUSED`), the NEES of every seed on a common time grid: (seeds, T).

    ``nis``, when given, is filled with each backend's per-sensor NIS on the same grid: backend (``ekf``,
    ``gtsam``, ``gtsam_online``) -> sensor -> ``(dof, (seeds, T) array)`` (the measurement tested at or just
    before each grid time).
    """
    grid = np.arange(1.0, duration - 0.5, 0.25)
    out: dict[str, list] = {name: [] for name in FUSED}
    per_sensor: dict[tuple[str, str], tuple[int, list]] = {}
    for seed in range(seeds):
        s = synthetic_streams(drawn_options(duration, seed), seed=seed)
        wheel = dataclasses.replace(s.wheel, config=dataclasses.replace(s.wheel.config, radius_sigma=RADIUS_SIGMA))
        streams = SensorStreams(visual=s.visual, wheel=wheel, imu=s.imu, camera_height=s.camera_height,
                                camera_height_sigma=HEIGHT_SIGMA)
        result = fuse(streams.select(list(sensors)), "all", config if nis is None else with_residuals(config))
        for name in FUSED:
            track = result.trajectories[name]
            nees = nees_track(track, result.covariances[name], s.truth)
            out[name].append(np.interp(grid + track.t[0], track.t, nees))
        if nis is None:
            continue
        found = {"ekf": ekf_nis(streams.select(list(sensors)), config or FusionConfig())}
        found.update(result.residuals)
        for backend, table in found.items():
            for sensor, (dof, rows) in table.items():
                if len(rows) < 2:
                    continue
                at = np.clip(np.searchsorted(rows[:, 0], grid + track.t[0], side="right") - 1, 0, len(rows) - 1)
                per_sensor.setdefault((backend, sensor), (dof, []))[1].append(rows[at, 1])
    if nis is not None:
        for (backend, sensor), (m, v) in per_sensor.items():
            if len(v) == seeds:
                nis.setdefault(backend, {})[sensor] = (m, np.array(v))
    return {k: np.array(v) for k, v in out.items()}


def band(dof: int, n: int) -> tuple[float, float]:
    """95 % band of the average of ``n`` chi-square variables with ``dof`` degrees of freedom."""
    lo, hi = chi2.ppf([0.025, 0.975], dof * n) / n
    return float(lo), float(hi)


def verdict(mean: float, lo: float, hi: float) -> str:
    """``consistent`` inside the band, ``overconfident`` above it (stated uncertainty too small), else
    ``pessimistic``."""
    return "consistent" if lo <= mean <= hi else ("overconfident" if mean > hi else "pessimistic")
