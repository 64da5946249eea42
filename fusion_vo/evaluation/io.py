"""Files read and written by the evaluation.

Readers
-------
* TUM trajectories: one pose per line, ``timestamp x y z qx qy qz qw`` (seconds, pose of the body frame B
  in the world W). Blank lines and lines starting with ``#`` are skipped.
* Ground truth in the EuRoC layout: ``#timestamp [ns],p_x,p_y,p_z,q_w,q_x,q_y,q_z[,...]``; columns after
  the quaternion are ignored. Timestamps are converted to seconds.
* ``velocities.csv`` of a run: header ``t,vx,vy,yaw_rate,status,inliers`` (further columns such as
  ``height_ratio`` are ignored), one row per camera frame.

Every malformed row raises :class:`fusion_vo.errors.InputError` naming the file and the 1-based line.
Outputs are written to a temporary file in the destination folder and renamed into place, so a reader
never sees a half-written file.
"""

from __future__ import annotations

import json
import logging
import math
import os
from dataclasses import dataclass
from decimal import Decimal
from typing import TYPE_CHECKING
from pathlib import Path

import numpy as np

from frontends.base import MotionStatus
from fusion_vo.errors import InputError, check_file, check_folder
from fusion_vo.config.files import load_yaml
from fusion_vo.outputs import write_atomic  # noqa: F401  (the one atomic writer, used by plots and report)
from fusion_vo.recording.reader import read_groundtruth_csv, unit_quaternions

if TYPE_CHECKING:  # evo is the GPL-3.0 ``eval`` extra: imported where a trajectory is built
    from evo.core.trajectory import PoseTrajectory3D

logger = logging.getLogger(__name__)

#: trajectory files a run may contain, in the order they are reported
TRAJECTORY_NAMES = ("vo", "wheel", "ekf", "ekf_smoothed", "gtsam", "gtsam_online")

#: relative location of the ground truth inside a recording
GROUNDTRUTH_CSV = Path("state_groundtruth_estimate0") / "data.csv"

#: statuses a visual frontend may report for a frame (``ok`` first)
FRAME_STATUSES = tuple(status.value for status in MotionStatus)


@dataclass
class FrameVelocities:
    """Body-frame velocities measured by the visual frontend, one entry per camera frame.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Frame time [s].
    vx, vy : ndarray, shape (n,)
        Forward and leftward velocity of the body [m/s] (NaN where the frame gave none).
    yaw_rate : ndarray, shape (n,)
        Yaw rate [rad/s] (NaN where the frame gave none).
    status : list of str
        Frontend status of each frame (``ok`` or the reason it failed).
    inliers : ndarray, shape (n,)
        Number of inlier matches.
    """

    t: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    yaw_rate: np.ndarray
    status: list[str]
    inliers: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask of frames with a valid motion estimate."""
        return np.array([s == "ok" for s in self.status], dtype=bool)


def _floats(fields: list[str], path: Path, line: int) -> list[float]:
    try:
        values = [float(f) for f in fields]
    except ValueError:
        raise InputError(f"expected numbers, got {','.join(fields)!r}", path, line) from None
    if not all(math.isfinite(v) for v in values):
        raise InputError("non-finite value (NaN or inf)", path, line)
    return values


def _read_lines(path: Path) -> list[str]:
    path = check_file(path)
    try:
        return path.read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read file: {exc}", path) from None


def read_rows(path: str | Path, header: str) -> list[tuple[int, str]]:
    """The non-blank rows of a CSV file a run wrote, after its first line, with their line numbers.

    Raises
    ------
    InputError
        Naming the file when it cannot be read, and line 1 when that line is not ``header``.
    """
    path = Path(path)
    lines = _read_lines(path)
    if not lines or lines[0].strip() != header:
        raise InputError(f"expected the header '{header}'", path, 1)
    return [(number, text) for number, text in enumerate(lines[1:], start=2) if text.strip()]


def _increasing_rows(t: np.ndarray, lines: list[int], path: Path) -> np.ndarray:
    """Indices of the rows to keep: a repeated timestamp keeps its last row; going back is an error."""
    step = np.diff(t)
    back = np.nonzero(step < 0.0)[0]
    if back.size:
        raise InputError(f"timestamp {float(t[back[0] + 1]):.9f} is earlier than the one before", path,
                         lines[int(back[0]) + 1])
    keep = np.append(step > 0.0, True)
    if not keep.all():
        logger.warning("%s: %d repeated timestamps, keeping the last pose of each", path, int((~keep).sum()))
    return np.nonzero(keep)[0]


@dataclass
class TumPoses:
    """The poses of a TUM file, as arrays.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Timestamps [s].
    stamp_ns : ndarray of int64, shape (n,)
        The same timestamps in integer nanoseconds, converted exactly from the file's decimal text.
    xyz : ndarray, shape (n, 3)
        Positions [m].
    quat_wxyz : ndarray, shape (n, 4)
        Unit quaternions ``(w, x, y, z)``.
    """

    t: np.ndarray
    stamp_ns: np.ndarray
    xyz: np.ndarray
    quat_wxyz: np.ndarray


def read_tum_poses(path: str | Path) -> TumPoses:
    """Read a TUM trajectory file (``timestamp x y z qx qy qz qw``) into arrays.

    Raises
    ------
    InputError
        If the file is missing, empty, a row does not hold eight finite numbers, a timestamp is beyond
        the range of int64 nanoseconds (about 9.2e9 s: e.g. nanoseconds written where seconds belong), a
        quaternion's norm is more than 0.05 from 1, or a timestamp is earlier than the one before (a
        repeated timestamp keeps its last pose).
    """
    path = Path(path)
    rows, line_numbers, stamps = [], [], []
    for number, text in enumerate(_read_lines(path), start=1):
        text = text.strip()
        if not text or text.startswith("#"):
            continue
        fields = text.replace(",", " ").split()
        if len(fields) != 8:
            raise InputError(f"expected 8 columns 'timestamp x y z qx qy qz qw', got {len(fields)}",
                             path, number)
        values = _floats(fields, path, number)
        stamp = int((Decimal(fields[0]) * 1_000_000_000).to_integral_value())
        if not -(2**63) <= stamp < 2**63:
            raise InputError(f"timestamp {fields[0]} is out of range: TUM timestamps are seconds"
                             f"{' (this looks like nanoseconds)' if abs(values[0]) >= 1e15 else ''}", path, number)
        rows.append(values)
        line_numbers.append(number)
        stamps.append(stamp)
    if not rows:
        raise InputError("no poses in trajectory file", path)
    data = np.array(rows)
    keep = _increasing_rows(data[:, 0], line_numbers, path)
    data = data[keep]
    # the ground truth's rule: a norm more than 0.05 from 1 is an error (normalising a quaternion of
    # norm 1e-6 would turn rounding noise into an arbitrary rotation)
    quat_wxyz = unit_quaternions(data[:, [7, 4, 5, 6]], np.asarray(line_numbers)[keep], path, "quaternion")
    return TumPoses(data[:, 0], np.asarray(stamps, dtype=np.int64)[keep], data[:, 1:4], quat_wxyz)


def read_tum(path: str | Path, name: str | None = None) -> PoseTrajectory3D:
    """Read a TUM trajectory file as an evo trajectory (see :func:`read_tum_poses` for the rules).

    Parameters
    ----------
    path : str or Path
        The file.
    name : str, optional
        Name given to the trajectory (default: the file stem).

    Returns
    -------
    PoseTrajectory3D
        The poses, with timestamps in seconds.
    """
    from evo.core.trajectory import PoseTrajectory3D

    poses = read_tum_poses(path)
    return PoseTrajectory3D(poses.xyz, poses.quat_wxyz, poses.t, name=name or Path(path).stem)


def read_groundtruth(path: str | Path) -> PoseTrajectory3D:
    """Read ground truth in the EuRoC ``state_groundtruth_estimate0/data.csv`` format.

    The rows are read by :func:`fusion_vo.recording.reader.read_groundtruth_csv`, the one reader of
    ground truth (its rules: strictly increasing timestamps, unit quaternions, at least two poses).

    Parameters
    ----------
    path : str or Path
        The CSV file, or a recording folder containing ``state_groundtruth_estimate0/data.csv``.

    Returns
    -------
    PoseTrajectory3D
        Poses of the body in the world, timestamps in seconds, named ``groundtruth``.

    Raises
    ------
    InputError
        Naming the file and line of any row that breaks the rules.
    """
    path = Path(path)
    if path.is_dir():
        path = path / GROUNDTRUTH_CSV
    from evo.core.trajectory import PoseTrajectory3D

    gt = read_groundtruth_csv(path, min_poses=2)
    xyz = np.column_stack([gt.xyyaw[:, 0], gt.xyyaw[:, 1], gt.z])
    return PoseTrajectory3D(xyz, np.asarray(gt.quat_wxyz, dtype=np.float64), gt.t, name="groundtruth")


def read_velocities(path: str | Path) -> FrameVelocities:
    """Read the per-frame velocities a run wrote (``velocities.csv``).

    Parameters
    ----------
    path : str or Path
        The CSV file with header ``t,vx,vy,yaw_rate,status,inliers``.

    Returns
    -------
    FrameVelocities

    Raises
    ------
    InputError
        On a missing header column, a row with the wrong number of fields, a non-numeric time or inlier
        count, or an unknown status. Empty or ``nan`` velocities are accepted (failed frames).
    """
    path = Path(path)
    lines = _read_lines(path)
    if not lines:
        raise InputError("empty file", path)
    header = [h.strip() for h in lines[0].lstrip("#").split(",")]
    expected = ["t", "vx", "vy", "yaw_rate", "status", "inliers"]
    missing = [c for c in expected if c not in header]
    if missing:
        raise InputError(f"header lacks column(s) {', '.join(missing)}", path, 1)
    col = {c: header.index(c) for c in expected}
    t, vx, vy, wz, status, inliers = [], [], [], [], [], []
    for number, text in enumerate(lines[1:], start=2):
        if not text.strip():
            continue
        fields = [f.strip() for f in text.split(",")]
        if len(fields) != len(header):
            raise InputError(f"expected {len(header)} fields, got {len(fields)}", path, number)
        try:
            t.append(float(fields[col["t"]]))
            vx.append(float(fields[col["vx"]] or "nan"))
            vy.append(float(fields[col["vy"]] or "nan"))
            wz.append(float(fields[col["yaw_rate"]] or "nan"))
            inliers.append(int(float(fields[col["inliers"]] or 0)))
        except ValueError:
            raise InputError(f"expected numbers in row {text!r}", path, number) from None
        if not math.isfinite(t[-1]):
            raise InputError("non-finite time", path, number)
        if fields[col["status"]] not in FRAME_STATUSES:
            raise InputError(f"unknown status {fields[col['status']]!r} "
                             f"(expected one of {', '.join(FRAME_STATUSES)})", path, number)
        status.append(fields[col["status"]])
    return FrameVelocities(np.array(t), np.array(vx), np.array(vy), np.array(wz), status,
                           np.array(inliers, dtype=int))


def find_trajectories(run_dir: str | Path) -> dict[str, Path]:
    """List the TUM trajectories of a run folder.

    The known names (:data:`TRAJECTORY_NAMES`) come first in their fixed order, then any other ``*.tum``
    file in alphabetical order.

    Raises
    ------
    InputError
        If ``run_dir`` is not a folder or holds no ``.tum`` file.
    """
    run_dir = check_folder(run_dir, "run folder")
    files = {p.stem: p for p in sorted(run_dir.glob("*.tum"))}
    if not files:
        raise InputError("no trajectories (*.tum) in run folder", run_dir)
    ordered = [n for n in TRAJECTORY_NAMES if n in files] + [n for n in files if n not in TRAJECTORY_NAMES]
    return {n: files[n] for n in ordered}


def read_run_config(run_dir: str | Path) -> dict:
    """Read ``run.yaml`` of a run folder; an absent file gives an empty configuration.

    Raises
    ------
    InputError
        If the file exists but is not a YAML mapping (read by the one YAML reader,
        :func:`fusion_vo.config.files.load_yaml`: a one-line message naming the line), or its
        ``sequence`` (the recording's folder) is given but is not a path.
    """
    path = Path(run_dir) / "run.yaml"
    if not os.path.lexists(path):
        return {}
    config = load_yaml(path)
    named = config.get("sequence")
    if named is not None and not isinstance(named, (str, os.PathLike)):
        raise InputError(f"sequence: must be the path of the recording folder, not {named!r}", path)
    return config


def _json_safe(value):
    """Replace non-finite floats (not valid JSON) by ``None`` and numpy scalars by Python ones."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_safe(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def write_metrics(path: str | Path, metrics: dict) -> Path:
    """Write metrics as indented JSON (NaN written as ``null``), atomically."""
    text = json.dumps(_json_safe(metrics), indent=2, sort_keys=False) + "\n"
    return write_atomic(path, text)


def read_metrics(path: str | Path) -> dict:
    """Read a ``metrics.json`` written by :func:`write_metrics`."""
    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc.msg}", path, exc.lineno) from None
