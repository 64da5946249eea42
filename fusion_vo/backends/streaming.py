"""Streaming use: add measurements as they arrive, read the current estimate.

::

    fusion = StreamingFusion(backend="ekf", sensors=["camera", "wheel", "imu"], wheel_config=cfg,
                             camera_height=0.095)
    for msg in messages:                       # any order within the reorder window
        fusion.add("wheel", WheelTicks(t, left, right))   # any registered sensor's sample (add_wheel ... too)
        estimate = fusion.current_estimate()   # Estimate(t, pose (x, y, yaw), covariance 3x3)
    result = fusion.finish()                   # FusionResult with the online trajectory

Samples are kept in per-stream buffers sorted by time. A node is processed once the newest time seen
has passed it by ``reorder_window`` seconds, so measurements that arrive out of order within the window
are applied in time order (counted as ``reordered``). A measurement older than the last processed node
can no longer be applied: it is counted as ``late`` and logged, never silently dropped.

Nodes are the camera frames (each visual increment's ``t1``) when the camera is used, plus fill-in
nodes at ``step_hz`` when no frame comes; without a camera they are every ``1/step_hz`` seconds. Each
node interval is integrated exactly as in batch use (:func:`~fusion_vo.backends.timeline.build_intervals`)
and handed to the EKF (``backend="ekf"``) or to iSAM2 (``backend="gtsam"``). A visual increment whose
``t0`` is not the previous node (it spans frames the stream has already passed) cannot be applied
causally and is counted as late.

GPS (``add_gps``, EKF only): every fix time is a node, and the fix updates the pose there through
:class:`~fusion_vo.sensors.gps.GpsModel` (gate, robust weight). Until the robot has moved enough for
:func:`~fusion_vo.sensors.gps.align_to_fixes` to fix the heading of ENU, estimates are in the start frame
(``initial_pose``) and fixes are only collected; at the first alignment the state, its covariance
(plus the alignment's uncertainty) and the poses recorded so far are re-expressed in ENU at the datum,
and every later fix is applied. ``current_estimate`` says which frame it is in (``Estimate.frame``).
The fixes keep their stated sigma (floored by ``fusion.gps.min_sigma``): ``fusion.gps.estimate_sigma``,
the scatter measured by a batch run's world-frame alignment, is not applied here.
The history keeps what each node did to this bookkeeping (the fixes it consumed, the frame, the fixes
kept for the alignment, the re-acquisition timer), so a late sample or fix rewinds the EKF with GPS
as without it, back across the switch to ENU if need be (the start-frame poses are kept for that).
Each fix is counted once, at its node: used, gated (the gate, or a bad value on arrival), missing
(kept for the alignment) or late.

A pose for now
--------------
:meth:`StreamingFusion.current_estimate` returns the processed state *predicted* to the newest
measurement time (or to a requested time at most ``horizon`` seconds ahead of it) with the constant-twist
model, its covariance grown by that model's process noise; the state held back by the reorder window is
never what a controller sees. :meth:`StreamingFusion.processed_estimate` returns the processed node itself.

Late data
---------
Both backends keep the last ``history`` seconds (default 2 s) of the raw samples and of what each
node consumed. A measurement older than the last processed node but within the history is applied:

* the EKF keeps its states too: it rewinds to the node before the measurement and re-filters
  everything after it, so the result is the one the same data would have given in time order;
* iSAM2 rebuilds the node intervals the measurement changes (its own interval and those whose
  interpolation, gating or spike median its neighbours feed) and swaps their factors for the new ones
  in one update (``removeFactorIndices``), when the next node is due; the custom factors are linearised
  at the current estimate, twice. The node times stay those already processed: a camera later than the
  reorder window finds fill-in nodes where its frames would have been, so its increment is re-timed onto
  the nearest two nodes (the wheels' and the gyro's motion over the slivers between each frame and its
  node composed onto it, the covariance grown accordingly); it is counted late only if those nodes are
  not consecutive or already carry an increment. The online poses of the rebuilt nodes become iSAM2's
  estimates after the swap (:meth:`smoothed` gives the whole current estimate).

Measurements older than the history are counted as ``late`` and reported by :meth:`finish`.

Bad input
---------
A measurement with a non-finite time or value, or a time more than ``horizon`` seconds ahead of the
newest one, is counted as ``gated``; no exception reaches the caller for bad data. The first of each
sensor and reason is logged as a warning, then at most one every ``REJECT_LOG_INTERVAL`` seconds with the
count so far, and :meth:`~StreamingFusion.finish` sums them up in a note.
Undeclared sensors and bad construction arguments raise :class:`~fusion_vo.errors.InputError`
(programming errors, not data).

Threads
-------
Every public method takes one re-entrant lock, so inputs may come from several threads (a camera
thread, a serial thread, a timer reading :meth:`current_estimate`): each call is atomic and sees the
effects of every call that returned before it started. Samples of one stream must still be added
by one thread at a time in (roughly) time order, as any stream would be; arrival order across threads
is what the reorder window and the history absorb.

With ``background=True`` (iSAM2) one worker thread owns iSAM2: the caller's thread builds the node's
interval and hands it over; the worker builds the factors, linearises them and updates iSAM2, node after
node and rebuild after rebuild in the order they were handed over, from its own state. The results are
therefore those of the caller-thread run whatever the worker's timing. Until a node's update is done
its pose is the last one predicted at constant twist; each later call takes the finished results in,
and :meth:`finish` and :meth:`smoothed` wait for all of them (so does a call that would retire a node
from the history before its result came: a worker that far behind slows the caller down).

Latency
-------
An ``add_*`` call does at most ``steps_per_call`` units of work (see :meth:`StreamingFusion._process`):
a node's interval, the heading monitor's check, (iSAM2:) its factors, their linearisation, and the
backend's update are separate units, run in the same order as at once, so no call pays for all of them.
The budget grows while the processed state is more than two node steps behind, so it keeps up with
streams that bring fewer calls than units.
"""

from __future__ import annotations

import bisect
import dataclasses
import logging
import math
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from fusion_vo.backends.batch import as_config
from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.ekf import PlanarEkf, interval_measurements, step_blocks
from fusion_vo.sensors.visual import frame_error_cov
from fusion_vo.backends.live_monitor import LiveHeadingMonitor, MonitorState
from fusion_vo.backends.result import FusionResult, SensorCount
from fusion_vo.backends.timeline import SensorStreams, build_intervals, scale_priors
from fusion_vo.sensors import registry
from fusion_vo.sensors.sync import TwistDelay
from fusion_vo.consistency.live import LiveMounting, aligned_offset
from fusion_vo.errors import InputError
from fusion_vo.measurements import (
    GpsData, GpsFix, ImuData, ImuSample, PoseData, RangeData, RangeSample, TwistData, TwistSample, VisualIncrement, WheelConfig,
    WheelData, WheelTicks,
)
from fusion_vo.backends.ekf import YAW
from fusion_vo.backends.world import prior_from_alignment
from fusion_vo.geometry import se2
from fusion_vo.sensors.gps import GpsModel, GpsReacquire, align_to_fixes, ekf_reacquire, ekf_update
from fusion_vo.sensors.wheel import arc_increment, curvature_observable, curvature_states

logger = logging.getLogger(__name__)



@dataclass
class Estimate:
    """The current estimate: time [s], pose ``(x, y, yaw)`` of B in W, its 3x3 covariance.

    ``predicted`` is how far [s] the pose was predicted beyond the last processed node (0 for a
    processed node). ``twist`` is the body twist ``(v_x, v_y, ω)`` at ``t`` with its 3x3 covariance, for the
    newest node and predictions from it (None for an older node): the EKF's twist state (the mean twist of
    the node's interval, its covariance grown by the prediction); iSAM2, which has no twist variable, the
    twist between the last two nodes with the constant-twist model's process noise over that interval
    (``diag(σ_a², σ_lat², σ_α²) Δt``, a lower bound: it leaves out the nodes' own errors).
    """

    t: float
    pose: np.ndarray
    covariance: np.ndarray
    frame: str = "start"
    predicted: float = 0.0
    twist: np.ndarray | None = None
    twist_covariance: np.ndarray | None = None


@dataclass
class _Started:
    """A node whose processing is under way across calls (see ``StreamingFusion._process``)."""

    t0: float
    t1: float
    iv: object  # Intervals
    step: dict  # sensor -> SensorCount of the node's step
    consumed: list  # visual increments taken from the buffer
    monitor: MonitorState  # the heading monitor before the node was added to it
    reach: dict  # stream -> time of the last sample the interval read
    dropped: frozenset | None = None  # the monitor's decisions, once applied to ``iv``
    factors: list | None = None  # iSAM2: [builder, node factors, linearised factors] (background: None)
    stage: int = 0  # iSAM2: 1 once the factors are built, 2 once linearised


@dataclass
class _NodeRecord:
    """What processing one node changed, kept while the node is within the history (EKF rewind)."""

    state: tuple | None  # EKF (x, P) after the node's update
    heading_offset: float | None
    counts: dict = field(default_factory=dict)  # sensor -> SensorCount of this node's step
    visual: list = field(default_factory=list)  # increments this node's step consumed
    monitor: MonitorState | None = None  # the heading monitor after this node
    fixes: list = field(default_factory=list)  # GPS fixes this node's step consumed
    gps: tuple | None = None  # GPS bookkeeping after this node (_gps_state)
    dropped: frozenset = frozenset()  # heading components the monitor dropped in this node's interval


class StreamingFusion:
    """Incremental fusion for embedding in a larger localization stack.

    Parameters
    ----------
    backend : str
        ``"ekf"`` or ``"gtsam"`` (iSAM2).
    config : FusionConfig or dict, optional
    sensors : list of str
        The sensors that will be added: registered sensor names (:mod:`fusion_vo.sensors.registry`; built in:
        ``camera, wheel, odom, imu, range, gps``).
    wheel_config : WheelConfig, optional
        Needed for ``add_wheel``.
    imu_T_BS : ndarray (4, 4), optional
        IMU pose in the body frame (default identity).
    imu_noise : dict, optional
        EuRoC noise keys of ``imu0/sensor.yaml``.
    camera_height : float, optional
        Height the visual increments assume (needed for ``range``).
    camera_height_sigma : float, optional
        Its standard deviation [m] (``height_sigma`` of ``cam0/sensor.yaml``): the visual scale's prior,
        as in a batch run (:func:`~fusion_vo.backends.timeline.scale_priors`; default
        ``config.visual_scale_sigma``, at least one range reading's ``config.range.sigma / camera_height`` when
        ``range`` is fused).
    range_height_sigma : float, optional
        Given when the visual increments were already scaled with the range finder's heights (an
        offline visual odometry run's ``frame_height_sigma``, typical value): it bounds that prior as in a
        batch run, and the range finder is then not used again (its samples are ignored, with a note).
    camera_frame_errors : bool, optional
        The visual increments state their frames' own errors
        (:attr:`~fusion_vo.measurements.VisualIncrement.frame_covariance`, from a camera noise calibration,
        :mod:`fusion_vo.calibration.camera_noise`): the EKF then carries them in its state as a batch run does
        (default False: it fuses each increment with its whole covariance; iSAM2 models them either way).
    gps_lever_arm : array_like, optional
        Antenna position in the body frame [m] (``gps0/sensor.yaml`` ``T_BS``), for ``add_gps``
        (default: at the body origin).
    history : float
        Seconds of samples (and EKF states) kept to re-apply late measurements (default 2).
    horizon : float
        Largest prediction [s] :meth:`current_estimate` makes beyond the newest measurement, and how far
        ahead of the newest measurement a new one may be before it is rejected (default 1).
    steps_per_call : int or None
        Most units of work one ``add_*`` call does (default 1): a node is two units (its interval from
        the buffers; the backend's update), three when the heading monitor's check is due at it. The
        rest is caught up by the next calls, which bounds the latency of a call when a late measurement
        makes the EKF re-filter several nodes. While the processed state is more than two node steps
        behind what is due, the budget grows with the backlog, so samples that come in fewer calls than
        there are units never leave it further and further behind. None processes everything due at
        once. :meth:`finish` always processes everything.
    background : bool
        iSAM2 only: run its updates (and the linearisation, relinearisation and marginal covariance that
        come with them) on a worker thread, off the caller's; GTSAM releases the GIL while it works. A node's
        recorded pose is its initial guess (the last estimate composed with the interval's odometry) until
        its update has finished; results are taken in by the next call.

    Notes
    -----
    A call's worst latency in a live process is often not this class's work but one of CPython's full
    garbage collections, which scan every object the process tracks (about 100 000 once numpy, scipy,
    GTSAM and filterpy are imported: some 40 ms). Call :func:`gc.freeze` once start-up is done, as
    the ROS 2 node (``fusion-vo ros2``, :mod:`fusion_vo.ros2.run`) does; ``benchmarks/bench_latency.py --gc-freeze`` measures the difference.
    The class changes no global state itself.
    """

    def __init__(self, backend: str = "ekf", config: FusionConfig | dict | None = None,
                 sensors=("camera", "wheel", "imu"), wheel_config: WheelConfig | None = None,
                 imu_T_BS: np.ndarray | None = None, imu_noise: dict | None = None, camera_height: float | None = None,
                 camera_height_sigma: float | None = None, range_height_sigma: float | None = None,
                 camera_frame_errors: bool = False, gps_lever_arm=None, history: float = 2.0, horizon: float = 1.0,
                 steps_per_call: int | None = 1, background: bool = False):
        if backend not in ("ekf", "gtsam"):
            raise InputError(f"streaming backend must be 'ekf' or 'gtsam', not '{backend}'")
        if not (np.isfinite(history) and history >= 0 and np.isfinite(horizon) and horizon > 0):
            raise InputError(f"history must be >= 0 and horizon > 0 seconds (got history={history}, horizon={horizon})")
        self.history = float(history)
        self.horizon = float(horizon)
        if steps_per_call is not None and (not isinstance(steps_per_call, int) or steps_per_call < 1):
            raise InputError(f"steps_per_call must be a positive integer or None, not {steps_per_call!r}")
        self.steps_per_call = steps_per_call
        if background and backend != "gtsam":
            raise InputError("background updates are for backend 'gtsam' (the EKF's steps are cheap)")
        self.background = bool(background)
        if backend == "gtsam":  # import GTSAM now (about 0.1 s), not inside the first add() call that makes a node
            import gtsam  # noqa: F401

            from fusion_vo.backends import graph  # noqa: F401
        self._lock = threading.RLock()
        self.config = as_config(config)
        if imu_noise:
            self.config = dataclasses.replace(self.config, imu=self.config.imu.with_sensor_keys(imu_noise))
        if self.config.imu.gyro_rest_noise_density > 0:
            logger.warning("imu.gyro_rest_noise_density is not used by streaming fusion: the gyro keeps its "
                           "noise density at rest too")
        self.backend = backend
        self.sensors = list(sensors)
        bad = [s for s in self.sensors if s not in registry.names()]
        if bad:
            raise InputError(f"unknown sensor '{bad[0]}' (use {', '.join(registry.names())})")
        if "wheel" in self.sensors and wheel_config is None:
            raise InputError("the wheel sensor needs its wheel_config (ticks per revolution, radii, wheel base)")
        if "gps" in self.sensors and backend != "ekf":
            raise InputError("streaming GPS fusion needs backend 'ekf' (batch runs fuse GPS in both backends)")
        if "range" in self.sensors and camera_height is None:
            raise InputError("the range sensor needs the camera_height the visual increments assume")
        self.wheel_config = wheel_config
        self.imu_T_BS = np.eye(4) if imu_T_BS is None else np.asarray(imu_T_BS, dtype=np.float64)
        self.imu_noise = dict(imu_noise or {})
        self.camera_height = camera_height
        #: the two scales' priors, as a batch run of the same streams takes them
        self._priors = scale_priors(self.config, camera_height, camera_height_sigma, range_height_sigma, wheel_config,
                                    range_fused="range" in self.sensors and range_height_sigma is None)
        self._camera_frame_errors = bool(camera_frame_errors)
        self._range_in_visual = range_height_sigma is not None
        self._input_counts: dict[str, SensorCount] = {}
        self._rejected: dict[tuple[str, str], list] = {}  # (sensor, reason) -> [count, wall time last logged]
        self._records: list[_NodeRecord | None] = []
        self._step_counts: dict[str, SensorCount] = {}  # counts of the node being processed
        self._retired_counts: dict[str, SensorCount] = {}  # counts of nodes older than the history
        self.rewinds = 0
        self._monitor = LiveHeadingMonitor(self.config)
        self._dirty: set[int] = set()  # iSAM2: nodes whose intervals late data changed
        # every sensor with a live intake (registry.Live), the built-in ones always (odometry twists also arrive
        # for a declared "wheel"), the others when declared: its registration and the name it is counted under
        self._intake = {s.name: s for s in registry.sensors() if s.live is not None and
                        (s.name in registry.BUILTIN_ORDER or s.name in self.sensors)}
        self._counted = {name: s.live.counted_as or name for name, s in self._intake.items()}
        # per-stream buffers of (t, payload) of those whose samples are interpolated at the nodes (no Live.take)
        self._buffers: dict[str, list] = {name: [] for name, s in self._intake.items() if s.live.take is None}
        #: the sensors' own state variables (registry.State) in both backends
        self._states = registry.states(self.sensors, self.config)
        if wheel_config is not None:  # the wheels' curvature bias and its prior, as in a batch run

            # whether the IMU brings an AHRS heading is known only from its samples: a stream decides from the
            # camera and GPS declared (a batch run of wheels and an AHRS alone estimates the curvature)
            observable = curvature_observable(camera="camera" in self.sensors, ahrs=False, gps="gps" in self.sensors)
            self._states = curvature_states(self._states, self.config,
                                            wheel_config.relative_radius_sigma(self.config.wheel_scale_sigma),
                                            wheel_config.wheel_base, observable)
        self._visual: list[VisualIncrement] = []
        self._latest = -np.inf
        self._t_nodes: list[float] = []
        self._poses: list[np.ndarray] = []
        self._covs: list[np.ndarray] = []
        self._heading_offset: float | None = None
        self._notes: list[str] = list(self._priors.notes)
        if self._range_in_visual and "range" in self.sensors:
            self._notes.append("range finder: already in the visual increments (their per-frame height), "
                               "not used again as a height measurement")
        self._ekf: PlanarEkf | None = None
        self._graph = None

        lever = np.zeros(3) if gps_lever_arm is None else np.asarray(gps_lever_arm, dtype=np.float64).ravel()
        self._gps_model = GpsModel(lever, self.config.gps)
        self._gps_lever = lever
        self._gps: list[GpsFix] = []  # pending fixes, in time order
        self._gps_seen: list[GpsFix] = []  # fixes before the world frame was aligned
        self._frame = "start"
        self._gps_reacquire = None
        self._step_fixes: list[GpsFix] = []  # fixes the node being processed consumed
        self._pending: _Started | None = None  # a node started but not yet applied (_begin_step)
        self._start_frame: tuple | None = None  # (node, poses, covariances, note) before the switch to ENU
        # an odometry twist's delay behind the gyro, estimated from the samples so far (as in batch use)
        self._twist_delay = (TwistDelay(self.config.max_odom_delay, self.config.imu)
                             if self.config.sync_odometry and "imu" in self.sensors else None)
        # the IMU's stated mounting checked against the data seen so far (fusion_vo.consistency.live)
        self._mounting = (LiveMounting(self.imu_T_BS, self.config, wheel_config)
                          if "imu" in self.sensors and self.config.consistency.check else None)
        self._imu_refused = False
        self._consistency: list[dict] = []

    # ------------------------------------------------------------------ input
    def add(self, sensor: str, sample) -> None:
        """Add one sample of the registered sensor ``sensor`` (:mod:`fusion_vo.sensors.registry`).

        The sample is what that sensor's :class:`~fusion_vo.sensors.registry.Live` intake takes (``camera``:
        :class:`~fusion_vo.measurements.VisualIncrement`, ``wheel``: :class:`~fusion_vo.measurements.WheelTicks`,
        ``odom``: ``TwistSample``, ``imu``: ``ImuSample``, ``range``: ``RangeSample``, ``gps``: ``GpsFix``). Every
        sample is read by its intake and checked (declared, finite, within the horizon) here; one that cannot be
        read is counted as gated, like a non-finite one; an unknown or undeclared sensor is an
        :class:`InputError`. A sensor whose samples make nodes (camera, GPS) then hands it on (``Live.take``);
        the others' samples are buffered and interpolated at the nodes.
        """
        with self._lock:
            spec = self._intake.get(sensor)
            if spec is None:  # an undeclared sensor, one without a live intake, or a mistake
                try:
                    registry.get(sensor)
                except KeyError:
                    raise InputError(f"unknown sensor '{sensor}' (use {', '.join(registry.names())})") from None
                self._check(sensor)
                raise InputError(f"sensor '{sensor}' has no live intake (its registration has no registry.Live)")
            live = spec.live
            if live.take is not None:
                self._check(sensor)
            try:
                t, payload = live.sample(sample)
                values = None if live.take is None else _values(payload) if live.values is None else live.values(payload)
            except (AttributeError, TypeError, ValueError, IndexError) as exc:
                self._check(sensor)
                self._reject(self._counted[sensor], "a sample that cannot be read", f"{sample!r:.80}: {exc}")
                return
            if self._mounting is not None:
                self._check_mounting(sensor, t, payload)
            if sensor == "imu" and self._imu_refused:
                self._count("gyro").gated += 1  # the IMU contradicted its mounting: left out
                return
            if live.take is None:
                self._add(sensor, self._synchronised(sensor, t, payload), payload)
            elif self._valid(self._counted[sensor], t, values):
                live.take(self, payload)

    def _check_mounting(self, sensor: str, t, payload) -> None:
        """Feed the live IMU mounting check (:class:`~fusion_vo.consistency.live.LiveMounting`); when it decides,
        read the IMU with the mounting it found (the samples buffered, and the gyro rates the twist's delay
        estimate holds, too) or leave it out."""
        decided = self._mounting.observe(sensor, t, payload)
        if decided is None:
            return
        finding, T, final = decided
        self._consistency.append(finding.as_dict())
        if finding.sentence:
            self._notes.append(f"live check from t={float(t):.2f}: {finding.sentence}")
        if T is None:
            self._imu_refused = True
        elif finding.decision == "corrected":
            self._drop_pending()  # a node started with the old mounting is started again with the new one
            self.imu_T_BS = T
            # the heading monitor starts again: its windows hold the gyro's and the AHRS's readings about the
            # old axes (the spans it dropped so far stay in the notes, closed here)
            episodes = self._monitor.all_episodes(self._t_nodes[-1] if self._t_nodes else float(t))
            self._monitor = LiveHeadingMonitor(self.config)
            self._monitor.episodes = episodes
            if self._twist_delay is not None:
                self._twist_delay.replace_gyro(*self._mounting.body_rates(T))
            self._reanchor_ahrs()
            if self._ekf is not None:  # the bias the readings about the wrong axis taught the filter, replaced
                bias, sigma = self._mounting.gyro_bias or (0.0, self.config.imu.gyro_bias_sigma)
                self._ekf.reset_state("gyro_bias", bias, max(sigma, self.config.monitor_bias_sigma))
        if final:
            self._mounting = None

    def _reanchor_ahrs(self) -> None:
        """After the IMU's mounting changed, its AHRS heading (read through the new ``T_BS``) aligned again as if
        from the start: its first orientation gives the initial heading (the headings estimated since may carry
        what the old mounting did to them; the AHRS, absolute, takes it out)."""
        first = self._mounting.first_orientation
        if self._heading_offset is None or first is None:
            return
        offset = aligned_offset(self.imu_T_BS, first, float(self.config.initial_pose[2]))
        if offset is not None:
            self._heading_offset = offset

    def _synchronised(self, stream: str, t, payload):
        """``t`` of an odometry twist moved back by its delay behind the gyro estimated so far
        (:class:`~fusion_vo.sensors.sync.TwistDelay`, the rule of batch use); a gyro sample feeds that
        estimate. Nodes are processed that much later (``_advance``), so the corrected twists are not late.
        Other streams, and values that cannot be read (counted as gated by ``_add``), pass unchanged."""
        tracker = self._twist_delay
        if tracker is None or stream not in ("odom", "imu"):
            return t
        try:
            t_f = float(t)
            if stream == "imu":
                rate = float(self.imu_T_BS[2, :3] @ np.asarray(payload[0], dtype=np.float64).reshape(3))
                if np.isfinite(rate) and np.isfinite(t_f):
                    tracker.gyro(t_f, rate)
                return t
            wz = float(payload[2])
        except (TypeError, ValueError, IndexError):
            return t
        if not (np.isfinite(t_f) and np.isfinite(wz)):
            return t
        before = tracker.delay
        t_f = tracker.twist(t_f, wz)
        if tracker.delay != before:
            self._shift_twists(before - tracker.delay)
        return t_f

    def add_visual(self, inc: VisualIncrement) -> None:
        """Add one frame-to-frame increment (applied at its ``t1``; ``t0`` must be the previous frame;
        ``add("camera", inc)``)."""
        self.add("camera", inc)

    def take_increment(self, inc: VisualIncrement) -> None:
        """The camera's intake (``Live.take``), after the checks of :meth:`add`: the increment makes its node."""
        self._touch("visual", inc.t1)
        if self._late("camera", inc.t0 if inc.ok else inc.t1, back=0):
            return
        if not inc.ok:
            self._count("camera").missing += 1
            self._advance(inc.t1)
            return
        if self.backend == "gtsam" and self._t_nodes and inc.t0 < self._t_nodes[-1] - 1e-9:
            attached = self._on_nodes(inc)
            if attached is None:
                self._count("camera").late += 1
                logger.warning("camera increment ending at t=%.3f could not be attached to the nodes; "
                               "not applied", inc.t1)
                return
            inc = attached
        self._insert_visual(inc)
        self._mark(inc.t1, inc.t1)  # consumed by the first node at or after its t1
        self._advance(inc.t1)

    def add_wheel(self, m: WheelTicks) -> None:
        """Add one sample of cumulative wheel ticks (``add("wheel", m)``)."""
        self.add("wheel", m)

    def add_twist(self, m: TwistSample) -> None:
        """Add one wheel-odometry twist ``(vx, vy, wz)`` in the body frame (``add("odom", m)``)."""
        self.add("odom", m)

    def add_imu(self, m: ImuSample) -> None:
        """Add one IMU sample: gyro, accel and optionally an orientation quaternion (``add("imu", m)``)."""
        self.add("imu", m)

    def add_range(self, m: RangeSample) -> None:
        """Add one range-finder distance to the ground (``add("range", m)``)."""
        self.add("range", m)

    def add_gps(self, fix: GpsFix) -> None:
        """One fix (east, north in ENU at the datum, 2x2 covariance); a non-finite or non-positive-definite
        one is counted as gated (``add("gps", fix)``)."""
        self.add("gps", fix)

    def take_fix(self, fix: GpsFix) -> None:
        """GPS's intake (``Live.take``), after the checks of :meth:`add`: the fix waits for its node."""
        self._touch("gps", fix.t)
        if self._late("gps", fix.t):
            return
        enu = np.asarray(fix.enu, dtype=np.float64).ravel()[:2]
        cov = np.asarray(fix.covariance, dtype=np.float64).reshape(2, 2)
        if np.any(np.linalg.eigvalsh(0.5 * (cov + cov.T)) <= 0):
            self._count("gps").gated += 1
            return
        if self._gps and fix.t < self._gps[-1].t:
            self._count("gps").reordered += 1
        bisect.insort(self._gps, GpsFix(float(fix.t), enu, cov), key=lambda f: f.t)
        self._advance(fix.t)

    # ------------------------------------------------------------------ output
    def current_estimate(self, t: float | None = None) -> Estimate | None:
        """The pose for now: the processed state predicted to ``t`` (default: the newest measurement time).

        The covariance is grown by the prediction. ``t`` may be at most ``horizon`` seconds beyond the
        newest measurement (:class:`~fusion_vo.errors.InputError` otherwise); a ``t`` at or before the
        last processed node returns the processed node at or before it (within the history). None
        before the first node.
        """
        with self._lock:
            self._collect()
            if not self._t_nodes:
                return None
            target = self._latest if t is None else float(t)
            if not np.isfinite(target) or target > self._latest + self.horizon:
                raise InputError(f"current_estimate: t={t} is more than horizon={self.horizon} s beyond the "
                                 f"newest measurement (t={self._latest:.3f})")
            t_node = self._t_nodes[-1]
            if target <= t_node + 1e-9:
                i = max(bisect.bisect_right(self._t_nodes, target + 1e-9) - 1, 0)
                twist = self._twist(0.0) if i == len(self._t_nodes) - 1 else (None, None)
                return Estimate(self._t_nodes[i], self._poses[i].copy(), self._covs[i].copy(), self._frame, 0.0,
                                *twist)
            pose, cov = self._predict(target - t_node)
            return Estimate(target, pose, cov, self._frame, target - t_node, *self._twist(target - t_node))

    def processed_estimate(self) -> Estimate | None:
        """The last processed node (held back by the reorder window), or None before the first node."""
        with self._lock:
            self._collect()
            if not self._t_nodes:
                return None
            return Estimate(self._t_nodes[-1], self._poses[-1].copy(), self._covs[-1].copy(), self._frame, 0.0,
                            *self._twist(0.0))

    def smoothed_estimate(self, t: float) -> Estimate | None:
        """iSAM2 only: its current estimate, given all data so far, of the last node at or before ``t`` (pose
        and marginal covariance; a fixed-lag view of the smoother without computing every node as
        :meth:`smoothed` does). None for the EKF, before the first node, or for a ``t`` before it."""
        with self._lock:
            if self._graph is None or not self._t_nodes:
                return None
            self._collect(wait=True)
            i = min(bisect.bisect_right(self._t_nodes, float(t) + 1e-9) - 1, self._graph.last)
            if i < 0:
                return None
            pose, cov = self._graph._pose_cov(i)
            return Estimate(self._t_nodes[i], pose, cov, self._frame)

    def smoothed(self) -> PoseData | None:
        """iSAM2 only: its current estimate of every node so far (each pose given all data up to now),
        beside the online track (each pose as it was when its node was the newest). None for the EKF."""
        with self._lock:
            if self._graph is None:
                return None
            self._collect(wait=True)
            return PoseData(np.array(self._t_nodes[:self._graph.n + 1]), self._graph.poses())

    def inconsistent(self) -> list[dict]:
        """The heading-consistency monitor's spans so far (``finish().inconsistent`` of now: a span still open
        ends at the last processed node)."""
        with self._lock:
            if not self._t_nodes:
                return []
            return [ep.as_dict() for ep in self._monitor.all_episodes(self._t_nodes[-1])]

    @property
    def counts(self) -> dict[str, SensorCount]:
        """Sensor name -> :class:`SensorCount` of everything added so far."""
        with self._lock:
            total: dict[str, SensorCount] = {}
            parts = [self._input_counts, self._retired_counts] + [r.counts for r in self._records if r is not None]
            for part in parts:
                _merge_into(total, part)
            return total

    def finish(self) -> FusionResult:
        """Process everything buffered and return the online trajectory (``ekf`` or ``gtsam_online``)."""
        with self._lock:
            return self._finish()

    def _finish(self) -> FusionResult:
        self._process(np.inf)
        self._collect(wait=True)
        name = "ekf" if self.backend == "ekf" else "gtsam_online"
        result = FusionResult()
        if self._t_nodes:
            result.trajectories[name] = PoseData(np.array(self._t_nodes), np.array(self._poses))
            result.covariances[name] = np.array(self._covs)
        counts = self.counts
        result.counts[name] = counts
        result.notes = list(self._notes)
        result.consistency = list(self._consistency)
        if "gps" in self.sensors:
            gps = counts.get("gps", SensorCount())
            result.notes.append(f"ekf: gps {gps.used} fixes used, {gps.gated} rejected (gate or bad values); "
                                "world frame: " + ("ENU at the datum" if self._frame == "enu" else
                                                   "the start frame (the fixes never fixed the heading of ENU)"))
        if self._t_nodes:
            episodes = self._monitor.all_episodes(self._t_nodes[-1])
            result.inconsistent = [ep.as_dict() for ep in episodes]
            result.notes.extend("live monitor: " + ep.note(self._t_nodes[0]) for ep in episodes)
        if self._twist_delay is not None and self._twist_delay.history:
            t_first = self._t_nodes[0] if self._t_nodes else 0.0
            (t, d), *later = self._twist_delay.history
            text = f"odometry twist {d * 1e3:.0f} ms behind the gyro: its timestamps corrected from t={t:.2f} " \
                   f"({t - t_first:.1f} s in)"
            if later:
                ms = [x[1] * 1e3 for x in later]
                text += f", re-estimated {len(ms)} times ({min(ms):.0f}-{max(ms):.0f} ms, last {ms[-1]:.0f} ms)"
            result.notes.append(text)
        if self.config.visual_noise.estimate and "camera" in self.sensors:
            result.notes.append("camera heading noise not estimated in streaming use (fusion.visual_noise.estimate is "
                                "for batch runs): the stated noise and visual_frame_error were used")
        if self._rejected:
            result.notes.append("samples rejected (counted as gated): " + ", ".join(
                f"{sensor} {n} ({reason})" for (sensor, reason), (n, _) in self._rejected.items()))
        late = {s: c.late for s, c in counts.items() if c.late}
        if late:
            result.notes.append("late measurements not applied: " + ", ".join(f"{s} {n}" for s, n in late.items()))
        if self.rewinds:
            how = "rewinding the filter" if self.backend == "ekf" else "swapping iSAM2 factors"
            result.notes.append(f"late measurements re-applied by {how} {self.rewinds} times")
        return result

    # ------------------------------------------------------------------ buffering
    def _check(self, sensor: str) -> None:
        if sensor not in self.sensors and not (sensor == "odom" and "wheel" in self.sensors):
            raise InputError(f"sensor '{sensor}' was not declared (sensors={self.sensors})")

    def _count(self, sensor: str) -> SensorCount:
        return self._input_counts.setdefault(sensor, SensorCount())

    def _valid(self, sensor: str, t, values) -> bool:
        """Non-finite values and times beyond the horizon are counted as gated, never raised."""
        try:
            t = float(t)
            parts = values if isinstance(values, (list, tuple)) else [values]
            flat = [np.ravel(np.asarray(v, dtype=np.float64)) for v in parts]
            finite = np.isfinite(t) and all(bool(np.all(np.isfinite(v))) for v in flat)
        except (TypeError, ValueError):
            finite = False
        if not finite:
            self._reject(sensor, "a non-finite or malformed value", f"t={t}")
            return False
        if np.isfinite(self._latest) and t > self._latest + self.horizon:
            self._reject(sensor, f"more than {self.horizon:g} s ahead of the newest sample",
                         f"t={t:.3f}, newest t={self._latest:.3f}")
            return False
        return True

    #: wall-clock seconds between two warnings about samples of one sensor rejected for one reason
    REJECT_LOG_INTERVAL = 10.0

    def _reject(self, sensor: str, reason: str, detail: str) -> None:
        """Count a rejected sample as gated and by its reason (summed up in :meth:`finish`'s notes); a warning
        for the first of each sensor and reason, then at most one every :attr:`REJECT_LOG_INTERVAL` s with the
        count so far (a stream of NaN gave one warning per sample)."""
        self._count(sensor).gated += 1
        entry = self._rejected.setdefault((sensor, reason), [0, -math.inf])
        entry[0] += 1
        now = time.monotonic()
        if now - entry[1] >= self.REJECT_LOG_INTERVAL:
            entry[1] = now
            logger.warning("%s sample rejected: %s (%s); %d so far, counted as gated", sensor, reason, detail, entry[0])
        else:
            logger.debug("%s sample rejected: %s (%s)", sensor, reason, detail)

    def _late(self, sensor: str, t: float, back: int = 2) -> bool:
        """True if ``t`` is before the last node and cannot be re-applied; rewinds the EKF if it can."""
        if not self._t_nodes or t >= self._t_nodes[-1] - 1e-9:
            return False
        i = self._rewind_index(t, back)
        if i is None:
            self._count(sensor).late += 1
            logger.warning("%s measurement at t=%.3f arrived after t=%.3f was processed (beyond the %.3g s "
                           "history); not applied", sensor, t, self._t_nodes[-1], self.history)
            return True
        if self.backend == "ekf":
            self._rewind(i)
        return False  # iSAM2: the intervals the sample changes are marked once it is buffered (_mark)

    def _mark(self, t_lo: float, t_hi: float) -> None:
        """iSAM2: mark the processed node intervals overlapping ``[t_lo, t_hi]`` for rebuilding."""
        if self.backend == "ekf" or not self._t_nodes or t_lo >= self._t_nodes[-1]:
            return
        first = max(bisect.bisect_left(self._t_nodes, t_lo - 1e-9), 1)
        last = min(bisect.bisect_left(self._t_nodes, t_hi - 1e-9), len(self._t_nodes) - 1)
        self._dirty.update(range(first, last + 1))

    def _add(self, stream: str, t: float, payload) -> None:
        self._check(stream)
        sensor = self._counted[stream]  # the name its counts are reported under
        if not self._valid(sensor, t, _values(payload)):
            return
        t = float(t)
        self._touch(stream, t)
        if self._late(sensor, t):
            return
        buf = self._buffers[stream]
        if buf and t < buf[-1][0]:
            self._count(sensor).reordered += 1
        k = bisect.bisect_right(buf, t, key=lambda item: item[0])
        buf.insert(k, (t, payload))
        if self._t_nodes and t < self._t_nodes[-1]:
            # a late sample changes the interpolation, gating and spike medians of its neighbours' intervals only
            self._mark(buf[max(k - 3, 0)][0], max(buf[min(k + 3, len(buf) - 1)][0], t))
        self._advance(t)

    def _on_nodes(self, inc: VisualIncrement) -> VisualIncrement | None:
        """iSAM2: a late increment moved onto the processed nodes nearest its frames (None: it cannot be).

        iSAM2's nodes stay where they were processed (fill-in nodes when the camera was late), so the
        increment is re-timed: the wheels' (and gyro's) motion over the slivers between each frame and its
        nearest node is composed onto it, ``B(n_a)->B(t0)  (+)  delta  (+)  B(t1)->B(n_b)``, and its covariance
        grows by 2 % of each sliver's motion (plus 0.1 mm / 0.1 mrad). Both nodes must be consecutive and
        within the history, the slivers shorter than a node step, and no other increment on that interval.
        """
        T = self._t_nodes
        a = min(range(max(bisect.bisect_left(T, inc.t0) - 1, 0), min(bisect.bisect_left(T, inc.t0) + 1, len(T))),
                key=lambda k: abs(T[k] - inc.t0))
        if inc.t1 > T[-1] + 1e-9:
            b, t_b = None, inc.t1  # ends after the last node: the next node is its frame, only t0 moves
            if a != len(T) - 1:
                return None
        else:
            k = bisect.bisect_left(T, inc.t1)
            b = min(range(max(k - 1, 0), min(k + 1, len(T))), key=lambda j: abs(T[j] - inc.t1))
            t_b = T[b]
            if b != a + 1:
                return None
        if abs(T[a] - inc.t0) < 1e-9 and abs(t_b - inc.t1) < 1e-9:
            return inc
        step = 1.0 / self.config.step_hz
        if max(abs(T[a] - inc.t0), abs(t_b - inc.t1)) > step or self._records[a] is None:
            return None
        if b is not None and (self._records[b] is None or any(abs(v.t0 - T[a]) < 1e-9 for v in self._records[b].visual)
                              or any(abs(v.t1 - t_b) < 1e-9 for v in self._visual)):
            return None
        head = self._sliver(T[a], inc.t0)
        tail = self._sliver(inc.t1, t_b)
        if head is None or tail is None:
            return None

        delta = se2.compose(se2.compose(head[0], np.asarray(inc.delta, dtype=np.float64)), tail[0])
        cov = np.asarray(inc.covariance, dtype=np.float64) + np.diag(head[1] + tail[1])
        return dataclasses.replace(inc, t0=float(T[a]), t1=float(t_b), delta=delta, covariance=cov)

    def _sliver(self, x: float, y: float):
        """Body motion from ``x`` to ``y`` (either order) from the buffered wheels and gyro, and its variance
        (2 % of the motion, plus 0.1 mm / 0.1 mrad); None without wheel data there."""

        lo, hi = min(x, y), max(x, y)
        if hi - lo < 1e-9:
            return np.zeros(3), np.zeros(3)
        iv = build_intervals(self._streams_between(lo, hi, self._heading_offset), self.config, np.array([lo, hi]),
                             self._heading_offset)
        if not iv.uses("wheel") or not iv.wheel_ok[0]:
            return None
        inc = arc_increment(iv.wheel_dl, iv.wheel_dr, iv.wheel_base)[0]
        if iv.uses("gyro") and iv.gyro_ok[0]:
            inc[2] = iv.gyro_angle[0]
        var = (0.02 * np.abs(inc)) ** 2 + np.array([1e-4, 1e-4, 1e-4]) ** 2
        return (inc if y >= x else se2.inverse(inc)), var

    def _insert_visual(self, inc: VisualIncrement) -> None:
        if self._visual and inc.t1 < self._visual[-1].t1:
            self._count("camera").reordered += 1
        bisect.insort(self._visual, inc, key=lambda v: v.t1)

    def _advance(self, t: float) -> None:
        self._collect()
        self._latest = max(self._latest, float(t))
        lag = self._twist_delay.lag() if self._twist_delay is not None else 0.0
        until = self._latest - self.config.reorder_window - lag
        self._process(until, self._budget(until))

    def _budget(self, until: float) -> int | None:
        """Units of work for this call: ``steps_per_call``, more while the processed state is behind.

        When the samples come in fewer calls than there are units to do (a 10 Hz odometry and a 30 Hz
        IMU, 40 calls a second, against nodes at 20 Hz of two or three units each), a fixed budget falls
        further behind with every second. Once the last node is more than two node steps behind what is
        due, the budget grows with the backlog (one more ``steps_per_call`` for every two steps behind),
        so the backlog stays bounded and the extra work per call stays small.
        """
        budget = self.steps_per_call
        if budget is None or not self._t_nodes:
            return budget
        behind = (until - self._t_nodes[-1]) * self.config.step_hz
        if behind > 2.0:
            budget *= 1 + int(behind) // 2
        return budget

    def _shift_twists(self, dt: float) -> None:
        """The twist delay changed: move the buffered twist samples not yet processed by ``dt`` [s] (those
        that land before the last processed node stay buffered for a rewind or rebuild, as late data)."""
        buf = self._buffers.get("odom", [])
        last = self._t_nodes[-1] if self._t_nodes else -np.inf
        keep = [item for item in buf if item[0] <= last]
        moved = [(item[0] + dt, item[1]) for item in buf if item[0] > last]
        if buf:
            self._buffers["odom"] = sorted(keep + moved, key=lambda item: item[0])

    # ------------------------------------------------------------------ history (EKF rewind)
    def _rewind_index(self, t: float, back: int) -> int | None:
        """The node to re-filter from for a measurement at ``t``, or None if it is beyond the history (or
        more than ``max_gap`` before the first node, even while the track is younger than the history).

        A sample at ``t`` changes the interval that contains it and, through interpolation at that
        interval's start, the one before; so the filter restarts ``back=2`` nodes before ``t``. A visual
        increment is applied from its ``t0`` node (``back=0``).
        """
        if self.history <= 0 or t < self._t_nodes[0] - self.config.max_gap:
            return None  # (a sample that far before the first node would be interpolated across the gap)
        i = max(bisect.bisect_left(self._t_nodes, t - 1e-9) - back, 0)
        if self._records[i] is None or self._t_nodes[-1] - self._t_nodes[i] > self.history + 1e-9:
            return None
        return i

    def _rewind(self, i: int) -> None:
        """Restore the filter to node ``i`` and forget the nodes after it (their inputs stay buffered)."""
        self._drop_pending()
        rec = self._records[i]
        for later in self._records[i + 1:]:
            for v in later.visual:
                bisect.insort(self._visual, v, key=lambda inc: inc.t1)
        self._rewind_gps(i, rec.gps)
        x, P = rec.state
        self._ekf.kf.x = x.reshape(-1, 1).copy()
        self._ekf.kf.P = P.copy()
        self._ekf.linearisation = None  # that node's prediction is not the last one made
        self._heading_offset = rec.heading_offset
        if rec.monitor is not None:
            self._monitor.restore(rec.monitor)
        del self._t_nodes[i + 1:], self._poses[i + 1:], self._covs[i + 1:], self._records[i + 1:]
        self.rewinds += 1

    def _twist(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Body twist of the newest node predicted ``dt`` seconds ahead and its covariance (:class:`Estimate`)."""
        if self.backend == "ekf":
            kf = self._ekf.kf
            if dt <= 0:
                return self._ekf.x[3:6].copy(), self._ekf.P[3:6, 3:6].copy()
            saved = kf.x.copy(), kf.P.copy(), kf.x_prior.copy(), kf.P_prior.copy(), self._ekf.linearisation
            try:
                self._ekf.predict(dt)
                return self._ekf.x[3:6].copy(), self._ekf.P[3:6, 3:6].copy()
            finally:
                kf.x, kf.P, kf.x_prior, kf.P_prior, self._ekf.linearisation = saved
        T = self._t_nodes
        q = np.array([self.config.ekf.accel_sigma, self.config.ekf.lateral_accel_sigma,
                      self.config.ekf.yaw_accel_sigma]) ** 2
        if len(T) < 2 or T[-1] - T[-2] <= 0:
            return np.zeros(3), np.diag(q * max(dt, 1.0 / self.config.step_hz))
        step = T[-1] - T[-2]
        prev, pose = self._poses[-2], self._poses[-1]
        c, s = np.cos(prev[2]), np.sin(prev[2])
        d = pose[:2] - prev[:2]
        dyaw = np.arctan2(np.sin(pose[2] - prev[2]), np.cos(pose[2] - prev[2]))
        twist = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], dyaw]) / step
        return twist, np.diag(q * (step + max(dt, 0.0)))

    def _predict(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose and covariance of the last node predicted ``dt`` seconds ahead (constant twist)."""
        if self.backend == "ekf":
            kf = self._ekf.kf
            saved = kf.x.copy(), kf.P.copy(), kf.x_prior.copy(), kf.P_prior.copy(), self._ekf.linearisation
            try:
                self._ekf.predict(dt)
                return self._ekf.x[:3].copy(), self._ekf.P[:3, :3].copy()
            finally:
                kf.x, kf.P, kf.x_prior, kf.P_prior, self._ekf.linearisation = saved
        return _extrapolate(self._t_nodes, self._poses, self._covs, dt, self.config)

    # ------------------------------------------------------------------ processing
    def _next_node(self, after: float, until: float) -> float | None:
        """The node after ``after``: the next frame if it comes within 1.5 steps, else a fill-in node."""
        step = 1.0 / self.config.step_hz
        frames = [v.t1 for v in self._visual if v.t1 > after + 1e-9]
        fixes = [f.t for f in self._gps if f.t > after + 1e-9]
        if frames and frames[0] <= after + 1.5 * step:
            nxt = frames[0]
        else:
            nxt = after + step
        if fixes and fixes[0] < nxt - 1e-3:  # a fix is a node of its own (timeline.GPS_SNAP)
            nxt = fixes[0]
        return nxt if nxt <= until else None

    def _start_time(self) -> float | None:
        times = [b[0][0] for b in self._buffers.values() if b] + [v.t0 for v in self._visual]
        return min(times) if times else None  # a fix alone does not start the track

    def _process(self, until: float, budget: int | None = None) -> None:
        """Process the nodes up to ``until``, at most ``budget`` units of work (None: all).

        A node is two units (iSAM2: four), one more when the heading monitor's check is due at it:
        building its interval from the buffers; the check; (iSAM2: the monitor's decisions and the node's
        factors; their linearisation;) the backend's update. With iSAM2 in the background the worker
        builds and linearises the factors, but the units are the same, so late data is swapped in at the
        same points as on the caller's thread and the results agree. The operations and
        their order are those of processing the node at once; only the call that runs each differs, so
        no call pays for all of them.
        """
        if self._dirty and (budget is None or self._pending is not None
                            or self._next_node(self._t_nodes[-1], until) is not None):
            # late data is swapped in when the next node is due (several late samples, one update)
            self._drop_pending()
            dirty, self._dirty = sorted(self._dirty), set()
            self._replace(dirty)
        if not self._t_nodes:
            start = self._start_time()
            if start is None or start > until:
                return
            self._first_node(start)
        done = 0
        while budget is None or done < budget:
            done += 1
            started = self._pending
            if started is None:
                t0 = self._t_nodes[-1]
                t1 = self._next_node(t0, until if np.isfinite(until) else self._last_time())
                if t1 is None:
                    return
                self._begin_step(t0, t1)
            elif self._monitor.due():
                self._monitor.check()
            elif self._graph is not None and started.stage == 0:
                self._decide(started)
                started.factors = self._graph.prepare(started.iv)
                started.stage = 1
            elif self._graph is not None and started.stage == 1:
                self._graph.freeze(started.factors)
                started.stage = 2
            else:
                self._end_step()

    def _last_time(self) -> float:
        times = [b[-1][0] for b in self._buffers.values() if b] + [v.t1 for v in self._visual]
        return max(times) if times else -np.inf

    def _streams_between(self, t0: float, t1: float, heading_offset: float | None = None,
                         reach: dict | None = None) -> SensorStreams:
        """The buffered samples an interval needs: those inside it, the ones bracketing it, and (IMU,
        range finder) the neighbours the spike check's running median reads around those (the same values
        as in batch use); until the AHRS offset is known (samples with an orientation), the IMU's first quarter second after
        ``t0`` too."""
        streams = SensorStreams(camera_height=self.camera_height)
        for name, buf in self._buffers.items():
            if name == "range" and self._range_in_visual:  # used once: already in the visual increments
                continue
            live = self._intake[name].live
            more = live.neighbours(self.config) if callable(live.neighbours) else int(live.neighbours)
            lo = max(bisect.bisect_right(buf, t0, key=lambda item: item[0]) - 1 - more, 0)
            hi = bisect.bisect_left(buf, t1, key=lambda item: item[0]) + 1 + more
            if name == "imu" and heading_offset is None and buf and buf[-1][1][2] is not None:
                hi = max(hi, bisect.bisect_right(buf, t0 + 0.25 + self.config.max_gap, key=lambda item: item[0]) + 1)
            rows = buf[lo:hi]
            if reach is not None:  # the time of the last sample read (any new one, if all were read)
                reach[name] = buf[hi - 1][0] if hi <= len(buf) else np.inf
            if len(rows) < live.min_rows:
                continue
            data = live.data(np.array([r[0] for r in rows]), [r[1] for r in rows], self)  # the sensor's own module
            field_name = self._intake[name].field
            if field_name is not None:
                setattr(streams, field_name, data)
            else:
                streams.extra[name] = data
        return streams

    def _interval(self, t0: float, t1: float, heading_offset: float | None):
        """The node interval ``(t0, t1)`` from the buffers: ``(Intervals, step counts, consumed increments,
        time of the last sample read per stream)``.

        Consumes the buffered visual increments ending at or before ``t1``; those that do not span
        exactly this interval cannot be applied and are counted as late.
        """
        step: dict[str, SensorCount] = {}
        reach: dict[str, float] = {}
        streams = self._streams_between(t0, t1, heading_offset, reach)
        consumed = [v for v in self._visual if v.t1 <= t1 + 1e-9]
        usable = [v for v in consumed if abs(v.t1 - t1) < 1e-9 and abs(v.t0 - t0) < 1e-9]
        for v in consumed:
            if v not in usable:
                step.setdefault("camera", SensorCount()).late += 1
        self._visual = [v for v in self._visual if v.t1 > t1 + 1e-9]
        if usable:
            streams.visual = usable
        iv = build_intervals(streams, self.config, np.array([t0, t1]), heading_offset)
        iv.visual_scale_sigma = self._priors.visual_scale_sigma  # what the whole streams give (one interval's
        iv.wheel_scale_sigma = self._priors.wheel_scale_sigma  # samples do not carry the sensors' files)
        for sensor, c in iv.counts.items():
            own = step.setdefault(sensor, SensorCount())
            own.gated += c.gated
            own.missing += c.missing
        return iv, step, consumed, reach

    def _begin_step(self, t0: float, t1: float) -> None:
        """First unit of a node: its interval from the buffers, handed to the heading monitor."""
        iv, step, consumed, reach = self._interval(t0, t1, self._heading_offset)
        monitor = self._monitor.state()
        self._monitor.add(iv)
        self._pending = _Started(t0, t1, iv, step, consumed, monitor, reach)

    def _decide(self, started: _Started) -> None:
        """The monitor's current decisions, applied to the started node's interval."""
        if started.dropped is None:
            started.dropped = frozenset(self._monitor.dropped)
            self._monitor.apply(started.iv)

    def _end_step(self) -> None:
        """Last unit: the monitor's decisions (after its check, if due), the backend's update, the record."""
        started = self._pending
        self._pending = None
        self._monitor.check()  # (a no-op when it ran as a unit of its own)
        self._decide(started)
        iv, step = started.iv, started.step
        self._step_counts = step
        self._step_fixes = []
        if iv.heading_offset is not None:
            self._heading_offset = iv.heading_offset
        if self.backend == "ekf":
            self._ekf_step(iv)
            state = (self._ekf.x.copy(), self._ekf.P.copy()) if self.history > 0 else None
        else:
            self._graph_step(iv, started.factors)
            state = None
        t0 = self._t_nodes[-1]
        self._t_nodes.append(started.t1)
        keep = state is not None
        self._records.append(_NodeRecord(state, self._heading_offset, step, started.consumed,
                                         monitor=self._monitor.state() if keep else None, dropped=started.dropped,
                                         fixes=self._step_fixes, gps=self._gps_state() if keep else None))
        self._retire()
        self._prune(t0)

    def _touch(self, stream: str, t: float) -> None:
        """A measurement of ``stream`` at ``t`` arrived: a started node it would change is started again
        (a sample among those its interval read, a frame that could be its node, a fix up to it)."""
        started = self._pending
        if started is None:
            return
        if stream == "visual":
            changes = t <= max(started.t1, started.t0 + 1.5 / self.config.step_hz) + 1e-9
        elif stream == "gps":
            changes = t <= started.t1 + 1e-3
        else:
            changes = t <= started.reach.get(stream, np.inf)
        if changes:
            self._drop_pending()

    def _drop_pending(self) -> None:
        """Undo the started node (its increments go back to the buffer, the monitor to its state before)."""
        started, self._pending = self._pending, None
        if started is None:
            return
        for v in started.consumed:
            bisect.insort(self._visual, v, key=lambda inc: inc.t1)
        self._monitor.restore(started.monitor)

    def _replace(self, nodes: list[int]) -> None:
        """iSAM2: rebuild the intervals ending at ``nodes`` from the buffers (late data now in them) and
        swap their factors in one update; their recorded poses become iSAM2's estimates after it."""
        batches = []
        for j in nodes:
            rec = self._records[j]
            if rec is None or self._records[j - 1] is None:  # left the history meanwhile
                continue
            for v in rec.visual:
                bisect.insort(self._visual, v, key=lambda inc: inc.t1)
            prev = self._records[j - 1]
            iv, step, consumed, _ = self._interval(self._t_nodes[j - 1], self._t_nodes[j], prev.heading_offset)
            rec.counts, rec.visual = step, consumed
            self._monitor.update(j - 1, iv)
            self._monitor.apply(iv, rec.dropped)  # the decision taken when the node was first processed
            rec.heading_offset = iv.heading_offset if iv.heading_offset is not None else prev.heading_offset
            batches.append((j, iv))
        if not batches:
            return
        self._heading_offset = self._records[-1].heading_offset
        for j, pose, cov, used in self._graph.replace(batches):
            self._poses[j], self._covs[j] = pose, cov
            self._count_used(j, used)
        self.rewinds += 1

    def _retire(self) -> None:
        """Drop the rewind data of nodes older than the history (their counts are kept)."""
        horizon = self._t_nodes[-1] - self.history - 1e-9
        for j in range(len(self._records) - 1, -1, -1):  # the newest already-retired node ends the scan
            if self._t_nodes[j] >= horizon:
                continue
            if self._records[j] is None:
                break
            if self._graph is not None and self._graph.has_jobs():
                # a worker more than the history behind: wait for it (its results set the node's counts)
                self._collect(wait=True)
            rec = self._records[j]
            _merge_into(self._retired_counts, rec.counts)
            self._records[j] = None
            if self._graph is not None:
                self._graph.forget(j)

    def _prune(self, t0: float) -> None:
        keep_from = t0 - self.history - 2.0 * self.config.max_gap
        for name, buf in self._buffers.items():
            cut = bisect.bisect_left(buf, keep_from, key=lambda item: item[0]) - 2
            if cut > 0:
                del buf[:cut]

    def _calibration_flags(self) -> tuple[bool, bool]:
        s = set(self.sensors)
        wheel = bool(s & {"wheel", "odom"})
        heading = bool(s & {"camera", "imu"}) or any(registry.get(n).absolute_heading for n in s)  # a heading reference
        return "camera" in s and (wheel or "range" in s), wheel and heading

    # ------------------------------------------------------------------ backends
    def _first_node(self, t: float) -> None:
        cfg = self.config
        self._t_nodes.append(t)
        kv, kb = self._calibration_flags()
        if self.backend == "ekf":
            twist = "odom" in self.sensors and "wheel" not in self.sensors
            self._ekf = PlanarEkf(cfg, self.camera_height, kv, kb, twist, visual_scale_sigma=self._priors.visual_scale_sigma,
                                  wheel_scale_sigma=self._priors.wheel_scale_sigma, states=self._states,
                                  camera="camera" in self.sensors,
                                  frame_error=1.0 if self._camera_frame_errors else None)
            self._records.append(_NodeRecord((self._ekf.x.copy(), self._ekf.P.copy()), None,
                                             monitor=self._monitor.state(), gps=self._gps_state()))
            self._record(self._ekf.x[:3], self._ekf.P[:3, :3])
        else:
            self._records.append(_NodeRecord(None, None))
            self._graph = _OnlineGraph(cfg, t, (kv, kb), self.background, self._states)
            pose, cov = self._graph.start()
            self._record(pose, cov)

    def _record(self, pose, cov) -> None:
        self._poses.append(np.asarray(pose, dtype=np.float64).copy())
        self._covs.append(np.asarray(cov, dtype=np.float64).copy())

    def _ekf_step(self, iv) -> None:
        ekf = self._ekf
        meas = interval_measurements(iv, self.config)
        ekf.predict(float(iv.dt[0]), frame_error_cov(meas, 0))
        ekf.update(step_blocks(ekf, meas, 0))
        t1 = float(iv.t[-1])
        for fix in [f for f in self._gps if f.t <= t1 + 1e-3]:
            self._gps.remove(fix)
            self._step_fixes.append(fix)
            if abs(fix.t - t1) > 1e-3:  # behind the last node already: cannot be applied causally
                self._step_counts.setdefault("gps", SensorCount()).late += 1
            else:
                self._apply_gps(fix)
        for sensor, c in ekf.counts.items():
            own = self._step_counts.setdefault(sensor, SensorCount())
            own.used += c.used
            own.gated += c.gated
        ekf.counts = {}
        self._record(ekf.x[:3], ekf.P[:3, :3])

    def _apply_gps(self, fix: GpsFix) -> None:

        ekf, model = self._ekf, self._gps_model
        if self._frame == "start":
            self._gps_seen.append(fix)
            poses = np.array(self._poses + [ekf.x[:3]])
            times = np.array(self._t_nodes[:len(poses) - 1] + [fix.t])
            seen = GpsData(np.array([f.t for f in self._gps_seen]), np.column_stack(
                [np.array([f.enu for f in self._gps_seen]), np.zeros(len(self._gps_seen))]),
                np.array([f.covariance for f in self._gps_seen]), np.zeros((len(self._gps_seen), 3)),
                np.zeros(len(self._gps_seen), int), (0.0, 0.0, 0.0), self._gps_lever, 0.0)
            fit = align_to_fixes(times, poses, seen, t_end=fix.t) if len(times) > 1 else None
            if fit is None:
                self._step_counts.setdefault("gps", SensorCount()).missing += 1  # kept for the alignment
                return
            sigma = math.sqrt(float(np.median(np.trace(seen.covariance, axis1=1, axis2=2))) / 2.0)
            _, prior_sigma = prior_from_alignment(fit, poses[0], sigma)
            c, s_ = math.cos(fit.yaw), math.sin(fit.yaw)
            T = np.eye(ekf.kf.P.shape[0])
            T[:2, :2] = [[c, -s_], [s_, c]]
            ekf.kf.x[:3, 0] = fit.apply(ekf.x[:3])[0]
            ekf.kf.P = T @ ekf.kf.P @ T.T
            ekf.kf.P[:2, :2] += np.eye(2) * prior_sigma[0] ** 2
            ekf.kf.P[YAW, YAW] += prior_sigma[2] ** 2
            rot = np.eye(3)
            rot[:2, :2] = T[:2, :2]
            self._start_frame = (len(self._t_nodes), list(self._poses), list(self._covs), len(self._notes))
            self._poses = [p for p in fit.apply(np.array(self._poses))]
            self._covs = [rot @ cv @ rot.T for cv in self._covs]
            self._frame = "enu"
            if self._heading_offset is not None:  # AHRS north was aligned to the start frame's heading
                self._heading_offset -= fit.yaw
            self._gps_reacquire = GpsReacquire(self.config.gps_reacquire)
            self._notes.append(f"gps: world frame re-expressed in ENU at t={fix.t:.2f} (first heading "
                               f"{math.degrees(float(self._poses[0][2])):.2f} deg ± {math.degrees(fit.yaw_sigma):.2f})")
        accepted = ekf_update(ekf, model, fix.enu, fix.covariance, fix.t)
        if not accepted and self._gps_reacquire.due(fix.t, False):
            accepted = ekf_reacquire(ekf, model, fix.enu, fix.covariance, fix.t)
        elif accepted:
            self._gps_reacquire.due(fix.t, True)
        count = self._step_counts.setdefault("gps", SensorCount())
        if accepted:
            count.used += 1
        else:
            count.gated += 1

    def _gps_state(self) -> tuple | None:
        """What a rewind restores of the GPS bookkeeping (frame, fixes kept for the alignment, re-acquisition)."""
        if "gps" not in self.sensors:
            return None
        re = self._gps_reacquire
        return (self._frame, len(self._gps_seen), None if re is None else (re.last_ok, len(re.times)),
                (self._gps_model.n_used, self._gps_model.n_rejected, len(self._gps_model.rejected_t)))

    def _rewind_gps(self, i: int, state: tuple | None) -> None:
        """Back to the GPS bookkeeping after node ``i``; undo the switch to ENU if it came after ``i``."""
        for rec in self._records[i + 1:]:
            for fix in rec.fixes:
                bisect.insort(self._gps, fix, key=lambda f: f.t)
        if state is None:
            return
        frame, n_seen, reacquire, model = state
        if self._frame == "enu" and frame == "start":
            _, poses, covs, n_notes = self._start_frame
            self._poses[:i + 1] = [p.copy() for p in poses[:i + 1]]
            self._covs[:i + 1] = [c.copy() for c in covs[:i + 1]]
            del self._notes[n_notes:]
            self._frame, self._gps_reacquire, self._start_frame = "start", None, None
        del self._gps_seen[n_seen:]
        if reacquire is not None:
            self._gps_reacquire.last_ok = reacquire[0]
            del self._gps_reacquire.times[reacquire[1]:]
        m = self._gps_model
        m.n_used, m.n_rejected = model[0], model[1]
        del m.rejected_t[model[2]:]

    def _graph_step(self, iv, prepared=None) -> None:
        pose, cov, sensors = self._graph.step(iv, prepared)
        if pose is None:  # background update under way: the last pose predicted meanwhile
            pose, cov = _extrapolate(self._t_nodes, self._poses, self._covs, float(iv.t[-1]) - self._t_nodes[-1],
                                     self.config)
        for s in sensors or ():
            self._step_counts.setdefault(s, SensorCount()).used += 1
        self._record(pose, cov)

    def _collect(self, wait: bool = False) -> None:
        """Take in the results of finished background iSAM2 updates (all of them with ``wait``)."""
        if self._graph is None or not self.background:
            return
        for n, pose, cov, sensors in self._graph.collect(wait):
            if n < len(self._poses):
                self._poses[n], self._covs[n] = pose, cov
            self._count_used(n, sensors)

    def _count_used(self, n: int, sensors) -> None:
        """Node ``n``'s factors are now those of ``sensors`` (None: unchanged): its ``used`` counts follow."""
        if sensors is None:
            return
        rec = self._records[n] if n < len(self._records) else None
        if rec is None:  # left the history while its update ran: its counts were merged already
            return
        for c in rec.counts.values():
            c.used = 0
        for s in sensors:
            rec.counts.setdefault(s, SensorCount()).used += 1


def _values(payload):
    """The numbers of a live sample's payload that must be finite: its entries that are not None."""
    return [x for x in payload if x is not None] if isinstance(payload, tuple) else payload


def time_ordered_messages(streams: SensorStreams, camera_delay: float = 0.0) -> list[tuple[float, str, object]]:
    """The samples of ``streams`` as ``(arrival time, kind, message)`` in arrival order.

    ``kind`` names the :class:`StreamingFusion` method (``add_<kind>``), or for a sensor registered outside the
    library whose :class:`~fusion_vo.sensors.registry.Live` intake gives ``samples``, the sensor
    (``add(kind, message)``). Samples arrive at their own time, the visual increments ``camera_delay`` seconds
    after their ``t1`` (frontend latency).
    """
    msgs: list[tuple[float, int, str, object]] = []
    if streams.visual:
        msgs += [(v.t1 + camera_delay, 0, "visual", v) for v in streams.visual]
    if streams.wheel is not None:
        w = streams.wheel
        msgs += [(t, 1, "wheel", WheelTicks(t, int(lt), int(rt))) for t, lt, rt in zip(w.t, w.left, w.right)]
    if streams.odom is not None:
        o = streams.odom
        msgs += [(t, 1, "twist", TwistSample(t, vx, vy, wz)) for t, vx, vy, wz in zip(o.t, o.vx, o.vy, o.wz)]
    if streams.imu is not None:
        m = streams.imu
        q = m.orientation if m.orientation is not None else [None] * len(m.t)
        msgs += [(t, 2, "imu", ImuSample(t, g, a, o)) for t, g, a, o in zip(m.t, m.gyro, m.accel, q)]
    if streams.range is not None:
        msgs += [(t, 3, "range", RangeSample(t, d)) for t, d in zip(streams.range.t, streams.range.distance)]
    for name, data in streams.extra.items():
        live = registry.get(name).live if name in registry.names() else None
        if live is not None and live.samples is not None and data is not None:
            msgs += [(float(t), 4, name, m) for t, m in live.samples(data)]
    msgs.sort(key=lambda m: (m[0], m[1]))
    return [(float(m[0]), m[2], m[3]) for m in msgs]


def streaming_for(streams: SensorStreams, backend: str = "ekf", config: FusionConfig | dict | None = None,
                  **kwargs) -> StreamingFusion:
    """A :class:`StreamingFusion` for the sensors and calibrations of ``streams`` (keyword arguments pass on)."""
    sensors = [name for name, present in (("camera", bool(streams.visual)), ("wheel", streams.wheel is not None),
                                          ("odom", streams.odom is not None), ("imu", streams.imu is not None),
                                          ("range", streams.range is not None)) if present]
    sensors += [name for name, data in streams.extra.items()  # sensors registered outside the library
                if data is not None and name in registry.names() and registry.get(name).live is not None]
    imu = streams.imu
    return StreamingFusion(backend, config, sensors, wheel_config=None if streams.wheel is None else streams.wheel.config,
                           imu_T_BS=None if imu is None else imu.T_BS, imu_noise=None if imu is None else imu.noise,
                           camera_height=streams.camera_height, camera_height_sigma=streams.camera_height_sigma,
                           range_height_sigma=streams.range_height_sigma if streams.range_in_visual else None,
                           camera_frame_errors=any(inc.frame_covariance is not None for inc in streams.visual or ()),
                           **kwargs)


def _merge_into(total: dict, part: dict) -> None:
    for sensor, c in part.items():
        own = total.setdefault(sensor, SensorCount())
        for key, value in c.as_dict().items():
            setattr(own, key, getattr(own, key) + value)


def _extrapolate(t_nodes, poses, covs, dt: float, config: FusionConfig) -> tuple[np.ndarray, np.ndarray]:
    """Constant-twist prediction of the last pose by ``dt`` from the twist between the last two nodes.

    The covariance is propagated through the motion (a world-frame pose error rotates the
    displacement) and grown by the EKF's acceleration noise integrated over ``dt``.
    """
    pose = poses[-1]
    if len(t_nodes) < 2 or t_nodes[-1] - t_nodes[-2] <= 0:
        twist = np.zeros(3)
    else:
        prev = poses[-2]
        c, s = np.cos(prev[2]), np.sin(prev[2])
        d = pose[:2] - prev[:2]
        dyaw = np.arctan2(np.sin(pose[2] - prev[2]), np.cos(pose[2] - prev[2]))
        twist = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], dyaw]) / (t_nodes[-1] - t_nodes[-2])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    step = twist * dt  # small steps: the body-frame displacement is the twist times dt to first order
    dx = c * step[0] - s * step[1]
    dy = s * step[0] + c * step[1]
    out = np.array([pose[0] + dx, pose[1] + dy, np.arctan2(np.sin(pose[2] + step[2]), np.cos(pose[2] + step[2]))])
    J = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
    q = np.array([config.ekf.accel_sigma, config.ekf.lateral_accel_sigma, config.ekf.yaw_accel_sigma]) ** 2
    rot = np.array([[c, -s], [s, c]])
    Q = np.zeros((3, 3))
    Q[:2, :2] = rot @ np.diag(q[:2]) @ rot.T * dt**3 / 3.0
    Q[2, 2] = q[2] * dt**3 / 3.0
    return out, J @ covs[-1] @ J.T + Q


class _OnlineGraph:
    """iSAM2 fed one node interval at a time through :class:`~fusion_vo.backends.graph.GraphBuilder`.

    On the caller's thread a node is built in three calls: :meth:`prepare` (its factors),
    :meth:`freeze` (their linearisation at the current estimate), :meth:`step` (the iSAM2 update). With
    ``background`` one worker thread owns iSAM2 and runs all three, and the rebuilds of :meth:`replace`,
    in the order they were submitted, from the same state: the estimates are those of the caller-thread
    run, whatever the worker's timing.
    """

    def __init__(self, config: FusionConfig, t_origin: float, calibrate: tuple[bool, bool], background: bool = False,
                 states: tuple = ()):
        import gtsam

        from fusion_vo.backends import graph

        self.gtsam = gtsam
        self.graph = graph
        self.config = config
        self.t_origin = t_origin
        self.calibrate = calibrate
        self.states = states  # the sensors' own state variables (registry.State)
        # QR: a heading source dropped by the monitor leaves its offset variables to a random walk alone,
        # a conditioning that Cholesky can report as indeterminate
        self.isam = gtsam.ISAM2(graph.isam_params())
        self.n = 0  # nodes submitted
        self.estimate: dict = {}  # running bias / calibration estimates (guesses of the next node)
        self.prev_pose = gtsam.Pose2(*config.initial_pose)  # iSAM2's estimate of the newest node
        self.online: dict[int, np.ndarray] = {}  # node -> its pose as last computed (seeds rebuilds)
        self.last = 0  # newest node in iSAM2 (behind ``n`` while background jobs wait)
        self._forget_below = 0  # nodes before this left the history
        # background: one worker thread owns iSAM2 (it is not thread-safe); jobs run in order
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="isam2") if background else None
        self._jobs: deque = deque()

    def start(self):
        cfg = self.config
        # the first node's own factors come with the first interval (which knows the sensors)
        self._pending_first = True
        self.factors: dict[int, list[int]] = {}  # node -> indices of its factors in iSAM2
        self.frames: set[int] = set()  # nodes whose camera frame pose exists
        self.frames_made: dict[int, set[int]] = {}  # node -> the frame poses its factors tie
        self.online[0] = np.asarray(cfg.initial_pose, dtype=np.float64)
        return self.online[0].copy(), np.diag([1e-8, 1e-8, 1e-8])

    def _node_factors(self, n: int, iv, first: bool, previous_pose):
        builder = self.graph.GraphBuilder(iv, self.config, offset=n - 1, t_origin=self.t_origin,
                                          calibrate=self.calibrate, states=self.states)
        # the camera's frame poses made so far (fusion_vo.sensors.visual); a node rebuilt for late data makes
        # again the ones it made (their ties go with its old factors)
        self.frames -= self.frames_made.pop(n, set())
        builder.frames = self.frames
        before = {g for g in (n - 1, n) if g in self.frames}  # (its interval's two nodes)
        nf = builder.node(1, previous_pose, self.estimate)
        made = {g for g in (n - 1, n) if g in self.frames} - before
        if made:
            self.frames_made[n] = made
        if first:
            head = builder.first_node()
            head.factors.extend(nf.factors)
            head.values.update(nf.values)
            head.sensors = nf.sensors
            nf = head
        return builder, nf

    # ------------------------------------------------------------------ one node
    def prepare(self, iv) -> list | None:
        """The factors of the next node (ending ``iv``); changes nothing (background: None, the worker
        builds them)."""
        if self._pool is not None:
            return None
        builder, nf = self._node_factors(self.n + 1, iv, self._pending_first, self.prev_pose)
        return [builder, nf, None, None]

    def freeze(self, prepared: list) -> None:
        """Linearise the prepared node's custom factors at the current estimate (background: the worker does)."""
        if prepared is None:
            return
        n, nf = self.n + 1, prepared[1]
        lookup = self.graph.current_value_lookup(nf.values, self.isam, self.prev_pose, n - 1)
        prepared[3] = []
        prepared[2] = self.graph.freeze_custom_factors(nf.factors, lookup, weights=prepared[3])

    def step(self, iv, prepared: list | None = None):
        """Add the node ending ``iv`` (its factors from :meth:`prepare` / :meth:`freeze` when given):
        ``(pose, covariance, sensors)``. In the background only the interval is handed over: pose,
        covariance and sensors are None and come through :meth:`collect`."""
        self.n += 1
        if self._pool is not None:
            self._jobs.append(self._pool.submit(self._add_node, self.n, iv, None))
            return None, None, None
        return self._add_node(self.n, iv, prepared)[0][1:]

    def _add_node(self, n: int, iv, prepared: list | None):
        if prepared is None:
            prepared = self._node_factors(n, iv, self._pending_first, self.prev_pose) + (None, None)
        builder, nf, frozen, weights = prepared
        if frozen is None:
            lookup = self.graph.current_value_lookup(nf.values, self.isam, self.prev_pose, n - 1)
            weights = []
            frozen = self.graph.freeze_custom_factors(nf.factors, lookup, weights=weights)
        self._pending_first = False
        g = self.gtsam.NonlinearFactorGraph()
        for f in frozen:
            g.add(f)
        values = self.gtsam.Values()
        self.graph.insert_values(values, nf.values)
        # the robust weights at the updated estimate, as the whole-recording iSAM2 (graph.update_reweighted)
        self.factors[n] = self.graph.update_reweighted(self.isam, g, values, nf.factors, weights,
                                                       passes=self.config.graph.reweight_passes)[0]
        self.last = n
        for old in [k for k in self.factors if k < self._forget_below]:
            del self.factors[old]
            self.frames_made.pop(old, None)
            self.frames.discard(old - 1)  # (no later node reaches back that far)
        pose, cov = self._pose_cov(n)
        self.prev_pose = self.gtsam.Pose2(*map(float, pose))
        self.graph.track_estimate(self.estimate, self.isam, builder, 1, nf)
        self._remember(n, pose)
        return [(n, pose, cov, nf.sensors)]

    def _remember(self, n: int, pose: np.ndarray) -> None:
        self.online[n] = pose
        self.online.pop(n - 4096, None)  # far older than any history

    def has_jobs(self) -> bool:
        """Whether background results are still to be collected."""
        return bool(self._jobs)

    def collect(self, wait: bool = False) -> list:
        """Results ``(n, pose, covariance, sensors)`` of the finished background jobs, in order."""
        out = []
        while self._jobs and (wait or self._jobs[0].done()):
            out += self._jobs.popleft().result()
        return out

    def _pose_cov(self, n: int):
        key = self.graph.X(n)
        pose = self.isam.calculateEstimatePose2(key)
        cov = self.graph.world_covariances(np.array([pose.theta()]), self.isam.marginalCovariance(key)[None])[0]
        return np.array([pose.x(), pose.y(), pose.theta()]), cov

    # ------------------------------------------------------------------ late data
    def replace(self, batches, passes: int = 2):
        """Swap the factors of nodes ``n`` for those of their rebuilt intervals.

        ``batches`` holds ``(n, Intervals)`` in node order (nodes that exist already). The factors are
        built (seeded by node ``n-1``'s pose as last computed) and swapped now, or in a background job.
        Returns the results ``(n, pose, covariance, sensors)`` of a swap that ran (background: none yet).
        """
        if self._pool is None:
            return self._swap(batches, passes)
        self._jobs.append(self._pool.submit(self._swap, batches, passes))
        return []

    def _swap(self, batches, passes: int):
        """The custom factors are linearised at the current estimate and swapped in one iSAM2 update;
        ``passes`` > 1 linearises them again at the estimate that update gave (the late data may have
        moved it) and swaps again."""
        built = []
        for n, iv in batches:
            builder, nf = self._node_factors(n, iv, n == 1, self.gtsam.Pose2(*map(float, self.online[n - 1])))
            built.append((n, nf, builder))
        builder, nf = built[-1][2], built[-1][1]
        new_keys: set = set()
        for p in range(passes):
            g = self.gtsam.NonlinearFactorGraph()
            values = self.gtsam.Values()
            remove, sizes = [], []
            for n, nf, _ in built:
                new = {k: v for k, v in nf.values.items() if not self.isam.valueExists(k) and not values.exists(k)}
                new_keys.update(new)
                previous = self.isam.calculateEstimatePose2(self.graph.X(n - 1))
                lookup = self.graph.current_value_lookup(new, self.isam, previous, n - 1)
                frozen = self.graph.freeze_custom_factors(nf.factors, lookup)
                for f in frozen:
                    g.add(f)
                self.graph.insert_values(values, new)
                remove += self.factors.get(n, [])
                sizes.append(len(frozen))
            index = list(self.isam.update(g, values, remove).getNewFactorsIndices())
            for (n, _, _), size in zip(built, sizes):
                self.factors[n], index = index[:size], index[size:]
        out = []
        for n, nf, _ in built:
            pose, cov = self._pose_cov(n)
            self._remember(n, pose)
            out.append((n, pose, cov, nf.sensors))
        self.prev_pose = self.isam.calculateEstimatePose2(self.graph.X(self.last))
        if built[-1][0] == self.last:
            self.graph.track_estimate(self.estimate, self.isam, builder, 1, nf)
        return out

    def poses(self) -> np.ndarray:
        """Current estimates ``(x, y, yaw)`` of nodes 0 .. n."""
        est = self.isam.calculateEstimate()
        if self.n == 0:
            return np.array([np.asarray(self.config.initial_pose, dtype=np.float64)])
        return np.array([[p.x(), p.y(), p.theta()] for p in (est.atPose2(self.graph.X(k)) for k in range(self.n + 1))])

    def forget(self, n: int) -> None:
        """Node ``n`` left the history: its factors are no longer replaced."""
        self._forget_below = max(self._forget_below, n + 1)  # (the thread that owns iSAM2 drops them)
        if self._pool is None:
            self.factors.pop(n, None)
