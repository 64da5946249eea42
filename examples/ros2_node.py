"""Embedding :class:`~fusion_vo.backends.streaming.StreamingFusion` in a ROS 2 node (documented example).

rclpy and the ROS message packages come with a ROS 2 installation, not from PyPI, so this file is
an example to adapt, not part of the test suite. It shows the pattern a localisation stack needs:

* sensor callbacks (wheel odometry, IMU, and the visual increments of a ground-camera frontend) hand
  their samples to one ``StreamingFusion``; with a ``MultiThreadedExecutor`` and a reentrant callback
  group they run on several threads at once, which ``StreamingFusion`` allows (every call takes its
  lock; see the module documentation);
* a 50 Hz timer asks for the pose *of now* (``current_estimate(t)``: the filtered state predicted to
  the requested time, its covariance grown accordingly) and publishes it as ``nav_msgs/Odometry`` in
  the ``odom`` frame;
* late data (the camera frontend typically delivers an increment 100-200 ms after its frame) is
  re-applied by the EKF from its 2 s history, so the node does not need to delay anything itself;
* nothing from the data raises into a callback: NaN, far-future stamps and samples older than the
  history are counted (``fusion.counts``) and logged, and the node reports the counts on shutdown.

Run (inside a sourced ROS 2 workspace, with fusion-vo installed in the same Python)::

    python examples/ros2_node.py --ros-args -p wheel_odom_topic:=/odom -p imu_topic:=/imu/data

The visual increments come from a frontend running in this process or another; ``add_increment`` is
the hook (a frame-to-frame similarity ``(dx, dy, dyaw)`` of the body with its 3x3 covariance, from
:mod:`fusion_vo.odometry`).
"""

from __future__ import annotations

import gc
import math
import sys

import numpy as np

try:
    import rclpy
    from nav_msgs.msg import Odometry
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.node import Node
    from sensor_msgs.msg import Imu
except ImportError:  # pragma: no cover - documented example
    sys.exit("examples/ros2_node.py needs a ROS 2 installation (rclpy, nav_msgs, sensor_msgs); "
             "source its setup script first")

from fusion_vo.backends import FusionConfig, StreamingFusion
from fusion_vo.errors import InputError
from fusion_vo.measurements import ImuSample, TwistSample, VisualIncrement


def stamp_seconds(stamp) -> float:
    """A ROS ``builtin_interfaces/Time`` in seconds (the clock every input must share)."""
    return stamp.sec + stamp.nanosec * 1e-9


class GroundCameraOdometry(Node):
    """Wheel odometry + IMU + ground-camera increments fused into a 50 Hz pose of now."""

    def __init__(self):
        super().__init__("fusion_vo")
        self.declare_parameter("wheel_odom_topic", "/odom")
        self.declare_parameter("imu_topic", "/imu/data")
        self.declare_parameter("output_topic", "/fusion_vo/odom")
        self.declare_parameter("backend", "ekf")  # "gtsam": iSAM2 (a late camera only within the window)
        self.declare_parameter("rate", 50.0)
        self.declare_parameter("camera_height", 0.095)  # [m] height the visual increments assume
        self.declare_parameter("camera_height_sigma", 0.001)  # [m] how well that height is known
        p = self.get_parameter
        self.fusion = StreamingFusion(
            p("backend").value,
            FusionConfig(reorder_window=0.05),  # the EKF re-filters anything later from its history
            sensors=["camera", "odom", "imu"],
            camera_height=p("camera_height").value,
            camera_height_sigma=p("camera_height_sigma").value,  # the visual scale's prior, as height_sigma
            history=2.0,  # seconds of states kept to re-apply late measurements
            horizon=0.5,  # largest prediction beyond the newest sample; also the future-stamp limit
        )
        group = ReentrantCallbackGroup()  # callbacks may run concurrently: StreamingFusion is thread-safe
        self.create_subscription(Odometry, p("wheel_odom_topic").value, self.on_wheel_odom, 50,
                                 callback_group=group)
        self.create_subscription(Imu, p("imu_topic").value, self.on_imu, 200, callback_group=group)
        self.publisher = self.create_publisher(Odometry, p("output_topic").value, 10)
        self.create_timer(1.0 / p("rate").value, self.publish_pose, callback_group=group)

    # ---------------------------------------------------------------- inputs (any thread)
    def on_wheel_odom(self, msg: Odometry) -> None:
        tw = msg.twist.twist
        self.fusion.add_twist(TwistSample(stamp_seconds(msg.header.stamp), tw.linear.x, tw.linear.y, tw.angular.z))

    def on_imu(self, msg: Imu) -> None:
        g, a, q = msg.angular_velocity, msg.linear_acceleration, msg.orientation
        orientation = None if msg.orientation_covariance[0] < 0 else np.array([q.w, q.x, q.y, q.z])
        self.fusion.add_imu(ImuSample(stamp_seconds(msg.header.stamp), np.array([g.x, g.y, g.z]),
                                      np.array([a.x, a.y, a.z]), orientation))

    def add_increment(self, t0: float, t1: float, delta: np.ndarray, covariance: np.ndarray) -> None:
        """Called by the camera frontend's thread for each frame pair (frame times on the ROS clock)."""
        self.fusion.add_visual(VisualIncrement(t0, t1, np.asarray(delta), np.asarray(covariance)))

    # ---------------------------------------------------------------- output (timer)
    def publish_pose(self) -> None:
        now = self.get_clock().now().nanoseconds * 1e-9
        try:
            est = self.fusion.current_estimate(now)  # predicted to now (within the horizon)
        except InputError:
            est = self.fusion.current_estimate()  # inputs stalled: the newest measurement time
        if est is None:
            return
        msg = Odometry()
        msg.header.frame_id, msg.child_frame_id = "odom", "base_link"
        msg.header.stamp.sec = int(est.t)
        msg.header.stamp.nanosec = int(round((est.t - int(est.t)) * 1e9)) % 1_000_000_000
        x, y, yaw = est.pose
        msg.pose.pose.position.x, msg.pose.pose.position.y = float(x), float(y)
        msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        cov = np.zeros((6, 6))  # ROS order x, y, z, roll, pitch, yaw
        idx = [0, 1, 5]
        cov[np.ix_(idx, idx)] = est.covariance
        cov[2, 2] = cov[3, 3] = cov[4, 4] = 1e6  # not estimated: planar motion
        msg.pose.covariance = cov.ravel().tolist()
        self.publisher.publish(msg)

    def report(self) -> None:
        for sensor, c in self.fusion.counts.items():
            self.get_logger().info(f"{sensor}: {c.as_dict()}")


def main() -> None:
    rclpy.init()
    node = GroundCameraOdometry()
    executor = MultiThreadedExecutor(num_threads=3)
    executor.add_node(node)
    # everything made so far (the imported modules: some 100 000 objects) leaves the garbage collector's
    # scans; otherwise a full collection stalls whichever callback it falls in by about 40 ms
    # (benchmarks/bench_latency.py --gc-freeze)
    gc.collect()
    gc.freeze()
    try:
        executor.spin()
    except KeyboardInterrupt:
        pass
    finally:
        node.report()
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
