"""``fusion-vo ros2-play``: a bag's or a recording's messages published with their own stamps, and ``/clock``.

Sources:

* a ROS bag (ROS 1 ``.bag``, ROS 2 folder, ``.mcap`` or ``.db3``, read with rosbags as ``import-bag`` does):
  every topic whose message type the installed ROS 2 Python packages know is published under its own name
  and type (the others are listed and left out), its messages copied field by field (a ROS 1 header's
  ``seq`` has no ROS 2 field and is dropped);
* a recording folder (:class:`~fusion_vo.recording.Recording`): ``cam0`` as ``image`` (``sensor_msgs/Image``,
  mono8 or mono16), ``imu0`` as ``imu/data``, ``wheel0`` as ``wheel_ticks`` (the node's
  ``std_msgs/Int64MultiArray`` layout), ``odom0`` as ``odom`` (child frame ``base_link``), ``range0`` as
  ``range`` and ``gps0`` as ``gps/fix`` (status and east-north covariance as the recording holds them): the
  node's own input names, so no remapping is needed.

Pacing: message ``k`` is published at ``wall_0 + (t_k - t_0) / speed`` (``speed`` 0: as fast as possible),
where ``t`` is the bag's recording time (a recording's sample time). ``/clock`` (``rosgraph_msgs/Clock``,
for nodes with ``use_sim_time``) carries that time every ``1 / clock_rate`` seconds of it (before the
first message that reaches the next step), and for ``tail`` seconds after the last message so that
timers on the simulated clock fire past the end; a subscriber's clock thus trails the stamps by at most
one step. Publishers are reliable with a deep history (so that a
burst at high speed is queued, not lost, for a reliable subscriber). ``--ros-args -r FROM:=TO`` remaps the
published topics.
"""

from __future__ import annotations

import heapq
import importlib
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Image, Imu, NavSatFix, Range
from std_msgs.msg import Int64MultiArray

from fusion_vo.errors import InputError
from fusion_vo.recording import Recording
from fusion_vo.recording.rosbag.reader import opened, one_line
from fusion_vo.ros2 import conversions as conv
from fusion_vo.sensors.gps import has_fixes, read_fixes
from fusion_vo.sensors.imu import read_imu
from fusion_vo.sensors.range import read_range
from fusion_vo.sensors.wheel import read_ticks, read_twist

log = logging.getLogger(__name__)

#: seconds waited after the player sees its subscribers: discovery is two-sided, and a best-effort
#: subscriber drops what comes from a publisher it has not matched yet
DISCOVERY_GRACE = 0.5
#: bag topics never replayed: the player publishes its own clock
SKIPPED_TOPICS = ("/clock",)


@dataclass
class PlaySummary:
    published: dict[str, int] = field(default_factory=dict)  # topic -> messages
    left_out: dict[str, str] = field(default_factory=dict)  # topic -> why
    span_s: float = 0.0
    wall_s: float = 0.0


def is_bag(source: Path) -> bool:
    return (source.is_dir() and (source / "metadata.yaml").is_file()) or source.suffix in (".bag", ".mcap", ".db3")


def message_class(msgtype: str):
    """The rclpy class of ``pkg/msg/Type`` (None when its package is not installed)."""
    pkg, _, name = msgtype.partition("/msg/")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except (ImportError, AttributeError):
        return None


def to_ros(obj, cls):
    """A rosbags message copied into the rclpy message class ``cls`` (fields ``cls`` lacks are dropped)."""
    msg = cls()
    for name, slot in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES):
        if not hasattr(obj, name):
            continue
        value = getattr(obj, name)
        current = getattr(msg, name)
        if hasattr(current, "get_fields_and_field_types"):
            setattr(msg, name, to_ros(value, type(current)))
        elif isinstance(value, list) and value and hasattr(value[0], "__msgtype__"):
            inner = message_class(value[0].__msgtype__)
            setattr(msg, name, [to_ros(v, inner) for v in value])
        elif isinstance(value, np.ndarray) and value.dtype == np.uint8:
            setattr(msg, name, value.tobytes())
        else:
            setattr(msg, name, value)
    return msg


def bag_topics(path: Path, summary: PlaySummary) -> dict[str, type]:
    """Topic -> rclpy class of the bag's publishable topics (the others go to ``summary.left_out``)."""
    topics = {}
    with opened(path) as reader:
        for c in reader.connections:
            cls = message_class(c.msgtype)
            if c.topic in SKIPPED_TOPICS:
                summary.left_out[c.topic] = "the player publishes its own /clock"
            elif cls is None:
                summary.left_out[c.topic] = f"{c.msgtype}: its ROS 2 Python package is not installed"
            else:
                topics[c.topic] = cls
    if not topics:
        raise InputError("no topic the installed ROS 2 message packages can publish", path)
    return topics


def bag_messages(path: Path, topics: dict[str, type]) -> Iterator[tuple[float, str, type, object]]:
    """``(time [s], topic, class, message)`` of the bag's ``topics`` in recording order."""
    with opened(path) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        classes = {c.id: topics[c.topic] for c in conns}
        stream = iter(reader.messages(connections=conns))
        while True:
            try:
                conn, t_ns, raw = next(stream)
                msg = to_ros(reader.deserialize(raw, conn.msgtype), classes[conn.id])
            except StopIteration:
                return
            except Exception as exc:  # a damaged bag fails in rosbags or its decompressors in many ways
                raise InputError(f"cannot read the bag ({one_line(exc)})", path) from None
            yield t_ns * 1e-9, conn.topic, classes[conn.id], msg


def recording_messages(path: Path) -> Iterator[tuple[float, str, type, object]]:
    """``(time [s], topic, class, message)`` of a recording folder's streams, merged in time order (the streams
    but the camera's are read, and checked, before this returns; frames are decoded as they are played)."""
    rec = Recording(path)
    streams = []

    def header(msg, t, frame):
        conv.set_stamp(msg.header.stamp, t)
        msg.header.frame_id = frame
        return msg

    if rec.has("cam0"):
        def frames():
            for f in rec.frames():
                if f.image is None:
                    log.warning("frame %d left out: %s", f.index, f.error)
                    continue
                img = np.ascontiguousarray(f.image)
                msg = header(Image(), f.t, "camera")
                msg.height, msg.width = img.shape
                msg.encoding = "mono16" if img.dtype == np.uint16 else "mono8"
                msg.step = img.shape[1] * img.itemsize
                msg.data = img.tobytes()
                yield f.t, "image", Image, msg
        streams.append(frames())
    if rec.has("imu0"):
        d = read_imu(rec)

        def imu():
            for k, t in enumerate(d.t):
                msg = header(Imu(), t, "imu")
                (msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z) = (float(v) for v in d.gyro[k])
                (msg.linear_acceleration.x, msg.linear_acceleration.y,
                 msg.linear_acceleration.z) = (float(v) for v in d.accel[k])
                if d.orientation is not None:
                    q = d.orientation[k]
                    msg.orientation.w, msg.orientation.x, msg.orientation.y, msg.orientation.z = (float(v) for v in q)
                else:
                    msg.orientation_covariance[0] = -1.0
                yield float(t), "imu/data", Imu, msg
        streams.append(imu())
    if rec.has("wheel0"):
        w = read_ticks(rec)

        def wheel():
            for t, left, right in zip(w.t, w.left, w.right):
                ns = int(round(float(t) * 1e9))
                yield float(t), "wheel_ticks", Int64MultiArray, Int64MultiArray(
                    data=[ns // 1_000_000_000, ns % 1_000_000_000, int(left), int(right)])
        streams.append(wheel())
    if rec.has("odom0"):
        o = read_twist(rec)

        def odom():
            for t, vx, vy, wz in zip(o.t, o.vx, o.vy, o.wz):
                msg = header(Odometry(), t, "odom")
                msg.child_frame_id = "base_link"
                msg.twist.twist.linear.x, msg.twist.twist.linear.y, msg.twist.twist.angular.z = float(vx), float(vy), float(wz)
                yield float(t), "odom", Odometry, msg
        streams.append(odom())
    if rec.has("range0"):
        r = read_range(rec)

        def ranges():
            for t, d in zip(r.t, r.distance):
                msg = header(Range(), t, "range")
                msg.radiation_type, msg.min_range, msg.max_range, msg.range = Range.INFRARED, 0.0, 100.0, float(d)
                yield float(t), "range", Range, msg
        streams.append(ranges())
    if has_fixes(rec):
        g = read_fixes(rec)

        def gps():
            for k, t in enumerate(g.t):
                msg = header(NavSatFix(), t, "gps")
                msg.latitude, msg.longitude, msg.altitude = (float(v) for v in g.geodetic[k])
                msg.status.status = int(g.status[k])
                c = g.covariance[k]
                msg.position_covariance = [float(c[0, 0]), float(c[0, 1]), 0.0, float(c[1, 0]), float(c[1, 1]), 0.0,
                                           0.0, 0.0, 1e6]
                msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_KNOWN
                yield float(t), "gps/fix", NavSatFix, msg
        streams.append(gps())
    if not streams:
        raise InputError("the recording has none of cam0/, imu0/, wheel0/, odom0/, range0/, gps0/", path)
    return heapq.merge(*streams, key=lambda m: m[0])


class Player(Node):
    """Publishes ``(time, topic, class, message)`` at ``speed`` with ``/clock``."""

    def __init__(self, topics: dict[str, type], clock: bool = True, depth: int = 1000):
        super().__init__("fusion_vo_player")
        self.qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)
        self.pubs = {topic: self.create_publisher(cls, topic, self.qos) for topic, cls in topics.items()}
        self.clock_pub = self.create_publisher(Clock, "/clock", self.qos) if clock else None
        self._clock_t = -np.inf

    def wait_for_subscribers(self, timeout: float, stop) -> list[str]:
        """Wait until every topic has a subscriber (at most ``timeout`` s), then :data:`DISCOVERY_GRACE` s more
        for the subscribers to match this publisher in turn; the topics still without one."""
        end = time.monotonic() + timeout
        while True:
            missing = [p.topic_name for p in self.pubs.values() if p.get_subscription_count() == 0]
            if not missing or time.monotonic() >= end or stop.is_set():
                break
            time.sleep(0.05)
        if len(missing) < len(self.pubs):
            stop.wait(DISCOVERY_GRACE)
        return missing

    def tick(self, t: float, step: float = 0.0) -> None:
        """Publish ``/clock`` at ``t`` if it is at least ``step`` seconds past the last one published."""
        if self.clock_pub is not None and t >= self._clock_t + step:
            self._clock_t = t
            msg = Clock()
            conv.set_stamp(msg.clock, t)
            self.clock_pub.publish(msg)

    def play(self, messages, speed: float, clock_rate: float, tail: float, stop, summary: PlaySummary) -> None:
        """Publish until the messages end or ``stop`` (an Event) is set."""
        wall0 = t0 = None
        step = 1.0 / clock_rate
        t = None
        for t, topic, cls, msg in messages:
            if stop.is_set():
                return
            if t0 is None:
                wall0, t0 = time.perf_counter(), t
                self.tick(t)
            self._wait_until(t, t0, wall0, speed, step, stop)
            self.tick(t, step)
            self.pubs[topic].publish(msg)
            summary.published[topic] = summary.published.get(topic, 0) + 1
        if t is None:
            return
        summary.span_s = t - t0
        self._wait_until(t + tail, t0, wall0, speed if speed > 0 else 1.0, step, stop)
        summary.wall_s = time.perf_counter() - wall0

    def _wait_until(self, t: float, t0: float, wall0: float, speed: float, step: float, stop) -> None:
        """Sleep until ``t``'s wall time, publishing ``/clock`` every ``step`` of simulated time meanwhile."""
        if speed <= 0:
            return
        while not stop.is_set():
            now = time.perf_counter()
            sim = t0 + (now - wall0) * speed
            if sim >= t:
                return
            self.tick(sim, step)
            time.sleep(min(step / speed, (t - sim) / speed))


#: what a recording folder's streams are published as
RECORDING_TOPICS = {"cam0": ("image", Image), "imu0": ("imu/data", Imu), "wheel0": ("wheel_ticks", Int64MultiArray),
                    "odom0": ("odom", Odometry), "range0": ("range", Range), "gps0": ("gps/fix", NavSatFix)}


def source_topics(source: Path, summary: PlaySummary) -> dict[str, type]:
    """Topic -> message class of what ``source`` (a bag or a recording folder) will publish."""
    if not source.exists():
        raise InputError("not found (give a ROS bag or a recording folder)", source)
    if is_bag(source):
        return bag_topics(source, summary)
    topics = dict(RECORDING_TOPICS[s] for s in Recording(source).streams() if s in RECORDING_TOPICS)
    if not topics:
        raise InputError("neither a ROS bag nor a recording with cam0/, imu0/, wheel0/, odom0/, range0/ or gps0/",
                         source)
    return topics


def messages_of(source: Path, topics: dict[str, type]):
    return bag_messages(source, topics) if is_bag(source) else recording_messages(source)
