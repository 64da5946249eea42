"""The whole ``fusion-vo run`` job, as a library call.

    check every input -> visual odometry (frontend + ground geometry) -> backends -> files -> evaluation

Before any work, :func:`check_inputs` validates the whole configuration and reads every stream the run
will use, so that a mistake anywhere (a malformed row, a broken stream, a bad option, streams on different
clocks, unusable ground truth) stops the run at once with a message naming the file, line or key.

The output folder belongs to one run. Everything, the evaluation included, is written into a hidden
staging folder beside it and moved into place in one rename only when all of it succeeded
(:class:`fusion_vo.outputs.OutputFolder`): a failed or interrupted run leaves the previous folder as it
was and nothing that looks complete; a later run replaces the folder as a whole, so no file of an earlier
run survives into it; while a run writes, the folder is locked against a second run. An existing folder
is replaced only if it is empty or was written by ``fusion-vo run`` (it holds ``.fusion-vo-run``),
unless ``force``.

Outputs (in ``out_dir``):

``vo.tum``            visual dead reckoning (TUM: ``t x y z qx qy qz qw``, pose of B in W)
``velocities.csv``    ``t,vx,vy,yaw_rate,status,inliers,height_ratio`` per camera frame (``height_ratio``
                      is the camera height at the frame over the height at the previous one, from the
                      similarity's scale)
``wheel.tum``         wheel dead reckoning (when the recording has wheel encoders)
``ekf.tum``, ``ekf_smoothed.tum``, ``gtsam.tum``, ``gtsam_online.tum``   fused trajectories
``NAME.cov.csv``      per pose of ``NAME.tum`` (same timestamps): ``# timestamp [s],xx,xy,xyaw,yy,yyaw,yawyaw``,
                      the upper triangle of the (x, y, yaw) covariance in m², m·rad, rad²
``innovations.csv``   every measurement block the EKF tested: NIS and gate outcome (:mod:`fusion_vo.evaluation.innovations`)
``headings.csv``      the IMU's own headings: gyro integrated, AHRS (:mod:`fusion_vo.evaluation.headings`)
``influence.json``    how far the fused track moves with each input left out (:mod:`fusion_vo.evaluation.influence`;
                      configuration ``influence``)
``run.yaml``          the configuration used and the recording's path
``summary.json``      counts, timings, notes, calibration (with priors) and the files the run wrote
``report.html``, figures   the report (:mod:`fusion_vo.evaluation.run_report`; ``docs/report.md``), for every run;
                      ``metrics.json`` with it when the recording has ground truth or GPS fixes. A report that
                      cannot be drawn is a warning and a note, not a failed run.
"""

from __future__ import annotations

import io
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from frontends import make_frontend
from fusion_vo import backends
from fusion_vo.backends.result import write_pose_covariances
from fusion_vo.calibration.camera_noise import CameraNoise
from fusion_vo.config import RunConfig
from fusion_vo.config.sensor_files import uncalibrated_camera
from fusion_vo.errors import InputError
from fusion_vo.evaluation import run_report
from fusion_vo.evaluation.headings import imu_headings, write_headings
from fusion_vo.evaluation.influence import inputs as influence_inputs, leave_one_out, write_influence
from fusion_vo.evaluation.innovations import from_residuals, write_innovations
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.measurements import PoseData
from fusion_vo.odometry import OdometryConfig, OdometryResult, run_visual_odometry
from fusion_vo.outputs import OutputFolder, check_outside, check_replaceable, write_atomic
from fusion_vo.recording import Recording, write_tum
from fusion_vo.recording.csvio import read_table
from fusion_vo.recording.reader import GROUNDTRUTH, read_groundtruth_csv
from fusion_vo.sensors import registry
from fusion_vo.sensors.gps import has_fixes, read_fixes

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
    sensors: list = field(default_factory=list)
    files: list = field(default_factory=list)
    metrics: dict | None = None
    report: dict = field(default_factory=dict)

    def line(self) -> str:
        fails = sum(self.failures.values())
        parts = []
        if self.frames:
            parts = [f"{self.frames} frames", f"{fails} failed"]
            if self.skipped_frames:
                parts.append(f"{self.skipped_frames} skipped (unreadable)")
            parts += [f"{self.distance_m:.3f} m travelled", f"{self.vo_fps:.0f} frames/s"]
        else:
            parts.append("no camera")
        if self.backend_seconds:
            parts.append(", ".join(f"{k[:-3]} {v:.2f} ms" if k.endswith("_ms") else f"{k} {v:.2f} s"
                                   for k, v in self.backend_seconds.items()))
        return "; ".join(parts) + f" -> {self.out_dir}"


#: marker file of a run folder (its presence allows a later run to replace the folder)
RUN_MARKER = ".fusion-vo-run"

#: a jump between two consecutive timestamps of one stream longer than this is a clock error [s]
MAX_JUMP_S = 86400.0


def resolve_sensors(rec: Recording, config: RunConfig) -> list[str]:
    """The sensors to use: as configured (each must be in the recording) or all that are present.

    Any registered sensor (:mod:`fusion_vo.sensors.registry`) may be named; by default the camera, wheels
    (or odometry) and IMU are used, and a sensor registered outside the library when its folder is present
    (and its ``default`` allows)."""
    return _resolve(rec, config)[0]


def _resolve(rec: Recording, config: RunConfig) -> tuple[list[str], dict[str, bool]]:
    """:func:`resolve_sensors`, and which registered sensors the recording has (name -> present)."""
    registry.ensure(config.sensors or ())
    known = registry.sensors()
    present = {s.name: s.present(rec) for s in known}
    if config.sensors is None:
        chosen = [s for s in ("camera", "wheel", "imu") if present[s]]
        if not present["wheel"] and present["odom"]:
            chosen.append("odom")
        if not chosen:
            raise InputError("the recording has none of cam0/, wheel0/, imu0/, odom0/", rec.path)
        return chosen + [s.name for s in known if s.name not in registry.BUILTIN_ORDER and present[s.name]
                         and s.by_default(present)], present
    for s in config.sensors:
        if s not in present:
            raise InputError(f"unknown sensor '{s}' (use {', '.join(present)})", rec.path)
        if not present[s]:
            folder = registry.get(s).folder or registry.get(s).where
            raise InputError(f"the sensors to use include '{s}' but the recording has no {folder.rstrip('/')}/",
                             rec.path)
    return list(config.sensors), present


@dataclass
class RunInputs:
    """What :func:`check_inputs` found: the recording, the sensors to use and each stream's time span [s]."""

    recording: Recording
    sensors: list[str]
    spans: dict[str, tuple[float, float]]
    groundtruth: PoseData | None
    times: dict[str, np.ndarray] = field(default_factory=dict)


def _config_error(exc: Exception, config_path: Path | None, key: str) -> InputError:
    """An error in the configuration, blamed on the configuration file and the key."""
    message = exc.message if isinstance(exc, InputError) else str(exc)
    where = f"{key}: " if key and not message.startswith(key) else ""
    return InputError(f"{where}{message}", config_path)


def check_inputs(sequence: str | Path, config: RunConfig, config_path: str | Path | None = None) -> RunInputs:
    """Check the configuration against the recording and read every input the run will use, before any work
    (the configuration's own values were checked when it was made, :class:`~fusion_vo.config.run.RunConfig`).

    Raises
    ------
    InputError
        Naming the configuration file and key, or the recording's file and line, of the first problem
        found: an option that does not fit the recording (a camera height, a frontend's setting), a stream that is malformed, broken or missing, frame names outside
        ``cam0/data/``, streams whose time spans do not overlap (different clocks), a timestamp that jumps by
        more than a day, or ground truth that cannot be used for the evaluation.
    """
    config_path = None if config_path is None else Path(config_path)
    odometry = config.odometry_config()

    rec = Recording(sequence)
    sensors, present = _resolve(rec, config)
    spans: dict[str, tuple[float, float]] = {}
    files: dict[str, Path] = {}
    times: dict[str, np.ndarray] = {}

    def note(name: str, t: np.ndarray, folder: str) -> None:
        if len(t):
            spans[name] = (float(t[0]), float(t[-1]))
            files[name] = rec.path / folder / "data.csv"
            times[name] = t

    if "camera" in sensors:
        if odometry.uncalibrated:  # cam0/sensor.yaml may have no intrinsics (the run's own model is checked here)
            try:
                cam = uncalibrated_camera(rec.path / "cam0" / "sensor.yaml", odometry.focal_length, quiet=True)
            except InputError as exc:  # a configured focal length out of range for the file's resolution
                if odometry.focal_length is None or not exc.message.startswith("focal_length:"):
                    raise
                raise _config_error(exc, config_path, "odometry") from None
        else:
            cam = rec.camera  # cam0/sensor.yaml
        if odometry.camera_noise:
            CameraNoise.stated(rec)  # a bad camera_noise in cam0/sensor.yaml
        t_ns, _, _ = rec._frames_index()  # cam0/data.csv, frame names inside cam0/data/
        if len(t_ns) < 2:
            raise InputError(f"{len(t_ns)} frame listed: visual odometry needs at least two",
                             rec.path / "cam0" / "data.csv")
        if not (rec.path / "cam0" / "data").is_dir() and rec.video_path() is None:
            raise InputError("no frames: neither cam0/data/ nor cam0/video.<ext> exists", rec.path / "cam0")
        rec.pixel_shift()  # a bad bit_depth in cam0/sensor.yaml
        try:
            geometry = GroundGeometry(cam, height=odometry.height, min_sigma_xy=odometry.min_sigma_xy,
                                      min_sigma_yaw=odometry.min_sigma_yaw)
        except ValueError as exc:
            if odometry.height is not None:
                raise _config_error(exc, config_path, "odometry.height") from None
            raise InputError(str(exc), rec.path / "cam0" / "sensor.yaml") from None
        for name in ("klt", "features"):  # both sections, not only the frontend in use
            try:
                make_frontend(name, getattr(config, name).to_dict(), point_map=geometry.rectifier)
            except (InputError, TypeError, ValueError) as exc:
                raise _config_error(exc, config_path, name) from None
        note("camera", t_ns * 1e-9, "cam0")
    for sensor in registry.sensors():  # every stream the run reads, by its sensor's reader, now (the camera's frames above)
        if sensor.name == "camera" or sensor.read is None:
            continue
        scales_frames = sensor.name == "range" and "camera" in sensors and odometry.use_range and present["range"]
        if sensor.is_wanted(sensors, present) or scales_frames:
            data = sensor.read(rec)
            note(sensor.name, np.asarray(getattr(data, "t", ()), dtype=np.float64), sensor.folder or sensor.name)

    for name, path in files.items():  # a jump of more than a day inside one stream: another clock
        step = np.diff(times[name])
        if len(step) and step.max() > MAX_JUMP_S:
            i = int(np.argmax(step))
            line = _line_of(rec, name, float(times[name][i + 1]))
            raise InputError(f"timestamp jumps by {step[i]:.0f} s from the row before; all rows of a stream must "
                             "be on the recording's clock", path, line)
    names = list(spans)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            (a0, a1), (b0, b1) = spans[a], spans[b]
            if a1 < b0 or b1 < a0:
                raise InputError(f"the {a} and {b} streams do not overlap in time ({a} {_span(spans[a])}, "
                                 f"{b} {_span(spans[b])}): all streams must be stamped on one clock", rec.path)

    groundtruth = None
    if config.evaluate and rec.has_groundtruth():
        gt_path = rec.path / "state_groundtruth_estimate0" / "data.csv"
        groundtruth = read_groundtruth_csv(rec.data_file(GROUNDTRUTH, "ground truth"), min_poses=2)
        g0, g1 = float(groundtruth.t[0]), float(groundtruth.t[-1])
        if spans:
            lo = min(v[0] for v in spans.values())
            hi = max(v[1] for v in spans.values())
            if g1 < lo or hi < g0:
                raise InputError(f"ground truth {_span((g0, g1))} does not overlap the sensors' "
                                 f"{_span((lo, hi))}: it must be stamped on the recording's clock", gt_path)
    if config.evaluate and groundtruth is None and has_fixes(rec):
        read_fixes(rec)  # the fixes the evaluation scores against: a malformed file stops the run before any work
    return RunInputs(rec, sensors, spans, groundtruth, times)


def _line_of(rec: Recording, name: str, t: float) -> int | None:
    """The line of ``name``'s ``data.csv`` whose timestamp is ``t`` [s] (a reader may have skipped rows, as GPS
    skips unusable fixes), or None."""
    if name == "camera":
        t_ns, _, lines = rec._frames_index()
    else:
        try:
            tab = read_table(rec.path / registry.get(name).folder / "data.csv", (1, 64), "values", allow_nan=True)
        except InputError:
            return None
        t_ns, lines = tab.t_ns, tab.lines
    rows = np.flatnonzero(np.abs(t_ns * 1e-9 - t) < 1e-9)
    return int(lines[rows[0]]) if len(rows) else None


def _span(span: tuple[float, float]) -> str:
    return f"{span[0]:.3f} s to {span[1]:.3f} s"


def write_velocities(path: Path, vo: OdometryResult) -> None:
    f = io.StringIO()
    f.write("t,vx,vy,yaw_rate,status,inliers,height_ratio\n")
    for t, v, s, n, r in zip(vo.frame_t, vo.velocity, vo.status, vo.inliers, vo.height_ratio):
        f.write(f"{t:.9f},{v[0]:.9g},{v[1]:.9g},{v[2]:.9g},{s},{int(n)},{r:.7f}\n")
    write_atomic(path, f.getvalue())


def run_pipeline(
    sequence: str | Path,
    out_dir: str | Path,
    config: RunConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    force: bool = False,
    config_path: str | Path | None = None,
) -> RunSummary:
    """Check every input, then run visual odometry, the backends and the evaluation on one recording.

    Parameters
    ----------
    sequence : the recording folder.
    out_dir : the output folder, created or replaced as a whole (see the module's rules); never inside the
        recording.
    config : the run's configuration (default: every default).
    progress : callable ``(done, total)`` called after every frame.
    force : replace an output folder that is not empty and was not written by ``fusion-vo run``.
    config_path : the file ``config`` was read from, named in configuration errors.

    Raises
    ------
    InputError
        For anything wrong with the recording, the configuration or the output folder, before any work
        when it can be found by reading the inputs.
    """
    config = config or RunConfig()
    out_dir = Path(out_dir)
    read = [Path(sequence)] + ([Path(config_path)] if config_path is not None else [])
    check_replaceable(out_dir, RUN_MARKER, force, read)  # the output folder first: it is quick
    check_outside(out_dir, [Path(sequence)])  # not even a new folder inside the recording
    inputs = check_inputs(sequence, config, config_path)
    rec, sensors = inputs.recording, inputs.sensors
    summary = RunSummary(sequence=str(rec.path), out_dir=str(out_dir))
    with OutputFolder(out_dir, RUN_MARKER, force=force, inputs=read, what="output folder") as folder:
        staging = folder.path
        trajectories: dict[str, PoseData] = {}
        vo = None
        if "camera" in sensors:
            vo = run_visual_odometry(rec, config.odometry_config(), progress)
            _check_camera_result(vo, rec, sensors, summary)
            trajectories["vo"] = vo.track
            write_velocities(staging / "velocities.csv", vo)
            summary.frames = vo.n_frames
            summary.failures = dict(vo.failures)
            summary.skipped_frames = len(vo.skipped)
            summary.distance_m = vo.distance
            summary.vo_fps = vo.fps
            summary.vo_seconds = vo.elapsed_s
            if vo.skipped:
                n = len(vo.skipped)
                summary.notes.append(f"{n} frame{'s' if n != 1 else ''} could not be read and "
                                     f"{'were' if n != 1 else 'was'} skipped")
            if vo.height_note:
                summary.notes.append(vo.height_note)
            if vo.noise_note:
                summary.notes.append(vo.noise_note)
            if vo.bridged_s > 0:
                summary.notes.append(f"visual track bridged {vo.bridged_s:.2f} s at constant velocity where the camera was lost")
            for a, b in vo.held:
                summary.notes.append(f"visual track held its pose for {b - a:.2f} s from t={a:.2f}: no frame gave motion "
                                     "there and the gap is too long to bridge at constant velocity (odometry.max_bridge)")
        result, streams, fusion_config = _run_backends(rec, vo, sensors, config, summary)
        fused, covariances = dict(result.trajectories), dict(result.covariances)
        trajectories.update(fused)
        for name, traj in trajectories.items():
            if len(traj) >= 2:  # a single pose is no trajectory (a camera that never measured a motion)
                write_tum(staging / f"{name}.tum", traj.t, traj.xyyaw)
                summary.trajectories.append(name)
                cov = covariances.get(name)
                if cov is not None and len(cov) == len(traj):
                    write_pose_covariances(staging / f"{name}.cov.csv", traj.t, cov)
        write_run_records(staging, result, streams, fusion_config, config.influence and config.backend != "none")
        run_info = {"sequence": str(rec.path.resolve()), "sensors": sensors, **config.to_dict()}
        write_atomic(staging / "run.yaml", yaml.safe_dump(run_info, sort_keys=False))
        summary.sensors = list(sensors)
        summary.files = sorted(p.name for p in staging.iterdir() if p.is_file() and not p.name.startswith("."))
        _write_summary(staging, summary)
        evaluated = config.evaluate and (inputs.groundtruth is not None or has_fixes(rec))
        _report(staging, out_dir.name, summary, config.evaluate, evaluated)
        folder.commit()
    return summary


def _write_summary(staging: Path, summary: RunSummary) -> None:
    fields = {k: v for k, v in summary.__dict__.items() if k not in ("metrics", "report")}
    write_atomic(staging / "summary.json", json.dumps(_finite(fields), indent=2, default=_json_default) + "\n")


def write_run_records(staging: Path, result, streams, config, influence: bool) -> None:
    """The files the report reads besides the trajectories: ``innovations.csv`` (the EKF's and, when computed,
    the graph's NIS), ``headings.csv`` (the IMU's own headings) and, with ``influence``, ``influence.json``."""
    tables = dict(result.innovations)
    tables.update({backend: from_residuals(residuals) for backend, residuals in (result.residuals or {}).items()})
    if any(len(table) for table in tables.values()):
        write_innovations(staging / "innovations.csv", tables)
    if streams is not None and streams.imu is not None:
        headings = imu_headings(streams.imu, config.imu, float(config.initial_pose[2]))
        if headings is not None:
            write_headings(staging / "headings.csv", headings)
    if influence and streams is not None and len(influence_inputs(streams)) > 1:
        name = "ekf_smoothed" if config.ekf.smoother else "ekf"
        write_influence(staging / "influence.json", leave_one_out(streams, config, result.trajectories.get(name)))


def _report(staging: Path, name: str, summary: RunSummary, accuracy: bool, evaluated: bool) -> None:
    """Write the run's report into ``staging`` (:func:`fusion_vo.evaluation.run_report.build_report`).

    An error of the evaluation against ground truth or GPS fixes stops the run, as it always has, and so does a
    file that cannot be written (a full disk); any other failure to draw the report is a warning and a note (the
    run's files stand)."""
    try:
        content, summary.metrics = run_report.build_report(staging, None, staging, name=name, accuracy=accuracy)
    except OSError:
        raise
    except InputError:
        if evaluated:
            raise
        content = None
        problem = traceback_line()
    except Exception:  # noqa: BLE001 -- a report that cannot be drawn must not fail a run that succeeded
        content = None
        problem = traceback_line()
    if content is None:
        log.warning("report.html not written: %s", problem)
        summary.notes.append(f"report.html not written: {problem}")
        _write_summary(staging, summary)
        return
    summary.report = {"path": "report.html", "verdict": list(content.verdict), "accuracy": content.accuracy_line}


def traceback_line() -> str:
    """The exception being handled, in one line."""
    import sys

    exc = sys.exc_info()[1]
    return f"{type(exc).__name__}: {exc}" if not isinstance(exc, InputError) else str(exc)


def _check_camera_result(vo: OdometryResult, rec: Recording, sensors: list[str], summary: RunSummary) -> None:
    """A camera that gave no motion at all: an error when it is the only motion sensor, else a note."""
    ok = sum(1 for s in vo.status if s == "ok")
    if ok:
        return
    why = ", ".join(f"{n} {k}" for k, n in sorted(vo.failures.items())) or "none could be read"
    if vo.failure_reasons:  # the frontend's own reason, most often given (e.g. an OpenCV error on every frame)
        reason, count = vo.failure_reasons.most_common(1)[0]
        shown = reason if len(reason) <= 300 else reason[:297] + "..."
        why += f"; {'every one' if count == sum(vo.failures.values()) else f'{count} of them'}: {shown}"
    others = [s for s in sensors if s in ("wheel", "odom", "imu")]
    if not others:
        first = f"; first unreadable frame: {vo.skipped[0]}" if vo.skipped else ""
        raise InputError(f"no frame gave a motion estimate ({vo.n_frames} frames: {why}){first}; "
                         "nothing to estimate the motion from", rec.path / "cam0" / "data.csv")
    summary.notes.append(f"the camera gave no motion estimate in any of its {vo.n_frames} frames ({why}); "
                         f"the estimate comes from {', '.join(others)} alone")
    log.warning("%s: no frame gave a motion estimate (%s)", rec.path / "cam0", why)


def _run_backends(rec: Recording, vo: OdometryResult | None, sensors: list[str], config: RunConfig,
                  summary: RunSummary
                  ):
    """Wheel dead reckoning and the fused backends; returns the :class:`~fusion_vo.backends.FusionResult`, the
    streams it fused and the fusion configuration."""
    t0 = time.perf_counter()
    fusion_config = config.fusion
    streams = backends.streams_from_recording(rec, vo, sensors, fusion_config)
    result = backends.fuse(streams, config.backend, fusion_config)
    summary.backend_seconds.update(result.seconds or {})
    alone = not any(s in sensors for s in ("wheel", "odom", "imu"))
    for note in result.notes or []:
        if alone and "the other sensors carried the estimate" in note:  # there are none
            note = note.replace("the other sensors carried the estimate",
                                "no other sensor: the estimate there is extrapolated")
        summary.notes.append(note)
    summary.fusion = {k: v for k, v in result.summary().items() if k in ("counts", "calibration", "inconsistent", "pauses",
                                                                     "visual_noise", "priors", "time_offsets",
                                                                     "consistency")}
    shown = {"camera_height": "camera height {:.4f} m", "wheel_base": "wheel base {:.4f} m",
             "gyro_bias": "gyro bias {:.5f} rad/s"}
    for backend_name in ("ekf", "gtsam"):  # the smoothed and online variants share these estimates
        estimates = (result.calibration or {}).get(backend_name) or {}
        text = ", ".join(fmt.format(estimates[k]) for k, fmt in shown.items() if isinstance(estimates.get(k), float))
        if text:
            summary.notes.append(f"{backend_name} self-calibration: {text} (all estimates in summary.json)")
    log.debug("backends took %.2f s", time.perf_counter() - t0)
    return result, streams, fusion_config


def _finite(value):
    """NaN and infinities (not valid JSON) as ``None``."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, (float, np.floating)) and not math.isfinite(value):
        return None
    return value


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)
