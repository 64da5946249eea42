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
causally and is counted as late. One that starts at the previous node and ends at a later frame (frames
dropped between its two) is applied as a batch run applies it: by the EKF as a share over each of its node
intervals, by iSAM2 as one factor between its two frames' nodes, added with the second.

GPS (``add_gps``, both backends): every fix time is a node, and the fix measures the pose there through the GPS
model of :mod:`fusion_vo.sensors.gps` (lever arm, ``fusion.gps``'s gate and robust weight, re-acquisition after
``gps_reacquire`` seconds of rejections). Until the robot has moved enough for
:func:`~fusion_vo.sensors.gps.align_to_fixes` to fix the heading of ENU, estimates are in the start frame
(``initial_pose``) and fixes are only collected; at the first alignment the poses recorded so far are
re-expressed in ENU at the datum, and that fix and every later one are applied. ``current_estimate`` says which
frame it is in (``Estimate.frame``). The EKF re-expresses its state and covariance (plus the alignment's
uncertainty) in ENU. iSAM2 keeps what it has in the start frame and adds the start frame's pose in ENU ``T_WS``,
with the alignment as its prior, and the node's pose once more in ENU, tied to both; every later pose is an ENU
variable and a fix there is the batch graph's factor on it (:mod:`fusion_vo.backends.online_graph`). A fix
re-acquired after ``gps_reacquire`` seconds of rejections is applied at full weight by both: the EKF after
widening its position covariance by the squared innovation, iSAM2 without the robust kernel.
The fixes keep their stated sigma (floored by ``fusion.gps.min_sigma``): ``fusion.gps.estimate_sigma``,
the scatter measured by a batch run's world-frame alignment, is not applied here.
The history keeps what each node did to this bookkeeping (the fixes it consumed, the frame, the fixes
kept for the alignment, the re-acquisition timer), so a late sample or fix rewinds the EKF with GPS
as without it, back across the switch to ENU if need be (the start-frame poses are kept for that).
iSAM2 rebuilds a node for late data with the fixes' factors it had (as gated then); its node times stay, so a
fix later than the reorder window is re-timed onto the nearest processed node (the wheels' and gyro's motion
from the node to the fix folded into the antenna's lever arm, its covariance grown by that motion's) and that
node rebuilt with it; one older than the history, or with no wheel data around it, is counted late.
Each fix is counted once, at its node: used, gated (the gate, or a bad value on arrival), missing
(kept for the alignment) or late. The EKF notes each outage of the fixes as a batch run does (the drift the first
fix after it measures, :func:`~fusion_vo.backends.fixes.outage_note`).

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

* the EKF keeps its states too: it rewinds to the node before the first interval that reads the
  measurement (in a gap of its stream, the gap's first) and re-filters everything after it, so the result is
  the one the same data would have given in time order;
* iSAM2 rebuilds the node intervals the measurement changes (its own interval and those whose
  interpolation, gating or spike median its neighbours feed) and swaps their factors for the new ones
  in one update (``removeFactorIndices``), when the next node is due; the custom factors are linearised
  at the current estimate, twice. The node times stay those already processed: a camera later than the
  reorder window finds fill-in nodes where its frames would have been, so its increment is re-timed onto
  the nearest two nodes (the wheels' and the gyro's motion over the slivers between each frame and its
  node composed onto it, the covariance grown accordingly), one factor between them when it spans dropped
  frames; it is counted late only if an interval between them already carries an increment. The online poses of the rebuilt nodes become iSAM2's
  estimates after the swap (:meth:`smoothed` gives the whole current estimate).

Measurements older than the history are counted as ``late`` and reported by :meth:`finish`.

Outages
-------
:meth:`finish`'s notes name the spans without the camera (0.2 s or longer) or without another sensor's samples
(0.5 s or longer) as a batch run's do (:func:`~fusion_vo.measurements.grid.outage_notes`), from the coverage of
each node interval as last processed (:func:`~fusion_vo.backends.stream_state.interval_coverage`).

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
from the history before its result came: a worker that far behind slows the caller down, and, until the
fixes have fixed the heading of ENU, a GPS fix: the alignment fits iSAM2's poses, not the ones predicted meanwhile).

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
import logging
import threading
from collections.abc import Iterable

import numpy as np

from fusion_vo import backends
from fusion_vo.backends.batch import as_config
from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.ekf import PlanarEkf, filter_libraries
from fusion_vo.backends.fixes import reacquired_text
from fusion_vo.backends.live_monitor import LiveHeadingMonitor
from fusion_vo.backends.result import FusionResult, SensorCount
from fusion_vo.backends.states import live_context, run_states
from fusion_vo.backends.timeline import SensorStreams, scale_priors
from fusion_vo.sensors import registry
from fusion_vo.consistency import mounting
from fusion_vo.consistency.live import LiveMounting, aligned_offset
from fusion_vo.errors import InputError
from fusion_vo.measurements import (
    GpsFix, ImuSample, PoseData, RangeSample, TwistSample, VisualIncrement, WheelConfig,
    WheelTicks,
)
from fusion_vo.sensors.gps import GpsModel
from fusion_vo.sensors.wheel_states import curvature_observable, curvature_states

from fusion_vo.backends.stream_history import HistoryMixin
from fusion_vo.backends.stream_intake import IntakeMixin
from fusion_vo.backends.stream_nodes import NodesMixin
from fusion_vo.backends.stream_state import (
    Estimate, NodeRecord, Started, merge_counts, node_outage_notes, payload_values,
)

logger = logging.getLogger(__name__)

def message_sensor(kind: str) -> str:
    """The sensor a kind of :func:`time_ordered_messages` is added to: the one whose intake names its samples
    ``kind`` (:attr:`Live.message <fusion_vo.sensors.registry.Live.message>`), else the sensor called ``kind``."""
    for sensor in registry.sensors():
        if sensor.live is not None and sensor.live.message == kind:
            return sensor.name
    return kind


class StreamingFusion(IntakeMixin, NodesMixin, HistoryMixin):
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
    the ROS 2 node (``fusion-vo ros2``, :mod:`fusion_vo.ros2.run`) does
    (``docs/decisions/0029-live-work-on-the-callers-thread.md``).
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
        #: iSAM2's side (GTSAM is imported here, about 0.1 s, not inside the first add() call that makes a node)
        self._online_graph = None
        if backend == "gtsam":
            self._online_graph = backends.OnlineGraph  # GTSAM: loaded only for an iSAM2 stream
        # what the first node and the first mounting check would load inside an add() call (about 0.6 s)
        if backend == "ekf":
            filter_libraries()
        mounting.scipy_rotation()
        self._lock = threading.RLock()
        self.config = as_config(config)
        if imu_noise:
            self.config = self.config.model_copy(update={"imu": self.config.imu.with_sensor_keys(imu_noise)})
        if self.config.imu.gyro_rest_noise_density > 0:
            logger.warning("imu.gyro_rest_noise_density is not used by streaming fusion: the gyro keeps its "
                           "noise density at rest too")
        self.backend = backend
        self.sensors = list(sensors)
        registry.ensure(self.sensors)
        bad = [s for s in self.sensors if s not in registry.names()]
        if bad:
            raise InputError(f"unknown sensor '{bad[0]}' (use {', '.join(registry.names())})")
        if "wheel" in self.sensors and wheel_config is None:
            raise InputError("the wheel sensor needs its wheel_config (ticks per revolution, radii, wheel base)")
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
        self._records: list[NodeRecord | None] = []
        self._step_counts: dict[str, SensorCount] = {}  # counts of the node being processed
        self._retired_counts: dict[str, SensorCount] = {}  # counts of nodes older than the history
        self.rewinds = 0
        self._monitor = LiveHeadingMonitor(self.config, self.history)
        self._dirty: set[int] = set()  # iSAM2: nodes whose intervals late data changed
        # every sensor with a live intake (registry.Live), the built-in ones always (odometry twists also arrive
        # for a declared "wheel"), the others when declared: its registration and the name it is counted under
        self._intake = {s.name: s for s in registry.sensors() if s.live is not None and
                        (s.name in registry.BUILTIN_ORDER or s.name in self.sensors)}
        self._counted = {name: s.live.counted_as or name for name, s in self._intake.items()}
        # per-stream buffers of (t, payload) of those whose samples are interpolated at the nodes (no Live.take)
        self._buffers: dict[str, list] = {name: [] for name, s in self._intake.items() if s.live.take is None}
        #: the run's scalar states (registry.State) in both backends
        self._states = registry.states(self.sensors, self.config)
        if wheel_config is not None:  # the wheels' curvature bias and its prior, as in a batch run

            # decided from the sensors declared: whether the IMU brings an AHRS heading is known only from its
            # samples, so it does not count here (a batch run of wheels and an AHRS alone estimates the curvature)
            observable = curvature_observable(registry.get(name).references_heading(None) for name in self.sensors)
            self._states = curvature_states(self._states, self.config,
                                            wheel_config.relative_radius_sigma(self.config.wheel_scale_sigma),
                                            wheel_config.wheel_base, observable)
        # with the built-in calibrations, decided from the sensors declared (states.live_context)
        self._states = run_states(live_context(self.config, self.sensors, self._priors.facts()), self._states)
        self._visual: list[VisualIncrement] = []
        self._fill: tuple | None = None  # (from, to, fill-in nodes) of the gap to the next frame
        self._latest = -np.inf
        self._t_nodes: list[float] = []
        self._covered: list[dict[str, bool]] = []  # interval k (ending at node k + 1) -> the sensors covering it
        self._poses: list[np.ndarray] = []
        self._covs: list[np.ndarray] = []
        self._carry: dict = {}  # sensor -> the value its intervals carry (Intervals.carry), as of the last node
        self._notes: list[str] = list(self._priors.notes)
        if self._range_in_visual and "range" in self.sensors:
            self._notes.append("range finder: already in the visual increments (their per-frame height), "
                               "not used again as a height measurement")
        self._ekf: PlanarEkf | None = None
        self._graph = None

        lever = np.zeros(3) if gps_lever_arm is None else np.asarray(gps_lever_arm, dtype=np.float64).ravel()
        if len(lever) not in (2, 3) or not np.all(np.isfinite(lever)):
            raise InputError(f"gps_lever_arm must be 2 or 3 finite numbers [m] (the antenna in the body frame), "
                             f"not {gps_lever_arm!r}")
        self._gps_model = GpsModel(lever, self.config.gps)
        self._gps_lever = lever
        self._gps: list[GpsFix] = []  # pending fixes, in time order
        self._gps_seen: list[GpsFix] = []  # fixes before the world frame was aligned
        self._late_fixes: dict[int, list] = {}  # iSAM2: node -> late fixes re-timed onto it, (fix, lever arm)
        self._switch: tuple | None = None  # iSAM2: (node, heading of ENU in the start frame) of the switch to ENU
        self._frame = "start"
        self._gps_reacquire = None
        self._gps_last: float | None = None  # EKF: the time of the last fix applied or kept (outage notes)
        self._outages: dict[float, str] = {}  # EKF: fix time -> the note of the outage it ends
        self._step_fixes: list[GpsFix] = []  # fixes the node being processed consumed
        self._pending: Started | None = None  # a node started but not yet applied (_begin_step)
        self._last_iv = None  # the node grid of the newest node processed (its states, for the calibration)
        self._finishing = False  # finish() processes the last nodes: no sample comes after the buffered ones
        self._start_frame: tuple | None = None  # (node, poses, covariances, note) before the switch to ENU
        # what puts a sensor's samples on the run's clock as they come (Live.clock: an odometry twist's delay behind
        # the gyro, estimated from the samples so far as in batch use)
        self._clocks = [clock for s in registry.sensors() if s.live is not None and s.live.clock is not None
                        for clock in (s.live.clock(self),) if clock is not None]
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
                values = None if live.take is None else payload_values(payload) if live.values is None else live.values(payload)
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
                t, moved = self._synchronised(sensor, t, payload)
                self._add(sensor, t, payload, moved)
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
            self._monitor = LiveHeadingMonitor(self.config, self.history)
            self._monitor.episodes = episodes
            for clock in self._clocks:
                clock.remounted(*self._mounting.body_rates(T))
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
        if self._carry.get("imu") is None or first is None:
            return
        offset = aligned_offset(self.imu_T_BS, first, float(self.config.initial_pose[2]))
        if offset is not None:
            self._carry["imu"] = offset

    def feed(self, messages: Iterable[tuple[float, str, object]]) -> None:
        """Add the samples ``(arrival time, kind, sample)`` of ``messages`` in their order
        (:func:`time_ordered_messages`): :meth:`add` with the sensor ``kind`` names, where ``visual`` is the
        camera's and ``twist`` the odometry's (``odom``) samples."""
        sensor_of: dict[str, str] = {}
        for _, kind, sample in messages:
            if kind not in sensor_of:
                sensor_of[kind] = message_sensor(kind)
            self.add(sensor_of[kind], sample)

    def add_visual(self, inc: VisualIncrement) -> None:
        """Add one frame-to-frame increment (applied at its ``t1``; ``t0`` must be the previous frame;
        ``add("camera", inc)``)."""
        self.add("camera", inc)

    def take_increment(self, inc: VisualIncrement) -> None:
        """The camera's intake (``Live.take``), after the checks of :meth:`add`: the increment makes its node."""
        self._touch("visual", inc.t1)
        if self._late("camera", inc.t0 if inc.ok else inc.t1, back=0):
            return
        if not inc.ok:  # its frame is still a node, as in a batch run; counted missing when the node is made
            self._insert_visual(inc)
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
        # consumed by the first node at or after its t1; a re-timed one over several intervals re-does each of them
        after = bisect.bisect_right(self._t_nodes, inc.t0 + 1e-9)
        self._mark(self._t_nodes[after] if after < len(self._t_nodes) else inc.t1, inc.t1)
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
        if self._graph is not None and fix.t < self._t_nodes[-1] + 1e-3:  # iSAM2: onto a processed node
            self._late_fix(GpsFix(float(fix.t), enu, cov))
            self._advance(fix.t)
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
                merge_counts(total, part)
            return total

    def finish(self) -> FusionResult:
        """Process everything buffered and return the online trajectory (``ekf`` or ``gtsam_online``), its counts,
        notes and calibration (each estimated state at the newest node, with its σ)."""
        with self._lock:
            return self._finish()

    def _finish(self) -> FusionResult:
        self._finishing = True
        self._process(np.inf)
        self._collect(wait=True)
        name = "ekf" if self.backend == "ekf" else "gtsam_online"
        result = FusionResult()
        if self._t_nodes:
            result.trajectories[name] = PoseData(np.array(self._t_nodes), np.array(self._poses))
            result.covariances[name] = np.array(self._covs)
        counts = self.counts
        result.counts[name] = counts
        result.calibration[name] = self._calibration()
        result.notes = node_outage_notes(self._t_nodes, self._covered) + list(self._notes)
        result.consistency = list(self._consistency)
        if "gps" in self.sensors:
            gps = counts.get("gps", SensorCount())
            reacquire = self._graph.reacquire if self._graph is not None else self._gps_reacquire
            reacquired = [] if reacquire is None else reacquire.times
            result.notes.append(f"{name}: gps {gps.used} fixes used, {gps.gated} rejected (gate or bad values)"
                                + reacquired_text(reacquired, self._t_nodes[0] if self._t_nodes else 0.0)
                                + "; world frame: " + ("ENU at the datum" if self._frame == "enu" else
                                                       "the start frame (the fixes never fixed the heading of ENU)"))
            result.notes.extend(self._outages[t] for t in sorted(self._outages))
        if self._t_nodes:
            episodes = self._monitor.all_episodes(self._t_nodes[-1])
            result.inconsistent = [ep.as_dict() for ep in episodes]
            result.notes.extend("live monitor: " + ep.note(self._t_nodes[0]) for ep in episodes)
        for clock in self._clocks:
            text = clock.note(self._t_nodes[0] if self._t_nodes else 0.0)
            if text is not None:
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


def time_ordered_messages(streams: SensorStreams, camera_delay: float = 0.0) -> list[tuple[float, str, object]]:
    """The samples of ``streams`` as ``(arrival time, kind, message)`` in arrival order.

    Each sensor's data become samples through its :class:`~fusion_vo.sensors.registry.Live` intake (``samples``);
    ``kind`` is the intake's ``message`` name, which :meth:`StreamingFusion.feed` adds to the sensor (the camera's
    are ``visual``, the odometry's ``twist``: the ``add_<kind>`` methods). Samples arrive at their own time, the
    visual increments ``camera_delay`` seconds after their ``t1`` (frontend latency); samples arriving together
    keep the order of their intakes' ``order``, then of the registry.
    """
    msgs: list[tuple[float, float, str, object]] = []
    for sensor in registry.sensors():
        live, data = sensor.live, streams.get(sensor.name)
        if live is None or live.samples is None or not _has_samples(data):
            continue
        delay = camera_delay if sensor.name == "camera" else 0.0
        kind = live.message or sensor.name
        msgs += [(t + delay, live.order, kind, m) for t, m in live.samples(data)]
    msgs.sort(key=lambda m: (m[0], m[1]))
    return [(float(m[0]), m[2], m[3]) for m in msgs]


def _has_samples(data) -> bool:
    """Whether a sensor's data is there (not None, and not an empty list of increments)."""
    return data is not None and not (isinstance(data, (list, tuple)) and not data)


def streaming_for(streams: SensorStreams, backend: str = "ekf", config: FusionConfig | dict | None = None,
                  **kwargs) -> StreamingFusion:
    """A :class:`StreamingFusion` for the sensors and calibrations of ``streams`` (keyword arguments pass on)."""
    sensors = [sensor.name for sensor in registry.sensors()
               if sensor.live is not None and _has_samples(streams.get(sensor.name))]
    if streams.gps is not None:
        kwargs.setdefault("gps_lever_arm", streams.gps.lever_arm)
    imu = streams.imu
    return StreamingFusion(backend, config, sensors, wheel_config=None if streams.wheel is None else streams.wheel.config,
                           imu_T_BS=None if imu is None else imu.T_BS, imu_noise=None if imu is None else imu.noise,
                           camera_height=streams.camera_height, camera_height_sigma=streams.camera_height_sigma,
                           range_height_sigma=streams.range_height_sigma if streams.range_in_visual else None,
                           camera_frame_errors=any(inc.frame_covariance is not None for inc in streams.visual or ()),
                           **kwargs)


