"""Edits that make a generated recording contradict itself, one stream at a time.

Used by ``benchmarks/contradictions.py`` and ``tests/consistency``: each function rewrites one file of a
recording folder (a copy: they edit in place).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation


def read_csv(path: Path) -> tuple[str, np.ndarray]:
    """The header line and the rows (timestamps in ns as int64 in column 0, the rest as float)."""
    lines = Path(path).read_text().splitlines()
    header = lines[0]
    rows = [line.split(",") for line in lines[1:] if line.strip()]
    t = np.array([int(r[0]) for r in rows], dtype=np.int64)
    values = np.array([[float(x) for x in r[1:]] for r in rows])
    return header, np.column_stack([t.astype(object), values.astype(object)])


def write_csv(path: Path, header: str, t_ns: np.ndarray, values: np.ndarray, fmt: str = "%.9g") -> None:
    with open(path, "w") as f:
        f.write(header + "\n")
        for t, row in zip(t_ns, values):
            f.write(f"{int(t)}," + ",".join(fmt % v for v in row) + "\n")


def columns(path: Path) -> tuple[str, np.ndarray, np.ndarray]:
    header, table = read_csv(path)
    return header, table[:, 0].astype(np.int64), table[:, 1:].astype(np.float64)


def flip_left_encoder(rec: Path) -> None:
    """The left encoder counts backwards."""
    header, t, v = columns(rec / "wheel0" / "data.csv")
    v[:, 0] = -v[:, 0]
    write_csv(rec / "wheel0" / "data.csv", header, t, v, "%d")


def shift_clock(rec: Path, stream: str, seconds: float) -> None:
    """Every timestamp of ``stream``'s data.csv ``seconds`` later."""
    path = rec / stream / "data.csv"
    header, t, v = columns(path)
    write_csv(path, header, t + int(round(seconds * 1e9)), v, "%d" if stream == "wheel0" else "%.9g")


def twist_from_truth(rec: Path, frame: str = "body", rate_hz: float = 20.0) -> None:
    """An odometry twist ``odom0`` from the ground truth: ``vx, vy`` in the body frame, in the odometry (world)
    frame (``frame="world"``) or with the body axes turned by 90° (``frame="turned"``: ``vx, vy = vy_b, -vx_b``)."""
    _, t, gt = columns(rec / "state_groundtruth_estimate0" / "data.csv")
    yaw = Rotation.from_quat(gt[:, [4, 5, 6, 3]]).as_euler("ZYX")[:, 0]
    ts = t * 1e-9
    grid = np.arange(ts[0], ts[-1], 1.0 / rate_hz)
    x, y = np.interp(grid, ts, gt[:, 0]), np.interp(grid, ts, gt[:, 1])
    psi = np.interp(grid, ts, np.unwrap(yaw))
    vxw, vyw, wz = np.gradient(x, grid), np.gradient(y, grid), np.gradient(psi, grid)
    c, s = np.cos(psi), np.sin(psi)
    vxb, vyb = c * vxw + s * vyw, -s * vxw + c * vyw
    vx, vy = {"body": (vxb, vyb), "world": (vxw, vyw), "turned": (vyb, -vxb)}[frame]
    (rec / "odom0").mkdir(exist_ok=True)
    write_csv(rec / "odom0" / "data.csv", "#timestamp [ns],v_x [m s^-1],v_y [m s^-1],w_z [rad s^-1]",
              np.round(grid * 1e9).astype(np.int64), np.column_stack([vx, vy, wz]))


def turn_imu(rec: Path, gyro_rotation: np.ndarray, accel_rotation: np.ndarray | None = None) -> None:
    """The IMU's samples as an IMU mounted with ``R_BS = rotation`` gives them (``ω_S = R_BSᵀ ω_B``), while
    ``imu0/sensor.yaml`` still states its old ``T_BS``; ``accel_rotation`` turns the accelerometer otherwise."""
    path = rec / "imu0" / "data.csv"
    header, t, v = columns(path)
    v[:, 0:3] = v[:, 0:3] @ np.asarray(gyro_rotation)
    v[:, 3:6] = v[:, 3:6] @ np.asarray(gyro_rotation if accel_rotation is None else accel_rotation)
    write_csv(path, header, t, v)


def state_imu_mounting(rec: Path, rotation: np.ndarray) -> None:
    """Write ``rotation`` as the IMU's ``T_BS`` into ``imu0/sensor.yaml``."""
    path = rec / "imu0" / "sensor.yaml"
    meta = yaml.safe_load(path.read_text())
    T = np.eye(4)
    T[:3, :3] = rotation
    meta["T_BS"] = {"rows": 4, "cols": 4, "data": [float(x) for x in T.reshape(-1)]}
    path.write_text(yaml.safe_dump(meta))
