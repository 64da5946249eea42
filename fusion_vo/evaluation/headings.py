"""``headings.csv`` of a run: the IMU's own headings, as the run read them.

The visual and wheel tracks are written as trajectories (``vo.tum``, ``wheel.tum``); the IMU has no
track of its own, only headings. The run writes them so that the report can show them beside the others
without reading the recording again (and with the mounting ``T_BS`` the run used):

``headings.csv``  header ``t,gyro,ahrs``; ``t`` [s, recording clock], ``gyro`` [rad] the body yaw rate
                  ``(R_BS ω_S)_z`` integrated from the run's initial heading (spikes gated as the backends
                  gate them, no bias removed: the gyro's own heading), ``ahrs`` [rad] the AHRS heading
                  unwrapped and shifted so that its first valid sample equals the gyro's heading there
                  (empty where the IMU records no orientation or a sample is invalid). At most
                  :data:`MAX_ROWS` rows (every n-th sample).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusion_vo.errors import InputError
from fusion_vo.evaluation.io import read_rows, write_atomic
from fusion_vo.measurements import ImuData
from fusion_vo.sensors.imu import ImuNoise, ahrs_heading, cumulative_angle, gyro_yaw

#: file name in a run folder
HEADINGS_CSV = "headings.csv"
HEADER = "t,gyro,ahrs"
#: the most rows written (a 395 s log at 50 Hz is thinned to every 4th sample)
MAX_ROWS = 5000


@dataclass
class Headings:
    """The IMU's headings: ``t`` (N,), ``gyro`` (N,) [rad], ``ahrs`` (N,) [rad] or None without an AHRS."""

    t: np.ndarray
    gyro: np.ndarray
    ahrs: np.ndarray | None


def imu_headings(imu: ImuData, noise: ImuNoise | None = None, initial_yaw: float = 0.0) -> Headings | None:
    """The gyro's integrated heading and the AHRS heading of ``imu`` (module docstring); None without samples."""
    if imu is None or len(imu.t) < 2:
        return None
    order = np.argsort(np.asarray(imu.t, dtype=np.float64), kind="stable")
    t = np.asarray(imu.t, dtype=np.float64)[order]
    keep = np.concatenate([[True], np.diff(t) > 0])
    idx = order[keep]
    data = ImuData(t[keep], np.asarray(imu.gyro)[idx], np.asarray(imu.accel)[idx],
                   None if imu.orientation is None else np.asarray(imu.orientation)[idx], imu.T_BS)
    gyro = initial_yaw + cumulative_angle(gyro_yaw(data, noise))
    ahrs = None
    heading = ahrs_heading(data)
    if heading is not None and np.count_nonzero(heading.valid) >= 2:
        valid = heading.valid
        yaw = np.full(len(data.t), np.nan)
        yaw[valid] = np.unwrap(heading.yaw[valid])
        first = int(np.argmax(valid))
        ahrs = yaw - yaw[first] + gyro[first]
    stride = max(1, math.ceil(len(data.t) / MAX_ROWS))
    return Headings(data.t[::stride], gyro[::stride], None if ahrs is None else ahrs[::stride])


def write_headings(path: str | Path, headings: Headings) -> Path:
    """Write ``headings.csv`` atomically."""
    buf = io.StringIO()
    buf.write(HEADER + "\n")
    ahrs = headings.ahrs if headings.ahrs is not None else np.full(len(headings.t), np.nan)
    for t, g, a in zip(headings.t, headings.gyro, ahrs):
        buf.write(f"{t:.6f},{g:.7g},{'' if not math.isfinite(a) else f'{a:.7g}'}\n")
    return write_atomic(path, buf.getvalue())


def read_headings(path: str | Path) -> Headings:
    """Read ``headings.csv`` back.

    Raises
    ------
    InputError
        Naming the file and line: a wrong header, a row without three fields, a non-numeric or non-finite
        time or gyro heading, times that do not increase.
    """
    path = Path(path)
    t, gyro, ahrs = [], [], []
    for number, text in read_rows(path, HEADER):
        fields = [f.strip() for f in text.split(",")]
        if len(fields) != 3:
            raise InputError(f"expected 3 fields ({HEADER}), got {len(fields)}", path, number)
        try:
            values = float(fields[0]), float(fields[1]), float(fields[2]) if fields[2] else math.nan
        except ValueError:
            raise InputError(f"expected numbers, got {text!r}", path, number) from None
        if not (math.isfinite(values[0]) and math.isfinite(values[1])):
            raise InputError("t and gyro must be finite", path, number)
        if t and values[0] <= t[-1]:
            raise InputError(f"time {fields[0]} does not increase", path, number)
        t.append(values[0])
        gyro.append(values[1])
        ahrs.append(values[2])
    if len(t) < 2:
        raise InputError("fewer than two rows", path)
    ahrs_array = np.array(ahrs)
    return Headings(np.array(t), np.array(gyro), ahrs_array if np.isfinite(ahrs_array).any() else None)
