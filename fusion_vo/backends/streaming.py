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
"""

from __future__ import annotations

import bisect
import dataclasses
import logging
from dataclasses import dataclass

import numpy as np

from fusion_vo.backends.batch import as_config
from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.ekf import PlanarEkf, interval_measurements, step_blocks
from fusion_vo.backends.result import FusionResult, SensorCount
from fusion_vo.backends.timeline import SENSORS, SensorStreams, build_intervals
from fusion_vo.errors import InputError
from fusion_vo.measurements import (
    ImuData, ImuSample, PoseData, RangeData, RangeSample, TwistData, TwistSample, VisualIncrement, WheelConfig,
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
    """

    def __init__(self, backend: str = "ekf", config: FusionConfig | dict | None = None,
                 sensors=("camera", "wheel", "imu"), wheel_config: WheelConfig | None = None,
                 imu_T_BS: np.ndarray | None = None, imu_noise: dict | None = None, camera_height: float | None = None):
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

    # ------------------------------------------------------------------ output
    def current_estimate(self) -> Estimate | None:
        """The latest processed node's estimate, or None before the first node."""
        if not self._t_nodes:
            return None
        return Estimate(self._t_nodes[-1], self._poses[-1].copy(), self._covs[-1].copy())

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
        if frames and frames[0] <= after + 1.5 * step:
            return frames[0] if frames[0] <= until else None
        fill = after + step
        return fill if fill <= until else None

    def _start_time(self) -> float | None:
        times = [b[0][0] for b in self._buffers.values() if b] + [v.t0 for v in self._visual]
        return min(times) if times else None

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
        for sensor, c in ekf.counts.items():
            own = self._count(sensor)
            own.used += c.used
            own.gated += c.gated
        ekf.counts = {}
        self._record(ekf.x[:3], ekf.P[:3, :3])

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
