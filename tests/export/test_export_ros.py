"""fusion-vo export: trajectories as nav_msgs/Odometry and /tf, read back with rosbags and with mcap."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from fusion_vo.cli.main import main
from fusion_vo.export.ros import COV_HEADER, pose_covariance_6x6
from fusion_vo.recording import write_tum

T0_NS = 1_600_000_000_000_000_000


def _poses(n, seed):
    rng = np.random.default_rng(seed)
    t_ns = T0_NS + np.arange(n, dtype=np.int64) * 50_000_000 + rng.integers(0, 1000, n)
    xyyaw = np.column_stack([np.cumsum(rng.normal(0.01, 0.002, n)), np.cumsum(rng.normal(0, 0.002, n)),
                             np.cumsum(rng.normal(0.02, 0.05, n))])
    return t_ns, xyyaw


def _covariances(n, seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, 3, 3)) * 1e-2
    return a @ a.transpose(0, 2, 1) + 1e-6 * np.eye(3)


@pytest.fixture
def run_dir(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    t_ns, xyyaw = _poses(40, 1)
    write_tum(run / "gtsam.tum", t_ns * 1e-9, xyyaw)
    cov = _covariances(40, 2)
    with open(run / "gtsam.cov.csv", "w") as f:
        f.write(COV_HEADER + "\n")
        for t, c in zip(t_ns, cov):
            upper = (c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2], c[2, 2])
            f.write(f"{t * 1e-9:.9f}," + ",".join(repr(float(v)) for v in upper) + "\n")
    t2, xy2 = _poses(25, 3)
    write_tum(run / "vo.tum", t2 * 1e-9, xy2)
    (run / "run.yaml").write_text(yaml.safe_dump({"sequence": str(tmp_path / "absent")}))
    return run, {"gtsam": (t_ns, xyyaw, cov), "vo": (t2, xy2, None)}


def _yaw(q):
    return 2.0 * np.arctan2(q.z, q.w)


def _check(messages, expected):
    """messages: topic -> list of (log time ns, deserialised message)."""
    from fusion_vo.geometry.se2 import wrap_angle

    assert set(messages) == {"/fusion_vo/gtsam/odometry", "/fusion_vo/vo/odometry", "/tf"}
    for name, (t_ns, xyyaw, cov) in expected.items():
        msgs = messages[f"/fusion_vo/{name}/odometry"]
        assert len(msgs) == len(t_ns)
        for (log_time, msg), t, pose, c in zip(msgs, t_ns, xyyaw, cov if cov is not None else [None] * len(t_ns)):
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            assert abs(stamp - t) <= 500 and log_time == stamp  # the recording's clock, to the float precision of TUM seconds
            assert msg.header.frame_id == "odom" and msg.child_frame_id == f"{name}/base_link"
            p = msg.pose.pose
            assert p.position.x == pytest.approx(pose[0], abs=2e-9) and p.position.y == pytest.approx(pose[1], abs=2e-9)
            assert abs(wrap_angle(_yaw(p.orientation) - pose[2])) < 1e-8
            if c is None:
                assert not np.any(msg.pose.covariance)  # ROS: all zeros = covariance unknown
            else:
                np.testing.assert_allclose(pose_covariance_6x6(msg.pose.covariance), c, rtol=1e-12, atol=0)
                full = np.asarray(msg.pose.covariance).reshape(6, 6)
                assert np.all(full[2:5, :] == 0) and np.all(full[:, 2:5] == 0)
    # the body velocity of the first step of gtsam
    t_ns, xyyaw, _ = expected["gtsam"]
    first = messages["/fusion_vo/gtsam/odometry"][0][1]
    dt = (t_ns[1] - t_ns[0]) * 1e-9
    assert first.twist.twist.angular.z == pytest.approx(wrap_angle(xyyaw[1, 2] - xyyaw[0, 2]) / dt, rel=2e-5)
    tf = messages["/tf"]
    assert len(tf) == sum(len(v[0]) for v in expected.values())
    children = {m.transforms[0].child_frame_id for _, m in tf}
    assert children == {"gtsam/base_link", "vo/base_link"}
    times = [lt for lt, _ in tf]
    assert times == sorted(times)


def test_rosbag2_reads_back_with_rosbags(run_dir, tmp_path, capsys):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    run, expected = run_dir
    out = tmp_path / "bag"
    assert main(["export", str(run), str(out), "--to", "rosbag2"]) == 0
    assert "/fusion_vo/vo/odometry: 25 poses (covariance unknown)" in capsys.readouterr().out
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    messages: dict[str, list] = {}
    with AnyReader([out], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for conn, timestamp, raw in reader.messages():
            messages.setdefault(conn.topic, []).append((timestamp, reader.deserialize(raw, conn.msgtype)))
    _check(messages, expected)


def test_mcap_reads_back_with_mcap(run_dir, tmp_path):
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    run, expected = run_dir
    out = tmp_path / "run.mcap"
    assert main(["export", str(run), str(out), "--to", "mcap"]) == 0
    store = get_typestore(Stores.ROS2_HUMBLE)
    messages: dict[str, list] = {}
    with open(out, "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        for schema, channel, message in reader.iter_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            assert schema.data.decode().startswith("std_msgs/Header header" if schema.name.endswith("Odometry")
                                                   else "geometry_msgs/TransformStamped[] transforms")
            messages.setdefault(channel.topic, []).append(
                (message.log_time, store.deserialize_cdr(message.data, schema.name)))
    _check(messages, expected)


def test_existing_output_is_an_error_and_kept(run_dir, tmp_path, capsys):
    run, _ = run_dir
    out = tmp_path / "taken.mcap"
    out.write_text("mine")
    assert main(["export", str(run), str(out), "--to", "mcap"]) == 2
    assert "already exists" in capsys.readouterr().err and out.read_text() == "mine"


@pytest.mark.parametrize("row, message", [
    ("1600000000.000000000,1,0,0,1,0", "gtsam.cov.csv:3: expected 7 columns"),
    ("1600000000.000000000,1,0,0,1,0,nan", "gtsam.cov.csv:3: non-finite covariance"),
    ("1600000000.000000000,1,0,0,-1,0,1", "gtsam.cov.csv:3: negative variance"),
    ("1600000000.000000000,1,0,0,1,0,x", "gtsam.cov.csv:3: expected numbers"),
])
def test_bad_covariance_file_names_the_line(run_dir, tmp_path, capsys, row, message):
    run, _ = run_dir
    lines = (run / "gtsam.cov.csv").read_text().splitlines()
    lines[2] = row
    (run / "gtsam.cov.csv").write_text("\n".join(lines) + "\n")
    assert main(["export", str(run), str(tmp_path / "o.mcap"), "--to", "mcap"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "o.mcap").exists()


def test_covariance_file_missing_a_pose(run_dir, tmp_path, capsys):
    run, _ = run_dir
    lines = (run / "gtsam.cov.csv").read_text().splitlines()
    (run / "gtsam.cov.csv").write_text("\n".join(lines[:-1]) + "\n")
    assert main(["export", str(run), str(tmp_path / "bag"), "--to", "rosbag2"]) == 2
    assert "gtsam.cov.csv: no covariance row for the pose at" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_groundtruth_of_the_recording_is_exported_on_its_clock(run_dir, tmp_path):
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    run, _ = run_dir
    rec = tmp_path / "rec"
    (rec / "state_groundtruth_estimate0").mkdir(parents=True)
    t_ns = T0_NS + np.arange(7, dtype=np.int64) * 5_000_000 + 123
    yaw = np.linspace(0.0, 0.6, 7)
    rows = [f"{t},{0.1 * i},{-0.05 * i},0.0,{float(np.cos(a / 2))!r},0.0,0.0,{float(np.sin(a / 2))!r}"
            for i, (t, a) in enumerate(zip(t_ns, yaw))]
    (rec / "state_groundtruth_estimate0" / "data.csv").write_text(
        "#timestamp [ns],p_x,p_y,p_z,q_w,q_x,q_y,q_z\n" + "\n".join(rows) + "\n")
    (run / "run.yaml").write_text(yaml.safe_dump({"sequence": str(rec)}))
    out = tmp_path / "gt.mcap"
    assert main(["export", str(run), str(out), "--to", "mcap", "--trajectories", "groundtruth"]) == 0
    store = get_typestore(Stores.ROS2_HUMBLE)
    with open(out, "rb") as f:
        got = [(message.log_time, store.deserialize_cdr(message.data, schema.name))
               for schema, channel, message in make_reader(f).iter_messages(topics=["/fusion_vo/groundtruth/odometry"])]
    # the recording's nanosecond stamps (to the float precision of seconds, as the trajectories)
    assert np.max(np.abs(np.array([lt for lt, _ in got]) - t_ns)) <= 500
    assert [m.pose.pose.position.x for _, m in got] == pytest.approx([0.1 * i for i in range(7)], abs=1e-12)
    assert [_yaw(m.pose.pose.orientation) for _, m in got] == pytest.approx(yaw, abs=1e-9)


def test_reads_the_covariance_files_the_backends_write(tmp_path):
    from fusion_vo.backends.result import write_pose_covariances
    from fusion_vo.export.ros import load_run_trajectories

    t_ns, xyyaw = _poses(30, 7)
    cov = _covariances(30, 8)
    write_tum(tmp_path / "ekf.tum", t_ns * 1e-9, xyyaw)
    write_pose_covariances(tmp_path / "ekf.cov.csv", t_ns * 1e-9, cov)
    (traj,) = load_run_trajectories(tmp_path)
    np.testing.assert_allclose(traj.covariance, cov, rtol=1e-9)  # the writer keeps 10 significant digits
