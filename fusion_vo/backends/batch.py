"""Batch use: a whole recording's measurements in, trajectories and diagnostics out.

::

    result = run_backends(recording, visual, sensors=["camera", "wheel", "imu"], backend="all")
    result.trajectories["gtsam"]        # PoseData of B in W
    result.covariances["ekf"]           # (N, 3, 3)
    result.summary()                    # counts, calibration, notes, timing

``fuse`` does the same from :class:`~fusion_vo.sensors.streams.SensorStreams` already in memory.

Before anything is fused, the streams pass the consistency checks (:mod:`fusion_vo.consistency`): a stated
configuration the data contradict (the IMU's mounting, an encoder's sign, a twist's frame, a clock, the
camera's or the wheels' scale) is corrected or the stream left out, with a sentence in the notes.

Before the streams are merged, each sensor that declares a clock step puts its data on another sensor's
clock (:func:`synchronise_clocks`). The odometry twist's is the one built in: its delay behind the gyro is
estimated from the two yaw rates over the whole recording (:func:`~fusion_vo.sensors.sync.rate_delay`) and,
when it exceeds the twist's sample period (the resolution of a twist held between samples), its timestamps are
moved back by it (``FusionConfig.sync_odometry``, :func:`~fusion_vo.sensors.wheel.synchronise_twist`). Streaming
use applies the same rule causally, to the samples seen so far (:class:`~fusion_vo.sensors.sync.TwistDelay`).
"""

from __future__ import annotations

import logging
import time

import numpy as np

from fusion_vo import backends
from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.ekf import run_ekf
from fusion_vo.backends.pauses import chain, cuts, find_pauses, pause_notes, sample_times, spans_time, split
from fusion_vo.backends.result import FusionResult, Innovations, SensorCount
from fusion_vo.backends.states import calibration_priors
from fusion_vo.backends.timeline import SensorStreams, build_intervals
from fusion_vo.backends.world import align_world
from fusion_vo.consistency.stage import check_streams
from fusion_vo.errors import InputError
from fusion_vo.measurements import PoseData
from fusion_vo.sensors import registry
from fusion_vo.sensors.visual import camera_grid, stated_height_sigma

logger = logging.getLogger(__name__)

BACKENDS = ("ekf", "gtsam")
CHOICES = ("none", "ekf", "gtsam", "all")


def backend_names(backend) -> list[str]:
    """``"none" | "ekf" | "gtsam" | "all"`` (or a list of names) -> the backends to run."""
    names = [backend] if isinstance(backend, str) else list(backend)
    out: list[str] = []
    for name in names:
        if name not in CHOICES:
            raise InputError(f"unknown backend '{name}' (use one of {', '.join(CHOICES)})")
        for b in (BACKENDS if name == "all" else () if name == "none" else (name,)):
            if b not in out:
                out.append(b)
    return out


def as_config(options) -> FusionConfig:
    """A :class:`FusionConfig` from None, a mapping (``from_dict``) or a config."""
    if isinstance(options, FusionConfig):
        return options
    return FusionConfig.from_dict(options or {})


def fuse(streams: SensorStreams, backend="all", config: FusionConfig | dict | None = None) -> FusionResult:
    """Run the requested backends on measurements in memory.

    Parameters
    ----------
    streams : SensorStreams
        Only the sensors to use (see :meth:`SensorStreams.select`).
    backend : str or list of str
        ``"ekf"``, ``"gtsam"``, ``"all"`` or ``"none"`` (dead reckoning only).
    config : FusionConfig or dict, optional

    Returns
    -------
    FusionResult
        ``ekf``, ``ekf_smoothed``, ``gtsam``, ``gtsam_online`` (and ``gtsam_fixed_lag``) trajectories,
        plus ``wheel`` dead reckoning when wheels are used.

    Notes
    -----
    Where no stream has a sample for longer than ``config.max_gap`` (a pause in every stream), the
    streams are cut there, each piece is fused on its own and the pieces are chained
    (:mod:`fusion_vo.backends.pauses`); ``FusionResult.pauses`` and the notes say where and how.
    """
    config = with_recorded_noise(as_config(config), streams)
    names = backend_names(backend)
    checked = check_streams(streams, config)  # inputs that contradict each other, before any backend
    result = _fuse_checked(checked.streams, names, checked.config)
    result.consistency = checked.as_dicts()
    result.notes[:0] = [n for n in checked.notes if n not in result.notes]
    return result


def _fuse_checked(streams: SensorStreams, names: list[str], config: FusionConfig) -> FusionResult:
    """:func:`fuse` of streams that passed the consistency checks."""
    result = FusionResult()
    result.trajectories.update(dead_reckoning(streams, config))
    if not names:
        return result
    streams, offsets = synchronise_clocks(streams, config)
    pauses = find_pauses(streams, config.max_gap)
    # split at the pauses, except where a camera slower than max_gap alone bridges its frame gaps
    cut = cuts(streams, pauses)
    bridged = [{"start": p.start, "end": p.end, "seconds": p.seconds, "joined": "camera"}
               for p in pauses if all(p is not c for c in cut)]
    t_first = float(sample_times(streams)[0]) if pauses else 0.0
    if not cut:
        whole = _fuse_piece(streams, names, config, offsets)
        result.merge(whole)
        result.inconsistent = whole.inconsistent
        result.visual_noise = whole.visual_noise
        result.pauses = bridged
        result.notes[:0] = pause_notes(bridged, t_first)
        for text in result.notes:
            logger.info("%s", text)
        _note_silent_sensors(result)
        return result
    # fuse the pieces between the pauses on their own and chain them
    pieces = split(streams, cut)
    results: list[FusionResult | None] = []
    placed: list[bool] = []  # by the piece's own absolute measurements (GPS fixes)
    origin = config.model_copy(update={"initial_pose": (0.0, 0.0, 0.0)})
    for piece in pieces:
        absolute = any(s.absolute_position and s.available(s.data(piece)) for s in registry.sensors())
        placed.append(absolute)
        if not spans_time(piece):
            results.append(None)
            continue
        first = not any(r is not None for r in results)
        results.append(_fuse_piece(piece, names, config if first or absolute else origin, offsets))
    used = [r for r in results if r is not None]
    if not used:
        raise InputError(f"no two samples of the sensors used are within fusion.max_gap ({config.max_gap:g} s) of "
                         "each other: every one is cut off by a pause, nothing to estimate (raise fusion.max_gap "
                         "for sparse sensors)")
    tracks, covs, joined = chain(results, cut, placed)
    result.trajectories.update(tracks)
    result.covariances.update(covs)
    result.pauses = sorted(bridged + joined, key=lambda entry: entry["start"])
    longest = max(used, key=lambda r: max((len(tr) for tr in r.trajectories.values()), default=0))
    result.calibration.update(longest.calibration)
    result.priors.update(longest.priors)
    result.time_offsets.update(longest.time_offsets)
    result.visual_noise = longest.visual_noise
    for backend_name in {b for r in used for b in r.innovations}:
        result.innovations[backend_name] = Innovations.concatenate([r.innovations[backend_name] for r in used
                                                                    if backend_name in r.innovations])
    for r in used:
        for backend_name, counts in r.counts.items():
            total = result.counts.setdefault(backend_name, {})
            for sensor, count in counts.items():
                acc = total.setdefault(sensor, SensorCount())
                for key, value in count.as_dict().items():
                    setattr(acc, key, getattr(acc, key) + value)
        for key, value in r.timing.items():
            result.timing[key] = result.timing.get(key, 0.0) + value
        result.inconsistent.extend(r.inconsistent)
    result.notes.extend(pause_notes(result.pauses, t_first))
    for r in used:
        result.notes.extend(n for n in r.notes if n not in result.notes)
    if len(used) > 1:
        result.notes.append(f"{len(used)} pieces fused on their own between the pauses; the calibration estimates "
                            "are those of the longest piece")
    for text in result.notes:
        logger.info("%s", text)
    _note_silent_sensors(result)
    return result


def _note_silent_sensors(result: FusionResult) -> None:
    """A note and a warning for each sensor that had measurements but none entered a backend's estimate
    (every reading gated, late or outside the fused span): asked for, it contributed nothing."""
    silent: dict[str, tuple[list[str], SensorCount]] = {}
    for backend_name, counts in result.counts.items():
        for sensor, count in counts.items():
            if sensor != "standstill" and count.used == 0 and count.gated + count.late + count.missing > 0:
                silent.setdefault(sensor, ([], count))[0].append(backend_name)
    for sensor, (names, count) in silent.items():
        why = ", ".join(f"{n} {what}" for what, n in (("gated", count.gated), ("late", count.late),
                                                       ("node intervals missing", count.missing)) if n)
        text = f"{sensor} contributed nothing to the {', '.join(names)} estimate: none of its measurements was used ({why})"
        result.notes.append(text)
        logger.warning("%s", text)


def _fuse_piece(streams: SensorStreams, names: list[str], config: FusionConfig, offsets=()) -> FusionResult:
    """The backends ``names`` over streams without a pause in every stream."""
    result = FusionResult()
    t0 = time.process_time()
    iv = build_intervals(streams, config)
    if any(s.absolute_position and s.data(streams) is not None for s in registry.sensors()):
        align_world(iv, config)  # an absolute sensor (GPS) sets the world frame
    for offset in offsets:  # (the clocks' offsets found over the whole recording, :func:`synchronise_clocks`)
        iv.notes.append(offset.note)
        result.time_offsets[offset.key] = offset.seconds
    result.priors = calibration_priors(iv)
    result.timing["timeline"] = time.process_time() - t0
    result.inconsistent = [ep.as_dict() for ep in iv.episodes]
    noise = camera_grid(iv).noise
    if noise is not None:
        result.visual_noise = noise.as_dict()
    if "ekf" in names:
        # single-threaded BLAS for the filter's small matrices: with OpenBLAS's threads (one per core by
        # default) each 5x5 inverse of the update cost about 2.5 ms of CPU instead of 0.02 ms on a busy
        # 2-core machine (robot_localization's Jackal log: 3.7 s of CPU for the EKF instead of 0.26 s)
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            result.merge(run_ekf(iv, config))
    if "gtsam" in names:
        try:
            result.merge(backends.run_graph(iv, config))  # GTSAM is loaded only when used
        except RuntimeError as exc:
            # GTSAM's IndeterminateSystemException: a variable the configuration leaves unconstrained
            where = " ".join(str(exc).split())
            where = where[where.find("near variable"):].split(".")[0] if "near variable" in where else where[:80]
            raise InputError(f"gtsam: the factor graph cannot be solved ({where}); a configured noise makes a "
                             "variable unobservable -- check the fusion sigmas, or use --backend ekf") from None
    return result


def synchronise_clocks(streams: SensorStreams, config: FusionConfig) -> tuple[SensorStreams, list]:
    """``streams`` with each sensor's data moved onto the clock its :attr:`~fusion_vo.sensors.registry.Sensor.clock`
    step puts it on (the odometry twist's onto the gyro's), in the steps' order, and the
    :class:`~fusion_vo.sensors.registry.ClockOffset` each removed."""
    offsets = []
    for _, step in registry.ordered("clock"):
        streams, offset = step.run(streams, config)
        if offset is not None:
            offsets.append(offset)
    return streams, offsets


def with_recorded_noise(config: FusionConfig, streams: SensorStreams) -> FusionConfig:
    """``config`` with the gyro noise keys of the recording's ``imu0/sensor.yaml`` where given."""
    if streams.imu is None or not streams.imu.noise:
        return config
    return config.model_copy(update={"imu": config.imu.with_sensor_keys(streams.imu.noise)})


def run_backends(recording, visual=None, sensors=None, backend="all", options=None) -> FusionResult:
    """The whole fusion stage of ``fusion-vo run``.

    Parameters
    ----------
    recording : fusion_vo.recording.Recording
        Provides ``wheel()``, ``odom()``, ``imu()``, ``range()``, ``camera`` and ``has_*()``.
    visual : OdometryResult or list of VisualIncrement, optional
        The visual odometry output (its ``increments``); None when the camera is not used.
    sensors : list of str, optional
        Of ``camera, wheel, odom, imu, range, gps``; default: all the recording has except GPS (an
        absolute source is fused only when asked for, so that it can also serve as the reference).
    backend : str
        ``none | ekf | gtsam | all``.
    options : dict or FusionConfig, optional
        Backend options (``FusionConfig.from_dict`` keys).
    """
    config = as_config(options)
    streams = streams_from_recording(recording, visual, sensors, config)
    return fuse(streams, backend, config)


def streams_from_recording(recording, visual=None, sensors=None, config: FusionConfig | None = None) -> SensorStreams:
    """Read the streams of ``sensors`` from ``recording`` (only those) into :class:`SensorStreams`."""
    config = config or FusionConfig()
    increments = getattr(visual, "increments", visual)
    registry.ensure(sensors or ())
    known = registry.sensors()
    # the camera's data is the frontend's output; every other sensor's is read from its folder
    present = {s.name: s.present(recording) for s in known if s.name != "camera"}
    present["camera"] = increments is not None and len(increments) > 0
    if sensors is None:
        sensors = [s.name for s in known if present[s.name] and s.by_default(present)]
    sensors = list(sensors)
    names = [s.name for s in known]
    for s in sensors:
        if s not in names:
            raise InputError(f"unknown sensor '{s}' (use {', '.join(names)})")
    if "camera" in sensors and not present["camera"]:
        raise InputError("sensor 'camera' was asked for but there are no visual increments (no cam0/ frames?)",
                         getattr(recording, "path", None))
    height = config.camera_height
    if height is None and recording.has("cam0"):
        height = float(recording.camera.T_BS[2, 3])
    streams = SensorStreams(
        visual=list(increments) if "camera" in sensors else None,
        camera_height=height,
        camera_height_sigma=_height_sigma(recording) if "camera" in sensors else None,
        range_in_visual=bool(getattr(visual, "range_scaled", False)),
    )
    if streams.visual is not None and streams.range_in_visual:
        streams.range_height_sigma = _range_height_sigma(visual)
    for s in known:
        if s.name == "camera" or s.read is None or not s.is_wanted(sensors, present):
            continue
        streams[s.name] = s.read(recording)
    return streams.select(sensors)


def dead_reckoning(streams: SensorStreams, config: FusionConfig | None = None) -> dict[str, PoseData]:
    """The tracks single sensors' data give alone (:attr:`~fusion_vo.sensors.registry.Sensor.dead_reckoning`: the
    wheels' ``wheel.tum``, at the encoder or twist rate), by track name."""
    config = config or FusionConfig()
    tracks: dict[str, PoseData] = {}
    for sensor in registry.sensors():
        if sensor.dead_reckoning is None:
            continue
        name, make = sensor.dead_reckoning
        data = sensor.data(streams)
        if name not in tracks and sensor.available(data):
            tracks[name] = make(data, config)
    return tracks


def wheel_dead_reckoning(streams: SensorStreams, config: FusionConfig | None = None) -> PoseData | None:
    """The wheel-only track (``wheel.tum``) of :func:`dead_reckoning`, or None without wheels or a twist."""
    return dead_reckoning(streams, config).get("wheel")


def _range_height_sigma(visual) -> float | None:
    """The median standard deviation [m] of the camera heights visual odometry scaled its frames with
    (``OdometryResult.frame_height_sigma``), or None when it does not state them."""
    sigma = getattr(visual, "frame_height_sigma", None)
    if sigma is None:
        return None
    sigma = np.asarray(sigma, dtype=np.float64)
    sigma = sigma[np.isfinite(sigma) & (sigma > 0)]
    return float(np.median(sigma)) if len(sigma) else None


def _height_sigma(recording) -> float | None:
    """``height_sigma`` of the recording's ``cam0/sensor.yaml`` (None when absent or not a folder recording)."""
    if not hasattr(recording, "sensor_file") or not recording.has("cam0"):
        return None
    return stated_height_sigma(recording)
