"""ROS messages to the fusion's samples (no DDS: message classes only), as import-bag reads them."""

import math

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ros2 extra is not installed (pip install \"fusion-vo[ros2]\")")

from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import Image, Imu, NavSatFix, Range  # noqa: E402
from std_msgs.msg import Int64MultiArray  # noqa: E402

from fusion_vo.backends.streaming import Estimate  # noqa: E402
from fusion_vo.recording.gps import geodetic_to_enu  # noqa: E402
from fusion_vo.ros2 import conversions as conv  # noqa: E402
from fusion_vo.ros2.diagnostics import TopicStats, input_status  # noqa: E402

pytestmark = pytest.mark.ros2


def test_imu_orientation_only_where_its_covariance_says_it_is_valid():
    m = Imu()
    m.orientation.w, m.orientation.z = math.cos(0.3), math.sin(0.3)
    m.angular_velocity.z = 0.2
    s = conv.imu_sample(m, 5.0)
    assert s.t == 5.0 and s.gyro[2] == 0.2 and s.orientation is not None
    m.orientation_covariance[0] = -1.0
    assert conv.imu_sample(m, 5.0).orientation is None
    m.orientation_covariance[0] = 0.0
    m.orientation.w = 0.5  # norm 0.65: not an orientation
    assert conv.imu_sample(m, 5.0).orientation is None


def test_gps_status_and_covariance_as_import_bag_reads_them():
    gps = conv.GpsConverter({"datum": None, "sigma": 2.5, "lever_arm": np.zeros(3)})
    m = NavSatFix()
    m.latitude, m.longitude, m.altitude = 48.0, 11.0, 500.0
    m.status.status = -1
    with pytest.raises(conv.Skipped):
        gps.fix(m, 1.0)
    m.status.status = 0
    first = gps.fix(m, 1.0)  # no covariance given: horizontal_sigma_m, the datum at the first fix
    np.testing.assert_allclose(first.enu, 0.0, atol=1e-6)
    np.testing.assert_allclose(first.covariance, np.eye(2) * 6.25)
    m.latitude = 48.0001
    m.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
    m.position_covariance = [0.04, 0.0, 0.0, 0.0, 0.09, 0.0, 0.0, 0.0, 1.0]
    second = gps.fix(m, 2.0)
    np.testing.assert_allclose(second.enu, geodetic_to_enu([48.0001], [11.0], [500.0], (48.0, 11.0, 500.0))[0, :2])
    np.testing.assert_allclose(second.covariance, np.diag([0.04, 0.09]))


def test_wheel_ticks_layout_odometry_frame_range_limits_and_images():
    w = conv.wheel_ticks(Int64MultiArray(data=[12, 500_000_000, 1000, -20]))
    assert (w.t, w.left, w.right) == (12.5, 1000, -20)
    with pytest.raises(conv.Unusable, match="expected 4"):
        conv.wheel_ticks(Int64MultiArray(data=[1, 2, 3]))
    o = Odometry(child_frame_id="base_link")
    o.twist.twist.linear.x, o.twist.twist.angular.z = 0.4, 0.1
    assert conv.twist_sample(o, 3.0, "base_link").vx == 0.4
    with pytest.raises(conv.Unusable, match="child_frame_id 'wheels'"):
        conv.twist_sample(Odometry(child_frame_id="wheels"), 3.0, "base_link")
    r = Range(min_range=0.02, max_range=2.0, range=0.1)
    assert conv.range_sample(r, 1.0).distance == 0.1
    with pytest.raises(conv.Skipped):
        conv.range_sample(Range(min_range=0.02, max_range=2.0, range=3.0), 1.0)
    img = Image(height=2, width=3, encoding="bgr8", step=9, data=bytes(range(18)))
    assert conv.grey_image(img, 3, 2).shape == (2, 3)
    with pytest.raises(conv.Unusable, match="the calibration's 4x2"):
        conv.grey_image(img, 4, 2)
    with pytest.raises(conv.Unusable, match="'32FC1' is not supported"):
        conv.grey_image(Image(height=2, width=3, encoding="32FC1", step=12, data=bytes(24)), 3, 2)
    check = conv.FrameCheck()
    check.check("imu_link")
    with pytest.raises(conv.Unusable, match="frame 'base_link', not 'imu_link'"):
        check.check("base_link")


def test_the_published_odometry_carries_pose_and_twist_covariances():
    est = Estimate(12.25, np.array([1.0, 2.0, 0.5]), np.diag([0.01, 0.02, 0.003]), twist=np.array([0.3, 0.0, 0.1]),
                   twist_covariance=np.diag([1e-4, 2e-4, 3e-4]))
    m = conv.odometry_message(est, "odom", "base_link")
    assert (m.header.stamp.sec, m.header.stamp.nanosec) == (12, 250_000_000)
    assert m.pose.pose.position.x == 1.0 and 2 * math.atan2(m.pose.pose.orientation.z, m.pose.pose.orientation.w) == \
        pytest.approx(0.5)
    cov = np.array(m.pose.covariance).reshape(6, 6)
    assert (cov[0, 0], cov[1, 1], cov[5, 5], cov[2, 2]) == (0.01, 0.02, 0.003, conv.UNESTIMATED_VARIANCE)
    tw = np.array(m.twist.covariance).reshape(6, 6)
    assert m.twist.twist.linear.x == 0.3 and (tw[0, 0], tw[5, 5]) == (1e-4, 3e-4)


def test_a_topics_messages_stamped_before_an_earlier_one_are_counted_out_of_order():
    stats = TopicStats("odom", "/odom")
    for t in (1.0, 2.0, 1.5, 2.0, 3.0, 0.5):  # 1.5 and 0.5 came after a newer stamp; 2.0 twice is in order
        stats.arrived(t)
    assert stats.out_of_order == 2 and stats.newest == 3.0
    values = {kv.key: kv.value for kv in input_status(stats, {}).values}
    assert values["out_of_order"] == "2"
