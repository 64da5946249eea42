"""How much each input moved the fused track: the EKF and its smoother run once more without it.

For each input the run fused (visual odometry, wheel encoders or odometry twist, the IMU, its AHRS heading
on its own, the range finder, GPS, a registered sensor), the fusion (:func:`fusion_vo.backends.batch.fuse`,
backend ``ekf``: the filter and the Rauch–Tung–Striebel smoother) runs again on the same streams with that
input removed, and its smoothed track ``x̃(t)`` is compared with the full run's ``x(t)`` at the full run's
node times within both tracks' span:

* ``rms_m``, ``max_m``, ``end_m``: RMS, largest and last horizontal distance ``|p̃(t) - p(t)|`` [m];
* ``heading_rms_deg``, ``heading_end_deg``: RMS and last heading difference ``wrap(ψ̃ - ψ)`` [deg];
* ``distance_pct``: the change of the distance travelled, ``100 (L̃ / L - 1)`` [%] (the input's share of the
  scale: -100 % when nothing else measures a distance).

Both runs start from the same pose, so the tracks are compared as estimated; only an input that sets the world
frame (GPS: East-North-Up at its datum) is compared after the least-squares rigid SE(2) fit of the track
without it onto the full one (``aligned``), since without it the track lives in a frame of its own. An input
without which nothing can be fused (the only sensor) is recorded with the error that says so.

The figures are written to ``influence.json`` (:func:`write_influence`) and read back by the report. The
cost is one fusion per input: 5.9 s of CPU on robot_localization's 395 s Husky log (odometry twist and IMU
with AHRS, about 7900 nodes; ``docs/report.md``); ``influence: false`` in the run configuration turns it
off.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from pathlib import Path

import numpy as np

from fusion_vo.backends.batch import fuse
from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.timeline import SensorStreams
from fusion_vo.errors import InputError
from fusion_vo.evaluation.io import write_metrics
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData
from fusion_vo.sensors import registry
from fusion_vo.sensors.gps import interpolate_poses

logger = logging.getLogger(__name__)

#: file name in a run folder
INFLUENCE_JSON = "influence.json"

#: what each input is called in the report
INPUT_LABELS = {"camera": "visual odometry", "wheel": "wheel encoders", "odom": "odometry twist",
                "imu": "IMU (gyro and AHRS)", "gyro": "gyro", "ahrs": "AHRS heading", "range": "range finder",
                "gps": "GPS fixes"}

#: the figures of each input (``influence.json``'s ``inputs`` entries besides name, label, aligned, error)
FIGURES = ("rms_m", "max_m", "end_m", "heading_rms_deg", "heading_end_deg", "distance_pct", "seconds")


def label_of(name: str) -> str:
    """The plain name of an input."""
    return INPUT_LABELS.get(name, name)


def _has_ahrs(imu) -> bool:
    if imu is None or imu.orientation is None:
        return False
    q = np.asarray(imu.orientation, dtype=np.float64)
    norm = np.linalg.norm(q, axis=1)
    return int(np.count_nonzero(np.isfinite(norm) & (np.abs(norm - 1.0) < 0.1))) >= 2


def inputs(streams: SensorStreams) -> list[tuple[str, SensorStreams, bool]]:
    """``(name, streams without it, sets the world frame)`` of every input in ``streams``.

    An IMU with an AHRS orientation is two inputs: the whole IMU (``imu``, or ``gyro`` when it has no AHRS)
    and the AHRS heading alone (``ahrs``: the orientation removed, the gyro kept)."""
    out = []
    for sensor in registry.sensors():
        data = sensor.data(streams)
        if not sensor.available(data):
            continue
        without = streams.replace(**{sensor.name: None})
        name = sensor.name
        if name == "imu" and not _has_ahrs(data):
            name = "gyro"
        out.append((name, without, sensor.absolute_position))
        if name == "imu":
            out.append(("ahrs", streams.replace(imu=dataclasses.replace(data, orientation=None)), False))
    return out


def difference(track: PoseData, reference: PoseData, aligned: bool = False) -> dict:
    """The figures of ``track`` against ``reference`` (module docstring) at the reference's times within
    both spans; ``aligned``: after the rigid SE(2) fit of ``track`` onto ``reference``. NaN figures when the
    spans share fewer than two times."""
    t = np.asarray(reference.t, dtype=np.float64)
    inside = (t >= track.t[0]) & (t <= track.t[-1])
    if np.count_nonzero(inside) < 2:
        return {key: math.nan for key in FIGURES if key != "seconds"}
    ref = np.asarray(reference.xyyaw, dtype=np.float64)[inside]
    est = interpolate_poses(np.asarray(track.t), np.asarray(track.xyyaw), t[inside])
    if aligned:
        yaw, offset = se2.fit_rigid_2d(est[:, :2], ref[:, :2])
        c, s = math.cos(yaw), math.sin(yaw)
        est = np.column_stack([est[:, :2] @ np.array([[c, s], [-s, c]]) + offset, est[:, 2] + yaw])
    d = np.linalg.norm(est[:, :2] - ref[:, :2], axis=1)
    dpsi = np.degrees(se2.wrap_angle(est[:, 2] - ref[:, 2]))
    length = float(np.sum(np.linalg.norm(np.diff(ref[:, :2], axis=0), axis=1)))
    other = float(np.sum(np.linalg.norm(np.diff(est[:, :2], axis=0), axis=1)))
    return {"rms_m": float(np.sqrt(np.mean(d**2))), "max_m": float(d.max()), "end_m": float(d[-1]),
            "heading_rms_deg": float(np.sqrt(np.mean(dpsi**2))), "heading_end_deg": float(dpsi[-1]),
            "distance_pct": 100.0 * (other / length - 1.0) if length > 1e-9 else math.nan}


def leave_one_out(streams: SensorStreams, config: FusionConfig, reference: PoseData | None = None) -> dict:
    """The influence of every input of ``streams`` (module docstring).

    Parameters
    ----------
    streams : SensorStreams
        The streams the run fused.
    config : FusionConfig
        The run's fusion configuration.
    reference : PoseData, optional
        The full run's smoothed EKF track (``ekf_smoothed``, or ``ekf`` with the smoother off); fused here
        when not given (a run whose backend was the graph alone).

    Returns
    -------
    dict
        ``{"reference": name, "seconds": total CPU s, "inputs": [{"name", "label", "aligned", "error",
        figures...}, ...]}``, as written to ``influence.json``.
    """
    start = time.process_time()
    name = "ekf_smoothed" if config.ekf.smoother else "ekf"
    if reference is None:
        reference = fuse(streams, "ekf", config).trajectories[name]
    entries = []
    for input_name, without, frame in inputs(streams):
        t0 = time.process_time()
        entry = {"name": input_name, "label": label_of(input_name), "aligned": frame, "error": None}
        try:
            track = fuse(without, "ekf", config).trajectories.get(name)
        except InputError as exc:
            track = None
            entry["error"] = exc.message
        if track is None or len(track) < 2:
            entry["error"] = entry["error"] or "no fused track without it"
            entry.update({key: math.nan for key in FIGURES})
        else:
            entry.update(difference(track, reference, frame))
        entry["seconds"] = time.process_time() - t0
        entries.append(entry)
        logger.info("influence of %s: %s", input_name, entry)
    return {"reference": name, "seconds": time.process_time() - start, "inputs": entries}


def write_influence(path: str | Path, influence: dict) -> Path:
    """Write ``influence.json`` (NaN as ``null``), atomically."""
    return write_metrics(path, influence)


def read_influence(path: str | Path) -> dict:
    """Read ``influence.json`` back (``null`` figures as NaN).

    Raises
    ------
    InputError
        Naming the file (and line, for invalid JSON) when it is unreadable or not of the written form.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc.msg}", path, exc.lineno) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read file: {exc}", path) from None
    entries = data.get("inputs") if isinstance(data, dict) else None
    if not isinstance(entries, list) or not all(isinstance(e, dict) and isinstance(e.get("name"), str)
                                                for e in entries):
        raise InputError("expected {'reference': ..., 'inputs': [{'name': ..., figures...}, ...]}", path)
    for entry in entries:
        entry.setdefault("label", label_of(entry["name"]))
        for key in FIGURES:
            value = entry.get(key)
            if value is not None and not isinstance(value, (int, float)):
                raise InputError(f"inputs: {entry['name']}: {key} must be a number, not {value!r}", path)
            entry[key] = math.nan if value is None else float(value)
    return data
