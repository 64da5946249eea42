"""The ``fusion_vo`` node: ROS 2 inputs into :class:`~fusion_vo.backends.streaming.StreamingFusion`, its pose out.

Topics (relative names: ``--ros-args -r imu/data:=/my/imu`` remaps them)::

    in   image               sensor_msgs/Image            camera (live visual odometry, own thread)
    in   imu/data            sensor_msgs/Imu              imu
    in   odom                nav_msgs/Odometry            odom (its twist)
    in   wheel_ticks         std_msgs/Int64MultiArray     wheel ([stamp_sec, stamp_nanosec, left, right])
    in   gps/fix             sensor_msgs/NavSatFix        gps
    in   range               sensor_msgs/Range            range
    out  odometry/filtered   nav_msgs/Odometry            at publish_rate, predicted to the time of publication
    out  odometry/smoothed   nav_msgs/Odometry            smoothed_lag behind (backend gtsam, smoothed_lag > 0)
    out  diagnostics         diagnostic_msgs/DiagnosticArray   every diagnostics_period (:mod:`.diagnostics`)

Only the inputs of the configured sensors are subscribed. Inputs use the sensor-data QoS (best effort,
volatile, the last ``queue_depth`` messages), which takes both best-effort and reliable publishers; the
outputs are reliable. The callbacks are short (a message's conversion); they run on one executor thread,
which takes the ready subscriptions in turn, so a burst on one topic waits in its own queue and a stalled
topic holds up nothing. The fusion is fed on a thread of its own, in stamp order across the inputs
(:mod:`.intake`), and the camera's frontend on another behind a bounded queue (:mod:`.camera`); the fusion
takes one lock per call and re-applies data that comes late within its history. The timers only ask a
third thread for their output (:class:`~fusion_vo.ros2.intake.Outputs`), which waits for that lock, so
the executor never does. (rclpy's multi-threaded executor took about a sixth of the
messages per second its single-threaded one did on this 2-core machine, and lost the rest from the
queues.)

Time: a message's time is its header stamp (a zero stamp: its arrival on the node's clock, logged once);
the node's clock follows ``/clock`` with ``use_sim_time``. The node gates stamps on its clock: a message
stamped more than ``horizon`` seconds ahead of it is counted (``future``) and dropped, so a stray
far-future stamp cannot make every later message late, and a gap in the inputs (a pause, lost messages)
does not make the ones after it look like far-future ones (the fusion itself is given no horizon). Each
published pose is ``current_estimate(now)``: the filtered state predicted to the node's clock; when the
clock is more than ``horizon`` away from the newest measurement (inputs stalled, or a bag played without
``use_sim_time``) it is the estimate at the newest measurement, published once, and diagnostics say the
inputs stalled.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, Imu, NavSatFix, Range
from std_msgs.msg import Int64MultiArray

from fusion_vo.recording import write_tum
from fusion_vo.ros2 import conversions as conv
from fusion_vo.ros2.camera import CameraPipeline
from fusion_vo.ros2.intake import Intake, Outputs
from fusion_vo.ros2.diagnostics import TopicStats, diagnostic_array, estimate_status, input_status
from fusion_vo.ros2.sensors import sensor_setup, streaming_fusion, visual_odometry
from fusion_vo.ros2.settings import load_settings

log = logging.getLogger(__name__)

#: sensor -> the names the fusion counts its data under
COUNTED = {"camera": ("camera",), "imu": ("gyro", "ahrs"), "odom": ("wheel",), "wheel": ("wheel",), "gps": ("gps",),
           "range": ("range",)}
#: sensor -> (input topic, message type)
INPUTS = {"camera": ("image", Image), "imu": ("imu/data", Imu), "odom": ("odom", Odometry),
          "wheel": ("wheel_ticks", Int64MultiArray), "gps": ("gps/fix", NavSatFix), "range": ("range", Range)}


class FusionNode(Node):
    """The node; ``config`` is the configuration file (or None), its ROS parameters override it.

    Raises
    ------
    InputError
        At construction, for an unknown parameter, a configuration the schema rejects, or a calibration
        that cannot be read; no subscription exists then.
    """

    def __init__(self, config=None):
        super().__init__("fusion_vo", allow_undeclared_parameters=True,
                         automatically_declare_parameters_from_overrides=True)
        names = self.list_parameters([], 0).names
        params = {p.name: p.value for p in self.get_parameters(names)}
        self.settings = load_settings(config, params)
        self.setup = sensor_setup(self.settings)
        self.fusion = streaming_fusion(self.settings, self.setup)
        node = self.settings.node
        self.camera = None
        if "camera" in self.setup.sensors:
            self.camera = CameraPipeline(visual_odometry(self.settings, self.setup), self.fusion, node.image_queue,
                                         self.setup.camera_noise)
        self.intake = Intake(self.fusion)
        self.gps = conv.GpsConverter(self.setup.gps) if self.setup.gps is not None else None
        self.frames = {"imu": conv.FrameCheck(node.imu_frame), "camera": conv.FrameCheck(node.camera_frame),
                       "gps": conv.FrameCheck(node.gps_frame), "range": conv.FrameCheck(node.range_frame)}
        self.stats: dict[str, TopicStats] = {}
        self.stamped_on_arrival = 0
        self.published = 0
        self._last_t = -math.inf
        self._last_smoothed = -math.inf
        self._predicted: float | None = None
        self._predicted_max = 0.0
        sensor_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=node.queue_depth,
                                reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
        out_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)
        handlers = {"camera": self._on_image, "imu": self._on_imu, "odom": self._on_odom, "wheel": self._on_wheel,
                    "gps": self._on_gps, "range": self._on_range}
        image_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(node.image_queue, 10),
                               reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
        for sensor in self.setup.sensors:
            topic, kind = INPUTS[sensor]
            sub = self.create_subscription(kind, topic, handlers[sensor], image_qos if sensor == "camera" else sensor_qos)
            self.stats[sensor] = TopicStats(sensor, sub.topic_name)
        self.pub = self.create_publisher(Odometry, "odometry/filtered", out_qos)
        self.diag_pub = self.create_publisher(DiagnosticArray, "diagnostics", out_qos)
        self.outputs = Outputs({"pose": self._publish, "diagnostics": self._diagnose,
                                "smoothed": self._publish_smoothed})
        self.create_timer(1.0 / node.publish_rate, lambda: self.outputs.request("pose", self._now()))
        # diagnostics on the steady clock: they go on while a played bag's /clock stands still
        self.create_timer(node.diagnostics_period, lambda: self.outputs.request("diagnostics", self._now()),
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.smoothed_pub = None
        if node.smoothed_lag > 0:
            self.smoothed_pub = self.create_publisher(Odometry, "odometry/smoothed", out_qos)
            self.create_timer(1.0 / node.smoothed_rate, lambda: self.outputs.request("smoothed"))

    # ------------------------------------------------------------------ inputs
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _time(self, header) -> float:
        t = conv.stamp_seconds(header.stamp)
        if t > 0:
            return t
        self.stamped_on_arrival += 1
        if self.stamped_on_arrival == 1:
            log.warning("a message without a header stamp: its arrival time on the node's clock is used")
        return self._now()

    def _take(self, sensor: str, convert, t: float | None = None, frame: str | None = None) -> None:
        """Convert one message and hand it to the fusion, counting whatever becomes of it; never raises."""
        stats = self.stats[sensor]
        stats.received += 1
        try:
            if frame is not None:
                self.frames[sensor].check(frame)
            sample = convert()
            t = sample.t if t is None else t
            now = self._now()
            if now > 0 and t > now + self.settings.node.horizon:
                stats.future += 1
                return
            if sensor == "camera":
                self.camera.put(t, sample.image)
            else:
                stats.arrived(t)
                self.intake.put(t, sensor, sample)
        except conv.Unusable as exc:
            stats.reject(str(exc))
        except conv.Skipped:
            stats.skipped += 1
        except Exception as exc:  # nothing from one message may stop the node
            stats.reject(f"internal error: {type(exc).__name__}: {exc}")
            log.debug("traceback", exc_info=True)

    def _on_imu(self, msg) -> None:
        t = self._time(msg.header)
        self._take("imu", lambda: conv.imu_sample(msg, t), t, msg.header.frame_id)

    def _on_odom(self, msg) -> None:
        t = self._time(msg.header)
        self._take("odom", lambda: conv.twist_sample(msg, t, self.settings.node.base_frame), t)

    def _on_wheel(self, msg) -> None:
        self._take("wheel", lambda: conv.wheel_ticks(msg))

    def _on_gps(self, msg) -> None:
        t = self._time(msg.header)
        self._take("gps", lambda: self.gps.fix(msg, t), t, msg.header.frame_id)

    def _on_range(self, msg) -> None:
        t = self._time(msg.header)
        self._take("range", lambda: conv.range_sample(msg, t), t, msg.header.frame_id)

    def _on_image(self, msg) -> None:
        t = self._time(msg.header)
        cam = self.setup.camera
        self._take("camera", lambda: _Frame(conv.grey_image(msg, cam.width, cam.height)), t, msg.header.frame_id)

    # ------------------------------------------------------------------ outputs
    def _publish(self, now: float) -> None:
        newest = self.fusion.current_estimate() if now > 0 else None
        if newest is None:
            return
        est = newest
        if abs(now - newest.t) <= self.settings.node.horizon:
            est = self.fusion.current_estimate(now)
        if est.t <= self._last_t:
            return
        self._last_t = est.t
        self._predicted = est.predicted
        self._predicted_max = max(self._predicted_max, est.predicted)
        self.pub.publish(conv.odometry_message(est, self.settings.node.odom_frame, self.settings.node.base_frame))
        self.published += 1

    def _publish_smoothed(self) -> None:
        newest = self.fusion.current_estimate()
        if newest is None:
            return
        est = self.fusion.smoothed_estimate(newest.t - newest.predicted - self.settings.node.smoothed_lag)
        if est is None or est.t <= self._last_smoothed:
            return
        self._last_smoothed = est.t
        self.smoothed_pub.publish(conv.odometry_message(est, self.settings.node.odom_frame, self.settings.node.base_frame))

    def _diagnose(self, now: float) -> None:
        counts = self.fusion.counts
        statuses = []
        for sensor, stats in self.stats.items():
            fused = {name: counts[name].as_dict() for name in COUNTED[sensor] if name in counts}
            statuses.append(input_status(stats, fused, self.camera if sensor == "camera" else None))
        newest = self.fusion.current_estimate()
        age = None if newest is None or now <= 0 else now - newest.t
        statuses.append(estimate_status(self.settings.backend, "none" if newest is None else newest.frame,
                                        self.published, age, self._predicted, self._predicted_max, self.fusion.rewinds,
                                        self.fusion.inconsistent(), self.settings.node.horizon))
        self.diag_pub.publish(diagnostic_array(statuses, lambda stamp: conv.set_stamp(stamp, max(now, 0.0))))

    # ------------------------------------------------------------------ shutdown
    def close(self) -> list[str]:
        """Stop the camera and intake threads; lines summing up what each input brought."""
        if self.camera is not None:
            self.camera.stop()
        self.intake.stop()
        self.outputs.stop()
        lines = []
        if self.settings.node.trajectory_file:
            lines.append(self._write_track(Path(self.settings.node.trajectory_file)))
        counts = self.fusion.counts
        for sensor, stats in self.stats.items():
            fused = "; ".join(f"{name} " + ", ".join(f"{k} {v}" for k, v in counts[name].as_dict().items() if v)
                              for name in COUNTED[sensor] if name in counts)
            lines.append(f"{stats.topic}: {stats.received} received" +
                         (f", {stats.unusable} unusable ({stats.unusable_reason})" if stats.unusable else "") +
                         (f", {stats.skipped} skipped" if stats.skipped else "") +
                         (f", {stats.future} stamped in the future" if stats.future else "") +
                         (f"; fusion: {fused}" if fused else ""))
        lines.append(f"{self.published} poses published on {self.pub.topic_name}")
        return lines

    def _write_track(self, path: Path) -> str:
        result = self.fusion.finish()
        name = "ekf" if self.settings.backend == "ekf" else "gtsam_online"
        track = result.trajectories.get(name)
        if track is None or not len(track):
            return f"no pose to write to {path}"
        write_tum(path, track.t, track.xyyaw)
        return f"online track of {len(track)} poses written to {path}"


class _Frame:
    """A converted image on its way to the camera thread (its time is the message's)."""

    __slots__ = ("image",)

    def __init__(self, image):
        self.image = image
