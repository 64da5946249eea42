"""Streaming use: add measurements as they arrive, read the current estimate.

::

    fusion = StreamingFusion(backend="ekf", sensors=["camera", "wheel", "imu"], wheel_config=cfg,
                             camera_height=0.095)
    for msg in messages:                       # any order within the reorder window
        fusion.add_wheel(WheelTicks(t, left, right))   # or add_visual / add_imu / add_twist / add_range
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
"""

from __future__ import annotations

import bisect
import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np

from fusion_vo.backends.batch import as_config
from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.ekf import PlanarEkf, interval_measurements, step_blocks
from fusion_vo.backends.result import FusionResult, SensorCount
from fusion_vo.backends.timeline import SENSORS, SensorStreams, build_intervals
from fusion_vo.errors import InputError
from fusion_vo.measurements import (
    GpsData, GpsFix, ImuData, ImuSample, PoseData, RangeData, RangeSample, TwistData, TwistSample, VisualIncrement, WheelConfig,
    WheelData, WheelTicks,
)

logger = logging.getLogger(__name__)

#: streams whose counts are reported under the backends' sensor names
_COUNTED_AS = {"imu": "gyro", "odom": "wheel"}


@dataclass
class Estimate:
    """The current estimate: time [s], pose ``(x, y, yaw)`` of B in W, its 3x3 covariance."""

    t: float
    pose: np.ndarray
    covariance: np.ndarray
    frame: str = "start"


class StreamingFusion:
    """Incremental fusion for embedding in a larger localization stack.

    Parameters
    ----------
    backend : str
        ``"ekf"`` or ``"gtsam"`` (iSAM2).
    config : FusionConfig or dict, optional
    sensors : list of str
        The sensors that will be added (of ``camera, wheel, odom, imu, range``).
    wheel_config : WheelConfig, optional
        Needed for ``add_wheel``.
    imu_T_BS : ndarray (4, 4), optional
        IMU pose in the body frame (default identity).
    imu_noise : dict, optional
        EuRoC noise keys of ``imu0/sensor.yaml``.
    camera_height : float, optional
        Height the visual increments assume (needed for ``range``).
    gps_lever_arm : array_like, optional
        Antenna position in the body frame [m] (``gps0/sensor.yaml`` ``T_BS``), for ``add_gps``
        (default: at the body origin).
    """

    def __init__(self, backend: str = "ekf", config: FusionConfig | dict | None = None,
                 sensors=("camera", "wheel", "imu"), wheel_config: WheelConfig | None = None,
                 imu_T_BS: np.ndarray | None = None, imu_noise: dict | None = None, camera_height: float | None = None,
                 gps_lever_arm=None):
        if backend not in ("ekf", "gtsam"):
            raise InputError(f"streaming backend must be 'ekf' or 'gtsam', not '{backend}'")
        self.config = as_config(config)
        if imu_noise:
            self.config = dataclasses.replace(self.config, imu=self.config.imu.with_sensor_keys(imu_noise))
        self.backend = backend
        self.sensors = list(sensors)
        bad = [s for s in self.sensors if s not in SENSORS]
        if bad:
            raise InputError(f"unknown sensor '{bad[0]}' (use {', '.join(SENSORS)})")
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
        self.counts: dict[str, SensorCount] = {}
        self._buffers: dict[str, list] = {name: [] for name in ("wheel", "odom", "imu", "range")}
        self._visual: list[VisualIncrement] = []
        self._latest = -np.inf
        self._t_nodes: list[float] = []
        self._poses: list[np.ndarray] = []
        self._covs: list[np.ndarray] = []
        self._heading_offset: float | None = None
        self._notes: list[str] = []
        self._ekf: PlanarEkf | None = None
        self._graph = None
        from fusion_vo.sensors.gps import GpsModel

        lever = np.zeros(3) if gps_lever_arm is None else np.asarray(gps_lever_arm, dtype=np.float64).ravel()
        self._gps_model = GpsModel(lever, self.config.gps)
        self._gps_lever = lever
        self._gps: list[GpsFix] = []  # pending fixes, in time order
        self._gps_seen: list[GpsFix] = []  # fixes before the world frame was aligned
        self._frame = "start"
        self._gps_reacquire = None
        self._gps_bad = 0

    # ------------------------------------------------------------------ input
    def add_visual(self, inc: VisualIncrement) -> None:
        self._check("camera")
        if self._late("camera", inc.t1):
            return
        if not inc.ok:
            self._count("camera").missing += 1
            self._advance(inc.t1)
            return
        self._insert_visual(inc)
        self._advance(inc.t1)

    def add_wheel(self, m: WheelTicks) -> None:
        self._add("wheel", m.t, (int(m.left), int(m.right)))

    def add_twist(self, m: TwistSample) -> None:
        self._add("odom", m.t, (m.vx, m.vy, m.wz))

    def add_imu(self, m: ImuSample) -> None:
        q = None if m.orientation is None else np.asarray(m.orientation, dtype=np.float64)
        self._add("imu", m.t, (np.asarray(m.gyro, dtype=np.float64), np.asarray(m.accel, dtype=np.float64), q))

    def add_range(self, m: RangeSample) -> None:
        self._add("range", m.t, float(m.distance))

    def add_gps(self, fix: GpsFix) -> None:
        """One fix (east, north in ENU at the datum, 2x2 covariance); a non-finite or non-positive-definite
        one is counted as gated."""
        self._check("gps")
        if self._late("gps", fix.t):
            return
        enu = np.asarray(fix.enu, dtype=np.float64).ravel()[:2]
        cov = np.asarray(fix.covariance, dtype=np.float64).reshape(2, 2)
        if not (np.all(np.isfinite(enu)) and np.all(np.isfinite(cov))) or np.any(np.linalg.eigvalsh(0.5 * (cov + cov.T)) <= 0):
            self._gps_bad += 1
            self._count("gps").gated += 1
            return
        if self._gps and fix.t < self._gps[-1].t:
            self._count("gps").reordered += 1
        bisect.insort(self._gps, GpsFix(float(fix.t), enu, cov), key=lambda f: f.t)
        self._advance(fix.t)

    # ------------------------------------------------------------------ output
    def current_estimate(self) -> Estimate | None:
        """The latest processed node's estimate, or None before the first node."""
        if not self._t_nodes:
            return None
        return Estimate(self._t_nodes[-1], self._poses[-1].copy(), self._covs[-1].copy(), self._frame)

    def finish(self) -> FusionResult:
        """Process everything buffered and return the online trajectory (``ekf`` or ``gtsam_online``)."""
        self._process(np.inf)
        name = "ekf" if self.backend == "ekf" else "gtsam_online"
        result = FusionResult()
        if self._t_nodes:
            result.trajectories[name] = PoseData(np.array(self._t_nodes), np.array(self._poses))
            result.covariances[name] = np.array(self._covs)
        result.counts[name] = self.counts
        result.notes = list(self._notes)
        if "gps" in self.sensors:
            m = self._gps_model
            self._notes.append(f"ekf: gps {m.n_used} fixes used, {m.n_rejected} rejected by the gate; world frame: "
                               + ("ENU at the datum" if self._frame == "enu" else
                                  "the start frame (the fixes never fixed the heading of ENU)"))
        late = {s: c.late for s, c in self.counts.items() if c.late}
        if late:
            result.notes.append("late measurements not applied: " + ", ".join(f"{s} {n}" for s, n in late.items()))
        return result

    # ------------------------------------------------------------------ buffering
    def _check(self, sensor: str) -> None:
        if sensor not in self.sensors and not (sensor == "odom" and "wheel" in self.sensors):
            raise InputError(f"sensor '{sensor}' was not declared (sensors={self.sensors})")

    def _count(self, sensor: str) -> SensorCount:
        return self.counts.setdefault(sensor, SensorCount())

    def _late(self, sensor: str, t: float) -> bool:
        if not np.isfinite(t):
            self._count(sensor).gated += 1
            return True
        if self._t_nodes and t < self._t_nodes[-1] - 1e-9:
            self._count(sensor).late += 1
            logger.warning("%s measurement at t=%.3f arrived after t=%.3f was processed; not applied",
                           sensor, t, self._t_nodes[-1])
            return True
        return False

    def _add(self, stream: str, t: float, payload) -> None:
        self._check(stream)
        sensor = _COUNTED_AS.get(stream, stream)
        if self._late(sensor, t):
            return
        buf = self._buffers[stream]
        if buf and t < buf[-1][0]:
            self._count(sensor).reordered += 1
        bisect.insort(buf, (float(t), payload), key=lambda item: item[0])
        self._advance(t)

    def _insert_visual(self, inc: VisualIncrement) -> None:
        if self._visual and inc.t1 < self._visual[-1].t1:
            self._count("camera").reordered += 1
        bisect.insort(self._visual, inc, key=lambda v: v.t1)

    def _advance(self, t: float) -> None:
        self._latest = max(self._latest, float(t))
        self._process(self._latest - self.config.reorder_window)

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

    def _process(self, until: float) -> None:
        if not self._t_nodes:
            start = self._start_time()
            if start is None or start > until:
                return
            self._first_node(start)
        while True:
            t0 = self._t_nodes[-1]
            t1 = self._next_node(t0, until if np.isfinite(until) else self._last_time())
            if t1 is None:
                return
            self._step(t0, t1)

    def _last_time(self) -> float:
        times = [b[-1][0] for b in self._buffers.values() if b] + [v.t1 for v in self._visual]
        return max(times) if times else -np.inf

    def _streams_between(self, t0: float, t1: float) -> SensorStreams:
        margin = self.config.max_gap
        streams = SensorStreams(camera_height=self.camera_height)
        for name, buf in self._buffers.items():
            lo = max(bisect.bisect_left(buf, t0 - margin, key=lambda item: item[0]) - 1, 0)
            hi = bisect.bisect_right(buf, t1 + margin, key=lambda item: item[0]) + 1
            rows = buf[lo:hi]
            if len(rows) < (1 if name == "range" else 2):
                continue
            t = np.array([r[0] for r in rows])
            if name == "wheel":
                ticks = np.array([r[1] for r in rows], dtype=np.int64)
                streams.wheel = WheelData(t, ticks[:, 0], ticks[:, 1], self.wheel_config)
            elif name == "odom":
                v = np.array([r[1] for r in rows])
                streams.odom = TwistData(t, v[:, 0], v[:, 1], v[:, 2])
            elif name == "imu":
                q = [r[1][2] for r in rows]
                streams.imu = ImuData(t, np.array([r[1][0] for r in rows]), np.array([r[1][1] for r in rows]),
                                      None if any(x is None for x in q) else np.array(q), self.imu_T_BS,
                                      None, self.imu_noise)
            else:
                streams.range = RangeData(t, np.array([r[1] for r in rows]))
        return streams

    def _step(self, t0: float, t1: float) -> None:
        streams = self._streams_between(t0, t1)
        usable = [v for v in self._visual if abs(v.t1 - t1) < 1e-9 and abs(v.t0 - t0) < 1e-9]
        for v in self._visual:
            if v.t1 <= t1 + 1e-9 and v not in usable:
                self._count("camera").late += 1
        self._visual = [v for v in self._visual if v.t1 > t1 + 1e-9]
        if usable:
            streams.visual = usable
        iv = build_intervals(streams, self.config, np.array([t0, t1]), self._heading_offset)
        if iv.heading_offset is not None:
            self._heading_offset = iv.heading_offset
        for sensor, c in iv.counts.items():
            own = self._count(sensor)
            own.gated += c.gated
            own.missing += c.missing
        if self.backend == "ekf":
            self._ekf_step(iv)
        else:
            self._graph_step(iv)
        self._t_nodes.append(t1)
        self._prune(t0)

    def _prune(self, t0: float) -> None:
        keep_from = t0 - 2.0 * self.config.max_gap
        for name, buf in self._buffers.items():
            cut = bisect.bisect_left(buf, keep_from, key=lambda item: item[0]) - 2
            if cut > 0:
                del buf[:cut]

    def _calibration_flags(self) -> tuple[bool, bool]:
        s = set(self.sensors)
        wheel = bool(s & {"wheel", "odom"})
        return "camera" in s and (wheel or "range" in s), wheel and bool(s & {"camera", "imu"})

    # ------------------------------------------------------------------ backends
    def _first_node(self, t: float) -> None:
        cfg = self.config
        self._t_nodes.append(t)
        kv, kb = self._calibration_flags()
        if self.backend == "ekf":
            twist = "odom" in self.sensors and "wheel" not in self.sensors
            self._ekf = PlanarEkf(cfg, self.camera_height, kv, kb, twist)
            self._record(self._ekf.x[:3], self._ekf.P[:3, :3])
        else:
            self._graph = _OnlineGraph(cfg, t, (kv, kb))
            pose, cov = self._graph.start()
            self._record(pose, cov)

    def _record(self, pose, cov) -> None:
        self._poses.append(np.asarray(pose, dtype=np.float64).copy())
        self._covs.append(np.asarray(cov, dtype=np.float64).copy())

    def _ekf_step(self, iv) -> None:
        ekf = self._ekf
        meas = interval_measurements(iv, self.config)
        ekf.predict(float(iv.dt[0]))
        ekf.update(step_blocks(ekf, meas, 0))
        t1 = float(iv.t[-1])
        for fix in [f for f in self._gps if f.t <= t1 + 1e-3]:
            self._gps.remove(fix)
            if abs(fix.t - t1) > 1e-3:  # behind the last node already: cannot be applied causally
                self._count("gps").late += 1
            else:
                self._apply_gps(fix)
        for sensor, c in ekf.counts.items():
            own = self._count(sensor)
            own.used += c.used
            own.gated += c.gated
        ekf.counts = {}
        self._record(ekf.x[:3], ekf.P[:3, :3])

    def _apply_gps(self, fix: GpsFix) -> None:
        from fusion_vo.backends.ekf import YAW, GpsReacquire
        from fusion_vo.backends.world import prior_from_alignment
        from fusion_vo.sensors.gps import align_to_fixes

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
                self._count("gps").missing += 1  # kept for the alignment, not applied
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
            self._poses = [p for p in fit.apply(np.array(self._poses))]
            self._covs = [rot @ cv @ rot.T for cv in self._covs]
            self._frame = "enu"
            if self._heading_offset is not None:  # AHRS north was aligned to the start frame's heading
                self._heading_offset -= fit.yaw
            self._gps_reacquire = GpsReacquire(self.config.gps_reacquire)
            self._notes.append(f"gps: world frame re-expressed in ENU at t={fix.t:.2f} (first heading "
                               f"{math.degrees(float(self._poses[0][2])):.2f} deg ± {math.degrees(fit.yaw_sigma):.2f})")
        accepted = ekf.gps_update(model, fix.enu, fix.covariance, fix.t)
        if not accepted and self._gps_reacquire.due(fix.t, False):
            ekf.gps_reacquire(model, fix.enu, fix.covariance, fix.t)
        elif accepted:
            self._gps_reacquire.due(fix.t, True)
        count = self._count("gps")
        count.used, count.gated = model.n_used, model.n_rejected + self._gps_bad

    def _graph_step(self, iv) -> None:
        pose, cov, sensors = self._graph.step(iv)
        for s in sensors:
            self._count(s).used += 1
        self._record(pose, cov)


class _OnlineGraph:
    """iSAM2 fed one node interval at a time through :class:`~fusion_vo.backends.graph.GraphBuilder`."""

    def __init__(self, config: FusionConfig, t_origin: float, calibrate: tuple[bool, bool]):
        import gtsam

        from fusion_vo.backends import graph

        self.gtsam = gtsam
        self.graph = graph
        self.config = config
        self.t_origin = t_origin
        self.calibrate = calibrate
        self.isam = gtsam.ISAM2(graph.isam_params())
        self.n = 0
        self.estimate: dict = {}
        self.prev_pose = gtsam.Pose2(*config.initial_pose)

    def _update(self, nf):
        g = self.gtsam.NonlinearFactorGraph()
        lookup = self.graph.current_value_lookup(nf.values, self.isam, self.prev_pose, self.n - 1)
        for f in self.graph.freeze_custom_factors(nf.factors, lookup):
            g.add(f)
        values = self.gtsam.Values()
        self.graph.insert_values(values, nf.values)
        self.isam.update(g, values)
        key = self.graph.X(self.n)
        pose = self.isam.calculateEstimatePose2(key)
        self.prev_pose = pose
        cov = self.graph.world_covariances(np.array([pose.theta()]), self.isam.marginalCovariance(key)[None])[0]
        return np.array([pose.x(), pose.y(), pose.theta()]), cov

    def start(self):
        cfg = self.config
        # the first node's own factors come with the first interval (which knows the sensors)
        self._pending_first = True
        return np.asarray(cfg.initial_pose, dtype=np.float64), np.diag([1e-8, 1e-8, 1e-8])

    def step(self, iv):
        builder = self.graph.GraphBuilder(iv, self.config, offset=self.n, t_origin=self.t_origin,
                                          calibrate=self.calibrate)
        if self._pending_first:
            first = builder.first_node()
            nf = builder.node(1, self.prev_pose, self.estimate)
            first.factors.extend(nf.factors)
            first.values.update(nf.values)
            first.sensors = nf.sensors
            nf = first
            self._pending_first = False
        else:
            nf = builder.node(1, self.prev_pose, self.estimate)
        self.n += 1
        pose, cov = self._update(nf)
        self.graph.track_estimate(self.estimate, self.isam, builder, 1, nf)
        return pose, cov, nf.sensors
