"""The whole ``fusion-vo run`` job, as a library call.

    recording -> visual odometry (frontend + ground geometry) -> backends -> files -> evaluation

Outputs (in ``out_dir``; written under a temporary folder and moved into place only when complete):

``vo.tum``            visual dead reckoning (TUM: ``t x y z qx qy qz qw``, pose of B in W)
``velocities.csv``    ``t,vx,vy,yaw_rate,status,inliers,height_ratio`` per camera frame (``height_ratio``
                      is the camera height at the frame over the height at the previous one, from the
                      similarity's scale)
``wheel.tum``         wheel dead reckoning (when the recording has wheel encoders)
``ekf.tum``, ``ekf_smoothed.tum``, ``gtsam.tum``, ``gtsam_online.tum``   fused trajectories
``NAME.cov.csv``      per pose of ``NAME.tum`` (same timestamps): ``# timestamp [s],xx,xy,xyaw,yy,yyaw,yawyaw``,
                      the upper triangle of the (x, y, yaw) covariance in m², m·rad, rad²
``run.yaml``          the configuration used and the recording's path
``summary.json``      counts, timings and notes of the run
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from fusion_vo.backends.result import write_pose_covariances
from fusion_vo.config import RunConfig
from fusion_vo.errors import InputError
from fusion_vo.measurements import PoseData
from fusion_vo.odometry import OdometryResult, run_visual_odometry
from fusion_vo.recording import Recording, write_tum

log = logging.getLogger(__name__)


@dataclass
class RunSummary:
    """What a run did, for the summary line and ``summary.json``."""

    sequence: str
    out_dir: str
    frames: int = 0
    failures: dict = field(default_factory=dict)
    skipped_frames: int = 0
    distance_m: float = 0.0
    vo_fps: float = float("nan")
    vo_seconds: float = 0.0
    backend_seconds: dict = field(default_factory=dict)
    trajectories: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    fusion: dict = field(default_factory=dict)
    metrics: dict | None = None

    def line(self) -> str:
        fails = sum(self.failures.values())
        parts = [f"{self.frames} frames", f"{fails} failed"]
        if self.skipped_frames:
            parts.append(f"{self.skipped_frames} skipped (unreadable)")
        parts += [f"{self.distance_m:.3f} m travelled", f"{self.vo_fps:.0f} frames/s"]
        if self.backend_seconds:
            parts.append(", ".join(f"{k[:-3]} {v:.2f} ms" if k.endswith("_ms") else f"{k} {v:.2f} s"
                                   for k, v in self.backend_seconds.items()))
        return "; ".join(parts) + f" -> {self.out_dir}"


def resolve_sensors(rec: Recording, config: RunConfig) -> list[str]:
    """The sensors to use: as configured (each must be in the recording) or all that are present."""
    present = {"camera": rec.has_camera(), "wheel": rec.has_wheel(), "imu": rec.has_imu(),
               "odom": rec.has_odom(), "range": rec.has_range(), "gps": rec.has_gps()}
    if config.sensors is None:
        chosen = [s for s in ("camera", "wheel", "imu") if present[s]]
        if not present["wheel"] and present["odom"]:
            chosen.append("odom")
        if not chosen:
            raise InputError("the recording has none of cam0/, wheel0/, imu0/, odom0/", rec.path)
        return chosen
    for s in config.sensors:
        if not present[s]:
            folder = {"camera": "cam0", "wheel": "wheel0", "imu": "imu0", "odom": "odom0", "range": "range0",
                      "gps": "gps0"}[s]
            raise InputError(f"sensor '{s}' was asked for but the recording has no {folder}/data.csv", rec.path)
    return list(config.sensors)


def write_velocities(path: Path, vo: OdometryResult) -> None:
    with open(path, "w") as f:
        f.write("t,vx,vy,yaw_rate,status,inliers,height_ratio\n")
        for t, v, s, n, r in zip(vo.frame_t, vo.velocity, vo.status, vo.inliers, vo.height_ratio):
            f.write(f"{t:.9f},{v[0]:.9g},{v[1]:.9g},{v[2]:.9g},{s},{int(n)},{r:.7f}\n")


def run_pipeline(
    sequence: str | Path,
    out_dir: str | Path,
    config: RunConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RunSummary:
    """Run visual odometry, the backends and the evaluation on one recording.

    Raises
    ------
    InputError
        For anything wrong with the recording or the configuration.
    """
    config = config or RunConfig()
    config.validate()
    rec = Recording(sequence)
    sensors = resolve_sensors(rec, config)
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("the output must be a folder, but a file of that name exists", out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = RunSummary(sequence=str(rec.path), out_dir=str(out_dir))
    staging = Path(tempfile.mkdtemp(prefix=".fusion-vo-partial-", dir=out_dir))
    try:
        trajectories: dict[str, PoseData] = {}
        vo = None
        if "camera" in sensors:
            vo = run_visual_odometry(rec, config.odometry_config(), progress)
            trajectories["vo"] = vo.track
            write_velocities(staging / "velocities.csv", vo)
            summary.frames = vo.n_frames
            summary.failures = dict(vo.failures)
            summary.skipped_frames = len(vo.skipped)
            summary.distance_m = vo.distance
            summary.vo_fps = vo.fps
            summary.vo_seconds = vo.elapsed_s
            if vo.skipped:
                summary.notes.append(f"{len(vo.skipped)} frames could not be read and were skipped")
            if vo.bridged_s > 0:
                summary.notes.append(f"visual track bridged {vo.bridged_s:.2f} s at constant velocity where the camera was lost")
        fused, covariances = _run_backends(rec, vo, sensors, config, summary)
        trajectories.update(fused)
        for name, traj in trajectories.items():
            if len(traj):
                write_tum(staging / f"{name}.tum", traj.t, traj.xyyaw)
                summary.trajectories.append(name)
                cov = covariances.get(name)
                if cov is not None and len(cov) == len(traj):
                    write_pose_covariances(staging / f"{name}.cov.csv", traj.t, cov)
        run_info = {"sequence": str(rec.path.resolve()), "sensors": sensors, **config.to_dict()}
        with open(staging / "run.yaml", "w") as f:
            yaml.safe_dump(run_info, f, sort_keys=False)
        with open(staging / "summary.json", "w") as f:
            json.dump({k: v for k, v in summary.__dict__.items() if k != "metrics"}, f, indent=2, default=_json_default)
        for p in staging.iterdir():
            os.replace(p, out_dir / p.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    if config.evaluate and (rec.has_groundtruth() or rec.has_gps()):
        summary.metrics = _evaluate(out_dir, rec.path)
    return summary


def _run_backends(rec: Recording, vo: OdometryResult | None, sensors: list[str], config: RunConfig,
                  summary: RunSummary) -> tuple[dict[str, PoseData], dict[str, np.ndarray]]:
    """Wheel dead reckoning and the fused backends; returns name -> trajectory and name -> (N, 3, 3)
    pose covariances."""
    from fusion_vo import backends

    t0 = time.perf_counter()
    result = backends.run_backends(rec, vo, sensors=sensors, backend=config.backend, options=config.fusion)
    summary.backend_seconds.update(result.seconds or {})
    summary.notes.extend(result.notes or [])
    summary.fusion = {k: v for k, v in result.summary().items() if k in ("counts", "calibration", "inconsistent")}
    shown = {"camera_height": "camera height {:.4f} m", "wheel_base": "wheel base {:.4f} m",
             "gyro_bias": "gyro bias {:.5f} rad/s"}
    for backend_name in ("ekf", "gtsam"):  # the smoothed and online variants share these estimates
        estimates = (result.calibration or {}).get(backend_name) or {}
        text = ", ".join(fmt.format(estimates[k]) for k, fmt in shown.items() if isinstance(estimates.get(k), float))
        if text:
            summary.notes.append(f"{backend_name} self-calibration: {text} (all estimates in summary.json)")
    log.debug("backends took %.2f s", time.perf_counter() - t0)
    return dict(result.trajectories), dict(result.covariances)


def _evaluate(out_dir: Path, seq: Path) -> dict | None:
    try:
        from fusion_vo.evaluation import evaluate_run
    except ImportError:
        return None
    return evaluate_run(out_dir, seq)


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)
