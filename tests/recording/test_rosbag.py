"""Importing ROS bags into the recording layout: two real ROS 1 bags and generated ROS 2 bags."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
import yaml
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from fusion_vo.cli.main import main
from fusion_vo.errors import InputError
from fusion_vo.recording import Recording
from fusion_vo.recording.rosbag import (
    StaticTransform,
    UnsupportedImage,
    chain_transform,
    compressed_to_grey,
    geodetic_to_enu,
    image_to_grey,
    import_bag,
    list_topics,
    parse_static_tf,
    ypr_to_matrix,
)
from fusion_vo.sensors.gps import read_fixes
from fusion_vo.sensors.imu import read_imu
from fusion_vo.sensors.wheel import read_twist

DATA = Path(__file__).resolve().parents[1] / "data" / "robot_localization"
JACKAL = DATA / "test2.bag"
HUSKY = DATA / "test1_140s_to_152s.bag"
HUSKY_IMU_TF = "0 -0.3 0.52 -1.570796327 0 1.570796327 base_link imu_link"


def read_csv(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", comments="#", ndmin=2)


# ------------------------------------------------------------------------------------ real bags
@pytest.fixture(scope="module")
def jackal(tmp_path_factory) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("jackal") / "seq"
    return out, import_bag(JACKAL, out)


@pytest.fixture(scope="module")
def husky(tmp_path_factory) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("husky") / "seq"
    return out, import_bag(HUSKY, out, static_tfs=[parse_static_tf(HUSKY_IMU_TF)])


def test_list_topics_of_the_jackal_bag():
    topics = {t.topic: t for t in list_topics(JACKAL)}
    assert set(topics) == {"/imu/data", "/jackal_velocity_controller/odom"}
    assert topics["/imu/data"].msgtype == "sensor_msgs/msg/Imu"
    assert topics["/imu/data"].count == 3061
    assert topics["/jackal_velocity_controller/odom"].count == 3060


def test_jackal_counts_rates_and_monotonic_time(jackal):
    out, summary = jackal
    imu, odom = summary.stream("imu0"), summary.stream("odom0")
    assert (imu.written, odom.written) == (3061, 3060)
    assert imu.duplicates == odom.duplicates == imu.dropped == odom.dropped == 0
    assert imu.rate_hz == pytest.approx(50.0, abs=0.5)
    assert odom.rate_hz == pytest.approx(50.0, abs=0.5)
    assert imu.duration_s == pytest.approx(61.2, abs=0.1)
    assert summary.stream("cam0") is None and summary.stream("gps0") is None
    for name in ("imu0/data.csv", "odom0/data.csv", "odom0/pose.csv"):
        t = read_csv(out / name)[:, 0].astype(np.int64)
        assert np.all(np.diff(t) > 0), name
    assert not list(out.parent.glob(".*part"))  # the temporary folder was renamed


def test_jackal_imu_has_the_ahrs_quaternion_and_reads_back(jackal):
    out, _ = jackal
    header = (out / "imu0" / "data.csv").read_text().splitlines()[0]
    assert header.endswith("q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []")
    rec = Recording(out)
    imu = read_imu(rec)
    assert imu.orientation is not None and imu.orientation.shape == (3061, 4)
    assert np.allclose(np.linalg.norm(imu.orientation, axis=1), 1.0, atol=1e-6)
    assert np.allclose(imu.T_BS, np.eye(4))  # the messages are in base_link already
    assert imu.rate_hz == pytest.approx(50.0, abs=0.5)
    # gravity along +z of a level robot
    assert np.mean(imu.accel[:, 2]) == pytest.approx(9.8, abs=0.3)


def test_jackal_values_round_trip(jackal):
    """Every 500th message read straight from the bag equals its row in the recording."""
    out, _ = jackal
    imu = read_csv(out / "imu0" / "data.csv")
    odom = read_csv(out / "odom0" / "data.csv")
    pose = read_csv(out / "odom0" / "pose.csv")
    rows = {"/imu/data": {int(r[0]): r for r in imu}, "/jackal_velocity_controller/odom": {int(r[0]): r for r in odom}}
    poses = {int(r[0]): r for r in pose}
    checked = 0
    with AnyReader([JACKAL]) as reader:
        for i, (conn, _, raw) in enumerate(reader.messages()):
            if i % 500:
                continue
            msg = reader.deserialize(raw, conn.msgtype)
            t = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            row = rows[conn.topic][t]
            if conn.topic == "/imu/data":
                w, a, q = msg.angular_velocity, msg.linear_acceleration, msg.orientation
                expect = [w.x, w.y, w.z, a.x, a.y, a.z, q.w, q.x, q.y, q.z]
            else:
                tw = msg.twist.twist
                expect = [tw.linear.x, tw.linear.y, tw.angular.z]
                p = msg.pose.pose
                assert poses[t][1:] == pytest.approx(
                    [p.position.x, p.position.y, p.position.z, p.orientation.w, p.orientation.x,
                     p.orientation.y, p.orientation.z], rel=1e-8, abs=1e-12)
            assert row[1:] == pytest.approx(expect, rel=1e-8, abs=1e-12)
            checked += 1
    assert checked >= 12


def test_husky_gps_local_enu_and_imu_mounting(husky):
    out, summary = husky
    gps = summary.stream("gps0")
    assert gps.written == 30 and gps.rate_hz == pytest.approx(2.5, abs=0.05)
    fixes = read_csv(out / "gps0" / "data.csv")
    assert np.allclose(fixes[0, 4:7], 0.0)
    enu = geodetic_to_enu(fixes[:, 1], fixes[:, 2], fixes[:, 3], fixes[0, 1:4])
    assert np.allclose(enu, fixes[:, 4:7], atol=1e-3)
    meta = yaml.safe_load((out / "gps0" / "sensor.yaml").read_text())
    assert meta["datum"]["latitude"] == pytest.approx(fixes[0, 1], abs=1e-9)
    # the fix's status and east-north covariance are kept, and the reader uses them
    with AnyReader([HUSKY]) as reader:
        conns = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/NavSatFix"]
        msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=conns)]
    cov = np.array([[m.position_covariance[0], m.position_covariance[1], m.position_covariance[4]] for m in msgs])
    assert fixes.shape[1] == 12
    np.testing.assert_allclose(fixes[:, 9:12], cov[: len(fixes)], rtol=1e-5)
    np.testing.assert_array_equal(fixes[:, 7], [m.status.status for m in msgs][: len(fixes)])
    data = read_fixes(Recording(out))
    assert len(data) == 30 and data.skipped == {}
    np.testing.assert_allclose(data.covariance[:, 0, 0], cov[:30, 0], rtol=1e-5)
    np.testing.assert_allclose(data.enu, fixes[:, 4:7], atol=1e-3)
    # the GPS track and the wheel odometry agree on the distance travelled (about 1 m/s for 12 s)
    odom = read_twist(Recording(out))
    wheel_dist = float(np.sum(odom.vx[:-1] * np.diff(odom.t)))
    gps_path = float(np.sum(np.hypot(*np.diff(fixes[:, 4:6], axis=0).T)))
    assert 9.0 < wheel_dist < 13.0
    assert gps_path == pytest.approx(wheel_dist, rel=0.25)
    # with the launch file's static transform, gravity and the yaw rate land on the body's z axis
    imu = read_imu(Recording(out))
    acc_b = imu.accel @ imu.T_BS[:3, :3].T
    gyro_b = imu.gyro @ imu.T_BS[:3, :3].T
    assert np.mean(acc_b[:, 2]) == pytest.approx(9.8, abs=0.4)
    yaw_gyro = float(np.sum(gyro_b[:-1, 2] * np.diff(imu.t)))
    yaw_odom = float(np.sum(odom.wz[:-1] * np.diff(odom.t)))
    assert abs(yaw_gyro) > 0.3 and yaw_gyro == pytest.approx(yaw_odom, rel=0.3)


def test_husky_without_static_tf_notes_identity(tmp_path):
    summary = import_bag(HUSKY, tmp_path / "seq")
    assert any("imu0 T_BS set to the identity" in n for n in summary.notes)
    assert np.allclose(read_imu(Recording(tmp_path / "seq")).T_BS, np.eye(4))


# ------------------------------------------------------------------------------------ geometry
def test_geodetic_to_enu_matches_the_ellipsoid_radii():
    lat0, lon0 = 42.0, -71.0
    a, e2 = 6378137.0, 0.0066943799901414
    s = math.sin(math.radians(lat0))
    meridian = a * (1 - e2) / (1 - e2 * s * s) ** 1.5
    normal = a / math.sqrt(1 - e2 * s * s)
    enu = geodetic_to_enu([lat0 + 1e-4, lat0, lat0], [lon0, lon0 + 1e-4, lon0], [0.0, 0.0, 10.0], (lat0, lon0, 0.0))
    assert enu[0] == pytest.approx([0.0, meridian * math.radians(1e-4), 0.0], abs=2e-3)
    assert enu[1] == pytest.approx([normal * math.cos(math.radians(lat0)) * math.radians(1e-4), 0.0, 0.0], abs=2e-3)
    assert enu[2] == pytest.approx([0.0, 0.0, 10.0], abs=1e-6)


def test_static_tf_convention_and_chain():
    tf = parse_static_tf(HUSKY_IMU_TF)
    assert (tf.parent, tf.child) == ("base_link", "imu_link")
    # IMU y axis (gravity reaction when mounted on its side) is the body's z axis
    assert tf.T[:3, :3] @ np.array([0.0, 1.0, 0.0]) == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)
    q = parse_static_tf("1 2 3 0 0 0.7071067811865476 0.7071067811865476 /odom base_link")
    assert q.T[:3, :3] == pytest.approx(ypr_to_matrix(math.pi / 2, 0, 0), abs=1e-9)
    arm = StaticTransform("base_link", "arm", np.array([[1, 0, 0, 1.0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    cam = StaticTransform("arm", "cam", np.array([[1, 0, 0, 0], [0, 1, 0, 2.0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    assert chain_transform([arm, cam], "base_link", "cam")[:3, 3] == pytest.approx([1.0, 2.0, 0.0])
    assert chain_transform([arm, cam], "cam", "base_link")[:3, 3] == pytest.approx([-1.0, -2.0, 0.0])
    assert chain_transform([arm], "base_link", "elsewhere") is None
    with pytest.raises(InputError):
        parse_static_tf("1 2 3 base_link imu")


# ------------------------------------------------------------------------------------ images
def _image_msg(img: np.ndarray, encoding: str, pad: int = 0, bigendian: bool = False) -> SimpleNamespace:
    h, w = img.shape[:2]
    raw = img.astype(img.dtype.newbyteorder(">" if bigendian else "<")).reshape(h, -1).view(np.uint8)
    raw = np.hstack([raw, np.zeros((h, pad), np.uint8)])
    return SimpleNamespace(encoding=encoding, height=h, width=w, step=raw.shape[1], is_bigendian=int(bigendian),
                           data=raw.reshape(-1))


def test_image_encodings_become_grey():
    rng = np.random.default_rng(1)
    bgr = rng.integers(0, 256, (6, 7, 3), dtype=np.uint8)
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    assert np.array_equal(image_to_grey(_image_msg(bgr, "bgr8", pad=3)), grey)
    assert np.array_equal(image_to_grey(_image_msg(bgr[:, :, ::-1].copy(), "rgb8")), grey)
    assert np.array_equal(image_to_grey(_image_msg(grey, "mono8", pad=5)), grey)
    deep = rng.integers(0, 65536, (4, 5), dtype=np.uint16)
    for big in (False, True):
        out = image_to_grey(_image_msg(deep, "mono16", pad=2, bigendian=big))
        assert out.dtype == np.uint16 and np.array_equal(out, deep)
    with pytest.raises(UnsupportedImage, match="not supported"):
        image_to_grey(_image_msg(deep.astype(np.float32), "32FC1"))
    with pytest.raises(ValueError, match="does not fit"):
        msg = _image_msg(grey, "mono8")
        msg.data = msg.data[:-1]
        image_to_grey(msg)
    ok, png = cv2.imencode(".png", bgr)
    assert np.array_equal(compressed_to_grey(SimpleNamespace(format="png", data=png.reshape(-1))), grey)
    with pytest.raises(ValueError, match="cannot decode"):
        compressed_to_grey(SimpleNamespace(format="jpeg", data=np.arange(50, dtype=np.uint8)))


# ------------------------------------------------------------------------------------ generated ROS 2 bags
T0 = 1_700_000_000_000_000_000


class Ros2Bag:
    """Writes a small ROS 2 bag (mcap) message by message."""

    def __init__(self, path: Path):
        self.ts = get_typestore(Stores.ROS2_HUMBLE)
        self.t = self.ts.types
        self.writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        self.conns = {}

    def __enter__(self):
        self.writer.open()
        return self

    def __exit__(self, *exc):
        self.writer.close()
        return False

    def header(self, t_ns: int, frame: str):
        return self.t["std_msgs/msg/Header"](
            stamp=self.t["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id=frame)

    def write(self, topic: str, msg, bag_t: int) -> None:
        if topic not in self.conns:
            self.conns[topic] = self.writer.add_connection(topic, msg.__msgtype__, typestore=self.ts)
        self.writer.write(self.conns[topic], bag_t, self.ts.serialize_cdr(msg, msg.__msgtype__))

    def vec(self, x, y, z):
        return self.t["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    def quat(self, w, x, y, z):
        return self.t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)

    def image(self, t_ns: int, img: np.ndarray):
        return self.t["sensor_msgs/msg/Image"](header=self.header(t_ns, "cam_optical"), height=img.shape[0],
                                               width=img.shape[1], encoding="mono8", is_bigendian=0,
                                               step=img.shape[1], data=img.reshape(-1))

    def imu(self, t_ns: int, gz: float, orientation: bool = False):
        cov = np.zeros(9) + (0.0 if orientation else -1.0)
        return self.t["sensor_msgs/msg/Imu"](
            header=self.header(t_ns, "imu"), orientation=self.quat(1.0, 0.0, 0.0, 0.0), orientation_covariance=cov,
            angular_velocity=self.vec(0.0, 0.0, gz), angular_velocity_covariance=np.full(9, 1e-4),
            linear_acceleration=self.vec(0.0, 0.0, 9.81), linear_acceleration_covariance=np.full(9, 1e-2))

    def fix(self, t_ns: int, lat: float, lon: float, status: int = 0):
        st = self.t["sensor_msgs/msg/NavSatStatus"](status=status, service=1)
        return self.t["sensor_msgs/msg/NavSatFix"](header=self.header(t_ns, "gps"), status=st, latitude=lat,
                                                   longitude=lon, altitude=10.0, position_covariance=np.eye(3).ravel(),
                                                   position_covariance_type=2)

    def camera_info(self, t_ns: int, w: int, h: int):
        roi = self.t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return self.t["sensor_msgs/msg/CameraInfo"](
            header=self.header(t_ns, "cam_optical"), height=h, width=w, distortion_model="plumb_bob",
            d=np.array([0.1, -0.05, 0.001, 0.002, 0.0]), k=np.array([100.0, 0, 16, 0, 101.0, 12, 0, 0, 1]),
            r=np.eye(3).ravel(), p=np.zeros(12), binning_x=0, binning_y=0, roi=roi)

    def tf_static(self, t_ns: int, parent: str, child: str, xyz, q_wxyz):
        tr = self.t["geometry_msgs/msg/Transform"](translation=self.vec(*xyz), rotation=self.quat(*q_wxyz))
        ts = self.t["geometry_msgs/msg/TransformStamped"](header=self.header(t_ns, parent), child_frame_id=child,
                                                          transform=tr)
        return self.t["tf2_msgs/msg/TFMessage"](transforms=[ts])


@pytest.fixture(scope="module")
def ros2_bag(tmp_path_factory) -> Path:
    """Camera at 10 Hz with CameraInfo and /tf_static, IMU at 100 Hz, GPS at 1 Hz, with planted faults."""
    path = tmp_path_factory.mktemp("ros2") / "synthetic"
    rng = np.random.default_rng(7)
    with Ros2Bag(path) as b:
        # camera 0.2 m ahead of base_link, 0.1 m up, looking straight down (half a turn about x)
        b.write("/tf_static", b.tf_static(0, "base_link", "cam_optical", (0.2, 0.0, 0.1), (0.0, 1.0, 0.0, 0.0)), T0)
        b.write("/cam/camera_info", b.camera_info(T0, 32, 24), T0)
        for i in range(20):
            t = T0 + i * 100_000_000
            b.write("/cam/image_raw", b.image(t, rng.integers(0, 256, (24, 32), dtype=np.uint8)), t + 5_000_000)
        b.write("/cam/image_raw", b.image(T0 + 500_000_000, np.zeros((24, 32), np.uint8)), T0 + 2_000_000_000)  # dup
        for i in range(200):
            t = T0 + i * 10_000_000
            b.write("/imu", b.imu(t, gz=0.1 * i), t + 1_000_000)
        b.write("/imu", b.imu(0, gz=99.0), T0 + 2_005_000_000)  # zero stamp: takes the bag time
        bad = b.imu(T0 + 2_010_000_000, gz=float("nan"))
        b.write("/imu", bad, T0 + 2_010_000_000)  # NaN: dropped
        for i in range(3):
            t = T0 + i * 1_000_000_000
            b.write("/gps/fix", b.fix(t, 48.0 + i * 1e-5, 11.0), t)
        b.write("/gps/fix", b.fix(T0 + 3_000_000_000, 0.0, 0.0, status=-1), T0 + 3_000_000_000)  # no fix
    return path


def test_ros2_bag_with_camera_imu_gps(ros2_bag, tmp_path):
    out = tmp_path / "seq"
    summary = import_bag(ros2_bag, out)
    cam, imu, gps = summary.stream("cam0"), summary.stream("imu0"), summary.stream("gps0")
    assert (cam.written, cam.duplicates, cam.rate_hz) == (20, 1, pytest.approx(10.0))
    assert (imu.written, imu.dropped, imu.bag_time_stamps) == (201, 1, 1)
    assert (gps.written, gps.dropped) == (3, 1)
    rec = Recording(out)
    frames = list(rec.frames())
    assert len(frames) == 20 and all(f.image is not None and f.image.shape == (24, 32) for f in frames)
    assert frames[5].image.any()  # the first image stamped 0.5 s was kept, not the black duplicate
    model = rec.camera
    assert (model.width, model.height, model.fu, model.cv) == (32, 24, 100.0, 12.0)
    assert model.distortion_model == "radial-tangential"
    assert np.allclose(model.T_BS[:3, 3], [0.2, 0.0, 0.1])
    assert np.allclose(model.T_BS[:3, :3], np.diag([1.0, -1.0, -1.0]))
    imu_data = read_imu(rec)
    assert imu_data.orientation is None  # orientation_covariance[0] == -1
    assert imu_data.gyro[-1, 2] == pytest.approx(99.0)  # the zero-stamped sample sorted by its bag time
    assert imu_data.gyro[150, 2] == pytest.approx(15.0)
    assert imu_data.noise["gyroscope_noise_density"] == pytest.approx(math.sqrt(1e-4 / 100.0), rel=1e-3)
    fixes = read_csv(out / "gps0" / "data.csv")
    assert fixes[:, 5] == pytest.approx([0.0, 1.1119, 2.2239], abs=2e-3)  # north, 1e-5 deg apart
    assert any("imu0 T_BS set to the identity" in n for n in summary.notes)


def test_camera_yaml_overrides_camera_info(ros2_bag, tmp_path):
    cam_yaml = tmp_path / "cam.yaml"
    cam_yaml.write_text("intrinsics: [50, 50, 16, 12]\ndistortion_model: none\n")
    import_bag(ros2_bag, tmp_path / "seq", camera_yaml=cam_yaml)
    model = Recording(tmp_path / "seq").camera
    assert (model.fu, model.width, model.height, model.rate_hz) == (50.0, 32, 24, pytest.approx(10.0))
    cam_yaml.write_text("resolution: [640, 480]\nintrinsics: [50, 50, 16, 12]\n")
    with pytest.raises(InputError, match="640x480"):
        import_bag(ros2_bag, tmp_path / "seq2", camera_yaml=cam_yaml)
    assert not (tmp_path / "seq2").exists() and not list(tmp_path.glob(".seq2*"))


def test_ambiguous_topics_need_a_choice(tmp_path, capsys):
    path = tmp_path / "two_cameras"
    rng = np.random.default_rng(3)
    frames = [rng.integers(0, 256, (12, 16, 3), dtype=np.uint8) for _ in range(3)]
    with Ros2Bag(path) as b:
        for i, img in enumerate(frames):
            t = T0 + i * 50_000_000
            b.write("/cam/image_raw", b.image(t, img[:, :, 0].copy()), t)
            png = cv2.imencode(".png", img)[1].reshape(-1)
            msg = b.t["sensor_msgs/msg/CompressedImage"](header=b.header(t, "cam"), format="png", data=png)
            b.write("/cam/image_raw/compressed", msg, t)
    with pytest.raises(InputError, match="choose one with --image-topic"):
        import_bag(path, tmp_path / "seq")
    summary = import_bag(path, tmp_path / "seq", image_topic="/cam/image_raw/compressed")
    assert summary.stream("cam0").written == 3
    assert any("give --camera-yaml" in n for n in summary.notes)  # no CameraInfo in this bag
    names = sorted((tmp_path / "seq" / "cam0" / "data").iterdir())
    for img, name in zip(frames, names):
        grey = cv2.imread(str(name), cv2.IMREAD_UNCHANGED)
        assert np.array_equal(grey, cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
    assert main(["import-bag", str(path), "--list"]) == 0
    listing = capsys.readouterr().out
    assert "/cam/image_raw/compressed" in listing and "sensor_msgs/msg/CompressedImage" in listing


# ------------------------------------------------------------------------------------ bad input
def test_unsupported_image_encoding_leaves_nothing(tmp_path):
    path = tmp_path / "depth"
    with Ros2Bag(path) as b:
        msg = b.image(T0, np.zeros((4, 4), np.uint8))
        msg.encoding, msg.step, msg.data = "32FC1", 16, np.zeros(64, np.uint8)
        b.write("/depth", msg, T0)
    with pytest.raises(InputError, match="/depth: image encoding '32FC1' is not supported"):
        import_bag(path, tmp_path / "seq")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["depth"]


def test_bad_input_is_a_one_line_error(tmp_path, capsys):
    corrupt = tmp_path / "corrupt.bag"
    corrupt.write_bytes(JACKAL.read_bytes()[:40_000])
    scrambled = tmp_path / "scrambled.bag"
    data = bytearray(JACKAL.read_bytes())
    data[200_000:200_400] = np.random.default_rng(3).integers(0, 256, 400, dtype=np.uint8).tobytes()
    scrambled.write_bytes(bytes(data))
    garbage = tmp_path / "garbage.bag"
    garbage.write_bytes(b"this is not a bag\n" * 10)
    cases = [
        ([str(tmp_path / "missing.bag"), str(tmp_path / "a")], "bag not found"),
        ([str(garbage), str(tmp_path / "b")], "not a readable ROS bag"),
        ([str(corrupt), str(tmp_path / "c")], "not a readable ROS bag"),
        ([str(scrambled), str(tmp_path / "g")], "cannot read the bag"),
        ([str(JACKAL), str(tmp_path / "d"), "--imu-topic", "/nope"], "no such topic"),
        ([str(JACKAL), str(tmp_path / "e"), "--imu-topic", "/jackal_velocity_controller/odom"],
         "expected sensor_msgs/msg/Imu"),
        ([str(JACKAL), str(tmp_path / "f"), "--static-tf", "1 2 base imu"], "static-tf"),
    ]
    for argv, text in cases:
        assert main(["-q", "import-bag", *argv]) == 2, argv
        err = capsys.readouterr().err.strip()
        assert err.startswith("fusion-vo: error: ") and "\n" not in err and text in err, err
        assert not Path(argv[1]).exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_existing_output_needs_force(tmp_path, capsys):
    out = tmp_path / "seq"
    out.mkdir()
    (out / "old.txt").write_text("keep me")
    assert main(["-q", "import-bag", str(HUSKY), str(out)]) == 2
    assert "--force" in capsys.readouterr().err and (out / "old.txt").exists()
    assert main(["-q", "import-bag", str(HUSKY), str(out), "--force", "--static-tf", HUSKY_IMU_TF]) == 0
    assert not (out / "old.txt").exists() and (out / "gps0" / "data.csv").is_file()
    assert "gps0" in capsys.readouterr().out
