"""The tests' ROS 2 peer: starts ``fusion-vo ros2`` in a subprocess, drives it, records what it publishes.

Run only inside a loopback-only network namespace (``dds_namespace.run_peer`` does that). Usage::

    python peer.py SPEC_JSON OUT_JSON

``SPEC_JSON`` is a JSON object: ``node`` (arguments after ``fusion-vo``), optionally ``play`` (arguments of a
``fusion-vo`` player run once the node is ready), ``inject`` (true: publish the bad-input sequence of
:func:`inject`), ``settle`` (seconds to wait after that), ``signal`` (``SIGINT`` or ``SIGTERM``, sent to stop
the node). ``OUT_JSON`` receives the node's exit code, output and shutdown time, the poses it published
(``odometry/filtered``, ``odometry/smoothed``) and its last diagnostics.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Clock
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, Imu

FUSION_VO = [sys.executable, "-m", "fusion_vo.cli.main"]


class Recorder(Node):
    def __init__(self):
        super().__init__("fusion_vo_test_peer")
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.poses, self.smoothed, self.diagnostics = [], [], None
        self.filtered = self.create_subscription(Odometry, "/odometry/filtered",
                                                 lambda m: self.poses.append(_pose(m)), qos)
        self.create_subscription(Odometry, "/odometry/smoothed", lambda m: self.smoothed.append(_pose(m)), qos)
        self.create_subscription(DiagnosticArray, "/diagnostics", self._diag, qos)
        self.clock_t = None
        self.create_subscription(Clock, "/clock", lambda m: setattr(self, "clock_t", _seconds(m.clock)), qos)
        self.clock = self.create_publisher(Clock, "/clock", qos)
        self.imu = self.create_publisher(Imu, "/imu/data", qos)
        self.odom = self.create_publisher(Odometry, "/odom", qos)
        self.image = self.create_publisher(Image, "/image", qos)

    def _diag(self, msg) -> None:
        self.diagnostics = {s.name: {"level": int.from_bytes(s.level, "little") if isinstance(s.level, bytes)
                                     else int(s.level), "message": s.message,
                                     **{kv.key: kv.value for kv in s.values}} for s in msg.status}


def _pose(m) -> dict:
    q = m.pose.pose.orientation
    return {"received": time.time(), "t": m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
            "frame": m.header.frame_id, "child": m.child_frame_id,
            "x": m.pose.pose.position.x, "y": m.pose.pose.position.y, "yaw": 2 * math.atan2(q.z, q.w),
            "var": [m.pose.covariance[0], m.pose.covariance[7], m.pose.covariance[35]],
            "twist": [m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.angular.z],
            "twist_var": [m.twist.covariance[0], m.twist.covariance[7], m.twist.covariance[35]]}


def _seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def received(diagnostics) -> int:
    """Messages the node took so far, or -1 while its camera still has frames waiting."""
    statuses = (diagnostics or {}).values()
    if any(s.get("queue", "0") != "0" for s in statuses):
        return -1
    return sum(int(s.get("received", 0)) for s in statuses)


def until_quiet(peer: Recorder, quiet: float = 1.0, timeout: float = 90.0) -> float:
    """Wait until the node has taken no message and its camera has had no frame waiting or being measured
    for ``quiet`` seconds, as told by diagnostics that came at the end of those seconds (they come on the
    steady clock; a node too busy to send them is not quiet). While waiting, a simulated clock left by a
    player goes on at real speed, so that the node's timers fire while it catches up with a backlog.
    Returns the seconds waited."""
    start = last_change = last_heard = time.time()
    seen = peer.diagnostics
    count = received(seen)
    clock0 = peer.clock_t
    while last_heard - last_change < quiet and time.time() - start < timeout:
        time.sleep(0.02)
        if clock0 is not None:
            msg = Clock()
            _stamp_time(msg.clock, clock0 + time.time() - start)
            peer.clock.publish(msg)
        if peer.diagnostics is not seen:
            seen, last_heard = peer.diagnostics, time.time()
            now = received(seen)
            if now != count or now < 0:
                count, last_change = now, last_heard
    return time.time() - start


def _stamp_time(stamp, t: float) -> None:
    ns = int(round(t * 1e9))
    stamp.sec, stamp.nanosec = ns // 1_000_000_000, ns % 1_000_000_000


def _stamp(msg, t: float) -> None:
    ns = int(round(t * 1e9))
    msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 1_000_000_000, ns % 1_000_000_000


def _imu(t, frame="imu", gyro_z=0.1):
    m = Imu()
    _stamp(m, t)
    m.header.frame_id = frame
    m.angular_velocity.z = gyro_z
    m.linear_acceleration.z = 9.81
    m.orientation_covariance[0] = -1.0
    return m


def _odom(t, child="base_link", vx=0.5, wz=0.1):
    m = Odometry()
    _stamp(m, t)
    m.header.frame_id, m.child_frame_id = "odom", child
    m.twist.twist.linear.x, m.twist.twist.angular.z = vx, wz
    return m


def _image(t, encoding="mono8", width=640, height=360):
    m = Image()
    _stamp(m, t)
    m.header.frame_id = "camera"
    m.height, m.width, m.encoding = height, width, encoding
    m.step = width * (4 if encoding == "32FC1" else 1)
    m.data = bytes(m.step * height)
    return m


def inject(peer: Recorder, log: dict) -> None:
    """Good IMU and odometry at 100 Hz on the wall clock, then each kind of bad message, then good data again."""

    def good(seconds: float) -> None:
        end = time.time() + seconds
        while time.time() < end:
            t = time.time()
            peer.imu.publish(_imu(t))
            peer.odom.publish(_odom(t))
            time.sleep(0.01)

    end = time.time() + 10.0  # the node's subscriptions matched in both directions before anything is sent
    while time.time() < end and min(p.get_subscription_count() for p in (peer.imu, peer.odom, peer.image)) == 0:
        time.sleep(0.05)
    time.sleep(0.5)
    good(2.0)
    t = time.time()
    log["bad_start"] = t
    for _ in range(5):
        m = _imu(time.time())
        m.angular_velocity.z = float("nan")
        peer.imu.publish(m)
    for k in range(3):
        peer.odom.publish(_odom(t + 1000.0 + k))  # far future
    for k in range(5):
        peer.odom.publish(_odom(t - 30.0 + 0.01 * k))  # older than the history
    now = time.time()
    peer.odom.publish(_odom(now))
    peer.odom.publish(_odom(now - 0.05))  # out of order, within the reorder window
    for _ in range(10):
        peer.imu.publish(_imu(time.time(), frame="elsewhere"))
        peer.odom.publish(_odom(time.time(), child="wheel_frame"))
        time.sleep(0.002)
    for _ in range(3):  # (paced: a best-effort burst of megabyte messages may lose fragments)
        peer.image.publish(_image(time.time(), encoding="32FC1", width=160, height=90))
        time.sleep(0.05)
    for _ in range(2):
        peer.image.publish(_image(time.time(), width=320, height=240))
        time.sleep(0.05)
    log["bad_end"] = time.time()
    good(1.5)


def main() -> int:
    spec = json.loads(open(sys.argv[1]).read())
    out: dict = {"spec": spec}
    rclpy.init()
    peer = Recorder()
    executor = SingleThreadedExecutor()
    executor.add_node(peer)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    proc = subprocess.Popen(FUSION_VO + spec["node"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))
    lines = {"stdout": [], "stderr": []}
    ready = threading.Event()

    def read(stream, name):
        for line in stream:
            lines[name].append(line.rstrip("\n"))
            if "running" in line:
                ready.set()

    readers = [threading.Thread(target=read, args=(proc.stdout, "stdout"), daemon=True),
               threading.Thread(target=read, args=(proc.stderr, "stderr"), daemon=True)]
    for r in readers:
        r.start()
    deadline = time.time() + 60
    while not ready.is_set() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    out["ready"] = ready.is_set()
    if ready.is_set():
        # discovery: the node's pose publisher matched to this recorder before any data reaches the node, so
        # that the first pose recorded is the node's first (a busy machine can take seconds)
        end = time.time() + 20.0
        while time.time() < end and peer.filtered.get_publisher_count() == 0:
            time.sleep(0.05)
        out["pose_publisher_matched"] = peer.filtered.get_publisher_count() > 0
        time.sleep(0.5)
        if spec.get("play"):
            player = subprocess.run(FUSION_VO + spec["play"], capture_output=True, text=True, timeout=300)
            out["player"] = {"code": player.returncode, "stdout": player.stdout, "stderr": player.stderr}
        if spec.get("inject"):
            inject(peer, out)
        out["waited_for_quiet"] = until_quiet(peer)
        time.sleep(spec.get("settle", 0.2))
        out["signal_sent"] = time.time()
        proc.send_signal(getattr(signal, spec.get("signal", "SIGINT")))
    try:
        proc.wait(timeout=spec.get("stop_timeout", 30))
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    out["exited"] = time.time()
    for r in readers:
        r.join(5)
    out.update(code=proc.returncode, stdout=lines["stdout"], stderr=lines["stderr"], poses=peer.poses,
               smoothed=peer.smoothed, diagnostics=peer.diagnostics)
    with open(sys.argv[2], "w") as f:
        json.dump(out, f, default=lambda v: v.tolist() if isinstance(v, np.ndarray) else str(v))
    # the peer's own teardown is not under test: rclpy may abort tearing down a context whose executor
    # still spins in another thread, so the process ends here, its results written
    sys.stdout.flush()
    os._exit(0)


if __name__ == "__main__":
    sys.exit(main())
