"""Synthetic ground truth and estimates for the evaluation tests (no files from elsewhere)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def square_path(rate: float = 50.0, side: float = 0.9, speed: float = 0.2, turn_rate: float = 0.8,
                pause: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Times, x, y, yaw of a counter-clockwise square driven with turns in place."""
    dt = 1.0 / rate
    rows = [(0.0, 0.0, 0.0, 0.0)]

    def hold(steps, dx=0.0, dyaw=0.0):
        for _ in range(steps):
            t, x, y, yaw = rows[-1]
            rows.append((t + dt, x + dx * np.cos(yaw), y + dx * np.sin(yaw), yaw + dyaw))

    for _ in range(4):
        steps = int(round(side / speed * rate))
        hold(steps, dx=side / steps)
        hold(int(pause * rate))
        steps = int(round(np.pi / 2 / turn_rate * rate))
        hold(steps, dyaw=np.pi / 2 / steps)
        hold(int(pause * rate))
    t, x, y, yaw = np.array(rows).T
    return t, x, y, yaw


def circle_path(rate: float = 50.0, radius: float = 0.5, period: float = 20.0):
    """Times, x, y, yaw of one full circle driven forward (heading tangent to the path)."""
    t = np.arange(0.0, period + 1e-9, 1.0 / rate)
    phase = 2.0 * np.pi * t / period
    return t, radius * np.sin(phase), radius * (1.0 - np.cos(phase)), phase


def quat_wxyz(yaw: np.ndarray) -> np.ndarray:
    return np.column_stack([np.cos(yaw / 2), np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2)])


def write_groundtruth(seq_dir: Path, t, x, y, yaw, z: float = 0.0, start_ns: int = 1_000_000_000) -> Path:
    """Write a EuRoC ground-truth CSV (with an extra velocity column that readers must ignore)."""
    path = seq_dir / "state_groundtruth_estimate0" / "data.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    q = quat_wxyz(np.asarray(yaw))
    lines = ["#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z [],"
             "v_RS_R_x [m s^-1]"]
    for i, ti in enumerate(t):
        ns = start_ns + int(round(ti * 1e9))
        lines.append(f"{ns},{x[i]:.9f},{y[i]:.9f},{z:.6f},{q[i, 0]:.9f},{q[i, 1]:.9f},{q[i, 2]:.9f},"
                     f"{q[i, 3]:.9f},0.0")
    path.write_text("\n".join(lines) + "\n")
    return path


def write_tum(path: Path, t, x, y, yaw, start_s: float = 1.0) -> Path:
    """Write a planar TUM trajectory; times are offset by ``start_s`` like the ground truth's clock."""
    q = quat_wxyz(np.asarray(yaw))
    lines = [f"{start_s + ti:.9f} {x[i]:.9f} {y[i]:.9f} 0 {q[i, 1]:.9f} {q[i, 2]:.9f} {q[i, 3]:.9f} "
             f"{q[i, 0]:.9f}" for i, ti in enumerate(t)]
    path.write_text("\n".join(lines) + "\n")
    return path


def distorted(t, x, y, yaw, scale: float = 1.0, yaw_rate_bias: float = 0.0, step: int = 1):
    """Re-integrate a path's body-frame increments with a scale error and a yaw-rate bias.

    The result is a consistent odometry trajectory (positions follow the drifting heading), sampled every
    ``step``-th pose.
    """
    t, x, y, yaw = (np.asarray(a)[::step] for a in (t, x, y, yaw))
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    dx, dy = np.diff(x), np.diff(y)
    fwd, left = c * dx + s * dy, -s * dx + c * dy
    dyaw = np.diff(yaw) + yaw_rate_bias * np.diff(t)
    est_yaw = np.concatenate([[yaw[0]], yaw[0] + np.cumsum(dyaw)])
    ce, se = np.cos(est_yaw[:-1]), np.sin(est_yaw[:-1])
    ex = np.concatenate([[x[0]], x[0] + np.cumsum(scale * (ce * fwd - se * left))])
    ey = np.concatenate([[y[0]], y[0] + np.cumsum(scale * (se * fwd + ce * left))])
    return t, ex, ey, est_yaw


def make_run(root: Path, scale: float = 1.03, yaw_rate_bias: float = 0.002, with_frames: bool = True,
             name: str = "run") -> tuple[Path, Path]:
    """A recording with square ground truth and a run folder with vo, wheel and ekf trajectories."""
    seq = root / "seq"
    t, x, y, yaw = square_path()
    if not (seq / "state_groundtruth_estimate0" / "data.csv").exists():
        write_groundtruth(seq, t, x, y, yaw)
    run = root / name
    run.mkdir(parents=True)
    write_tum(run / "vo.tum", *distorted(t, x, y, yaw, scale, yaw_rate_bias, step=2))
    write_tum(run / "wheel.tum", *distorted(t, x, y, yaw, 0.98, -yaw_rate_bias, step=1))
    write_tum(run / "ekf.tum", *distorted(t, x, y, yaw, 1.0 + (scale - 1) / 3, yaw_rate_bias / 3, step=2))
    (run / "run.yaml").write_text(f"sequence: {seq}\nfrontend: klt\nbackend: ekf\n")
    if with_frames:
        tv, xv, yv, yawv = distorted(t, x, y, yaw, scale, yaw_rate_bias, step=2)
        rows = ["t,vx,vy,yaw_rate,status,inliers", f"{1.0 + tv[0]:.6f},,,,first,0"]
        for k in range(1, len(tv)):
            dt = tv[k] - tv[k - 1]
            c, s = np.cos(yawv[k - 1]), np.sin(yawv[k - 1])
            vx = (c * (xv[k] - xv[k - 1]) + s * (yv[k] - yv[k - 1])) / dt
            vy = (-s * (xv[k] - xv[k - 1]) + c * (yv[k] - yv[k - 1])) / dt
            status = "too_few_features" if k % 97 == 0 else "ok"
            rows.append(f"{1.0 + tv[k]:.6f},{vx:.6f},{vy:.6f},{(yawv[k] - yawv[k - 1]) / dt:.6f},{status},"
                        f"{0 if status != 'ok' else 40 + k % 7}")
        (run / "velocities.csv").write_text("\n".join(rows) + "\n")
    return run, seq
